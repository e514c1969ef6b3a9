# SPDX-License-Identifier: Apache-2.0
"""Rotation helpers and vectorised forward kinematics shared by the skeleton readers.

Everything here works on whole clips at once: angles are ``(T,)`` arrays, rotations are
``(T, 3, 3)`` stacks. Loops run over joints or over the (at most three) Euler axes, never over
frames.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, overload

import numpy as np

from .human_motion import HumanMotion

# Up-axis conversion: a y-up world is mapped to our z-up world by the cyclic permutation
# (x, y, z) -> (z, x, y), i.e. new_x = old_z, new_y = old_x, new_z = old_y.  It is a proper
# rotation (det = +1), so right-handedness is kept.  For the CMU skeletons (rest pose facing +Z,
# left arm along +X, y up) it gives a rest pose facing +X with the left arm along +Y and z up,
# which is the REP-103 convention of humanoid robot models.
Y_UP_TO_Z_UP = np.array(
    [
        [0.0, 0.0, 1.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
    ]
)


def axis_rotations(angles: np.ndarray, axis: str) -> np.ndarray:
    """Stack of elementary rotations about one coordinate axis.

    Args:
        angles: Angles in [rad], any shape ``S``.
        axis: ``"x"``, ``"y"`` or ``"z"`` (case-insensitive).

    Returns:
        Rotation matrices of shape ``S + (3, 3)``.
    """
    angles = np.asarray(angles, dtype=float)
    c, s = np.cos(angles), np.sin(angles)
    one, zero = np.ones_like(angles), np.zeros_like(angles)
    axis = axis.lower()
    if axis == "x":
        rows = ((one, zero, zero), (zero, c, -s), (zero, s, c))
    elif axis == "y":
        rows = ((c, zero, s), (zero, one, zero), (-s, zero, c))
    elif axis == "z":
        rows = ((c, -s, zero), (s, c, zero), (zero, zero, one))
    else:
        raise ValueError(f"rotation axis must be 'x', 'y' or 'z', got {axis!r}")
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def euler_product(angles: np.ndarray, axes: Sequence[str]) -> np.ndarray:
    r"""Product of elementary rotations, left to right in the order given.

    ``euler_product(a, "zyx")`` is :math:`R_z(a_0) R_y(a_1) R_x(a_2)` (the BVH convention for
    ``Zrotation Yrotation Xrotation``).  For the Acclaim convention, where the first listed axis
    is applied first, pass the reversed order.

    Args:
        angles: Angles in [rad], shape ``(..., k)`` with ``k = len(axes)``.
        axes: Sequence of ``"x"``, ``"y"``, ``"z"``.

    Returns:
        Rotation matrices of shape ``(..., 3, 3)``.
    """
    angles = np.asarray(angles, dtype=float)
    out = np.broadcast_to(np.eye(3), angles.shape[:-1] + (3, 3)).copy()
    for i, axis in enumerate(axes):
        out = out @ axis_rotations(angles[..., i], axis)
    return out


def forward_kinematics(
    parents: Sequence[int],
    translations: Sequence[np.ndarray],
    rotations: Sequence[np.ndarray | None],
    num_frames: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    r"""World positions and rotations of a kinematic tree, vectorised over frames.

    For a joint :math:`j` with parent :math:`p`:

    .. math::

        R_j = R_p L_j, \qquad x_j = x_p + R_p t_j,

    and for a root :math:`R_j = L_j`, :math:`x_j = t_j`.

    Args:
        parents: Parent index of each joint (-1 for a root); parents come before children.
        translations: Local translation of each joint, ``(3,)`` or ``(T, 3)``.
        rotations: Local rotation of each joint, ``(T, 3, 3)``, or ``None`` for identity.
        num_frames: ``T``; by default taken from the first per-frame rotation or translation.

    Returns:
        ``(positions, orientations)`` of shapes ``(T, J, 3)`` and ``(T, J, 3, 3)``.
    """
    if num_frames is None:
        num_frames = next(
            (r.shape[0] for r in rotations if r is not None),
            next((t.shape[0] for t in translations if np.ndim(t) == 2), 1),
        )
    num_joints = len(parents)
    positions = np.empty((num_frames, num_joints, 3))
    orientations = np.empty((num_frames, num_joints, 3, 3))
    for j, p in enumerate(parents):
        local_t = np.broadcast_to(np.asarray(translations[j], dtype=float), (num_frames, 3))
        local_r = rotations[j]
        if p < 0:
            positions[:, j] = local_t
            orientations[:, j] = np.eye(3) if local_r is None else local_r
            continue
        parent_r = orientations[:, p]
        positions[:, j] = positions[:, p] + np.einsum("tab,tb->ta", parent_r, local_t)
        orientations[:, j] = parent_r if local_r is None else parent_r @ local_r
    return positions, orientations


@overload
def change_up_axis(
    positions: np.ndarray, orientations: np.ndarray, up_axis: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...


@overload
def change_up_axis(
    positions: np.ndarray, orientations: None, up_axis: str
) -> tuple[np.ndarray, None, np.ndarray]: ...


def change_up_axis(
    positions: np.ndarray,
    orientations: np.ndarray | None,
    up_axis: str,
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Express positions and orientations in the z-up world.

    Positions become :math:`A x`; rotations :math:`A R A^T` (the joint frames are relabelled the
    same way as the world, so the rest pose keeps the identity orientation).

    Args:
        positions: ``(..., 3)`` positions in the source world.
        orientations: ``(..., 3, 3)`` rotations in the source world, or ``None``.
        up_axis: ``"y"`` (apply :data:`Y_UP_TO_Z_UP`) or ``"z"`` (no change).

    Returns:
        ``(positions, orientations, A)`` with ``A`` the 3x3 matrix that was applied.

    Raises:
        ValueError: If ``up_axis`` is not ``"y"`` or ``"z"``.
    """
    if up_axis == "z":
        return positions, orientations, np.eye(3)
    if up_axis != "y":
        raise ValueError(
            f"up_axis must be 'y' or 'z', got {up_axis!r}; pass the axis that points up in the "
            "file (CMU BVH and ASF/AMC: 'y'; C3D: usually 'z')"
        )
    A = Y_UP_TO_Z_UP
    positions = positions @ A.T
    if orientations is not None:
        orientations = A @ orientations @ A.T
    return positions, orientations, A


def skeleton_motion(
    names: Sequence[str],
    parents: Sequence[int],
    translations: Sequence[np.ndarray],
    rotations: Sequence[np.ndarray | None],
    *,
    num_frames: int,
    rate: float,
    up_axis: str,
    source: str,
    meta: Mapping[str, Any],
) -> HumanMotion:
    """A skeleton reader's clip: :func:`forward_kinematics`, then :func:`change_up_axis`.

    Args:
        names: joint names, parents before children.
        parents: parent index of each joint (-1 for a root).
        translations: per joint, its offset in its parent, as for :func:`forward_kinematics`.
        rotations: per joint, its local rotation stack or ``None``.
        num_frames: ``T``; the samples are at ``t = k / rate``.
        rate: frame rate [Hz].
        up_axis: up axis of the file (``"y"`` or ``"z"``).
        source: the file, stored in the motion.
        meta: the reader's metadata.

    Returns:
        The motion in metres, z up, with world orientations.
    """
    positions, orientations = forward_kinematics(parents, translations, rotations, num_frames)
    positions, orientations, _ = change_up_axis(positions, orientations, up_axis)
    return HumanMotion(
        t=np.arange(num_frames) / rate,
        names=tuple(names),
        positions=positions,
        parents=tuple(parents),
        orientations=orientations,
        rate=rate,
        source=source,
        meta=dict(meta),
    )
