# SPDX-License-Identifier: Apache-2.0
r"""Scaling human key-points to the robot's dimensions (Poubel 2014 eq. 1, Dariush 2009 Sec. 3).

Two methods, chosen in the ``retarget:`` section of the controller YAML (``scaling: poubel`` or
``scaling: dariush``); both use the :class:`~qpretarget.motion.calibration.Calibration` of the
motion (heading rotation :math:`R_a`, human and robot segment lengths).

**Poubel 2014 eq. 1, segment by segment from the support foot.** Walking the key-point tree from a
root point fixed on the robot, each key-point :math:`\alpha` is placed after its antecedent
:math:`a` along the human segment's direction, with the robot's segment length
:math:`\ell^r_\alpha`:

.. math::

    p^r_\alpha = R_a \frac{p^h_\alpha - p^h_a}{\lVert p^h_\alpha - p^h_a \rVert}\,
                 \ell^r_\alpha + p^r_a .

In single support the root is the support ankle, held at the robot's own ankle (the foot is in
contact), and the tree is walked from it: support knee, hip, waist, then the rest of the body and
the swing leg. In double support (Poubel 2014 Sec. III.A) both ankles are fixed on the robot's
ankles; the closed loop of the legs is scaled from the point between the ankles to the point
between the hips without going through the knees, then from the hips on as in single support.
The mid-ankle to mid-hip segment is not a rigid link: its length is the human's times the ratio
of the robot's reference posture to the human's calibration pose, so a squatting person makes a
squatting robot (the paper leaves this length open). Scaled segments have exactly the robot's
length and the human segment's direction, except the shanks in double support (knee to fixed
ankle), which close the loop.

**Dariush 2009 per-link scaling.** Rooted at the waist (the base frame of Dariush 2009 Sec. 3),
each segment vector is multiplied by its per-link scale :math:`s_\alpha = \ell^r_\alpha /
\ell^h_\alpha` (human length from the calibration samples):

.. math::

    p^r_\alpha = p^r_a + s_\alpha R_a (p^h_\alpha - p^h_a), \qquad
    p^r_{waist} = w_r + s_0 R_a (p^h_{waist} - w_h),

with :math:`s_0` the ratio of the robot's to the human's waist height above the ankles. On a rigid
skeleton (BVH, ASF/AMC) both methods give the same segment lengths; on marker data Dariush scaling
follows the human's length variations while Poubel scaling keeps the robot's lengths.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from .calibration import Calibration

#: The scaling methods, by YAML name.
SCALING_METHODS = ("poubel", "dariush")


def _direction(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Unit vector from ``a`` to ``b`` (NaN when degenerate or missing)."""
    d = b - a
    n = math.sqrt(float(d @ d))
    if not n > 1e-12:
        return np.full(3, np.nan)
    return d / n


class Scaler:
    r"""Scale human key-points to the robot (Poubel 2014 eq. 1 or Dariush 2009 per-link).

    Args:
        calibration: The calibration of the motion to the robot.
        method: ``"poubel"`` or ``"dariush"``.

    Raises:
        ValueError: Unknown method.
    """

    def __init__(self, calibration: Calibration, method: str = "poubel") -> None:
        if method not in SCALING_METHODS:
            raise ValueError(
                f"scaling method must be one of {', '.join(SCALING_METHODS)}, got {method!r}"
            )
        self.calibration = calibration
        self.method = method
        tree = calibration.tree
        self.tree = tree
        self._adjacent: dict[str, list[tuple[str, str]]] = {k: [] for k in tree}
        for child, parent in tree.items():
            if parent is not None:
                # (neighbour, segment key): a segment is named after its child key-point.
                self._adjacent[child].append((parent, child))
                self._adjacent[parent].append((child, child))
        self._orders: dict[tuple[str, frozenset[str]], list[tuple[str, str, str]]] = {}
        self._R = calibration.rotation
        self._lengths = calibration.robot_lengths
        self._scales = calibration.scales
        robot = calibration.robot_points
        self.has_legs = all(
            k in tree for k in ("left_hip", "right_hip", "left_ankle", "right_ankle")
        )
        if self.has_legs:
            mid_hip = 0.5 * (robot["left_hip"] + robot["right_hip"])
            self._hip_to_waist = float(np.linalg.norm(robot["waist"] - mid_hip))
        else:
            self._hip_to_waist = 0.0

    def __repr__(self) -> str:
        """Method and tree size."""
        return f"Scaler(method={self.method!r}, keypoints={list(self.tree)})"

    # ------------------------------------------------------------------------------ traversal
    def order_from(
        self, root: str, stop: frozenset[str] = frozenset()
    ) -> list[tuple[str, str, str]]:
        """Breadth-first ``(antecedent, key-point, segment)`` of the tree re-rooted at ``root``.

        Key-points in ``stop`` are not entered (nor what lies beyond them).
        """
        key = (root, stop)
        order = self._orders.get(key)
        if order is None:
            order = []
            seen = {root} | set(stop)
            frontier = [root]
            while frontier:
                nxt = []
                for a in frontier:
                    for n, seg in self._adjacent[a]:
                        if n not in seen:
                            seen.add(n)
                            order.append((a, n, seg))
                            nxt.append(n)
                frontier = nxt
            self._orders[key] = order
        return order

    # ------------------------------------------------------------------------------ methods
    def scale_rooted(
        self,
        human: Mapping[str, np.ndarray],
        root: str,
        root_position: np.ndarray,
        *,
        fixed: Mapping[str, np.ndarray] | None = None,
    ) -> dict[str, np.ndarray]:
        r"""Poubel 2014 eq. 1 from ``root`` placed at ``root_position``.

        Args:
            human: Human key-points, name -> ``(3,)`` [m] (the calibration's tree names).
            root: Key-point the walk starts from (e.g. the support ankle).
            root_position: Where the root is on the robot [m].
            fixed: Key-points whose robot position is imposed (double-support ankles): they are
                placed there and the walk continues from them.

        Returns:
            Scaled key-points, name -> ``(3,)``; NaN where the human direction is undefined.
        """
        R, lengths = self._R, self._lengths
        out = {root: np.asarray(root_position, float).copy()}
        for a, n, seg in self.order_from(root):
            if fixed is not None and n in fixed:
                out[n] = np.asarray(fixed[n], float).copy()
                continue
            d = _direction(human[a], human[n])
            out[n] = out[a] + lengths[seg] * (R @ d)
        return out

    def scale_double_support(
        self,
        human: Mapping[str, np.ndarray],
        left_ankle: np.ndarray,
        right_ankle: np.ndarray,
    ) -> dict[str, np.ndarray]:
        r"""Poubel 2014 Sec. III.A: both ankles fixed, legs' loop scaled mid-ankle -> mid-hip.

        The robot mid-hip is :math:`m_a^r + \rho R_a (m_h^h - m_a^h)` with :math:`m_a, m_h` the
        mid-ankle and mid-hip points and :math:`\rho` the calibration's double-support ratio; the
        waist follows along the human mid-hip -> waist direction with the robot's length, then
        every other key-point by eq. 1 from the waist, the ankles staying where they are fixed.

        Args:
            human: Human key-points, name -> ``(3,)`` [m].
            left_ankle: Fixed robot left ankle position [m].
            right_ankle: Fixed robot right ankle position [m].

        Returns:
            Scaled key-points.

        Raises:
            ValueError: If the tree has no hips and ankles (use :meth:`scale_rooted`).
        """
        if not self.has_legs:
            raise ValueError("double-support scaling needs both hips and both ankles")
        R = self._R
        mid_ankle_r = 0.5 * (np.asarray(left_ankle, float) + np.asarray(right_ankle, float))
        mid_ankle_h = 0.5 * (human["left_ankle"] + human["right_ankle"])
        mid_hip_h = 0.5 * (human["left_hip"] + human["right_hip"])
        mid_hip_r = mid_ankle_r + self.calibration.double_support_ratio * (
            R @ (mid_hip_h - mid_ankle_h)
        )
        waist = mid_hip_r + self._hip_to_waist * (R @ _direction(mid_hip_h, human["waist"]))
        fixed = {"left_ankle": left_ankle, "right_ankle": right_ankle}
        return self.scale_rooted(human, "waist", waist, fixed=fixed)

    def scale_dariush(self, human: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        r"""Dariush 2009 per-link scaling from the waist (see the module docstring)."""
        cal, R = self.calibration, self._R
        out = {"waist": cal.robot_waist + cal.root_scale * (R @ (human["waist"] - cal.human_waist))}
        for a, n, seg in self.order_from("waist"):
            s = self._scales.get(seg)
            if s is None or not math.isfinite(s):  # human length unknown: keep the robot's
                out[n] = out[a] + self._lengths[seg] * (R @ _direction(human[a], human[n]))
            else:
                out[n] = out[a] + s * (R @ (human[n] - human[a]))
        return out

    def scale(
        self,
        human: Mapping[str, np.ndarray],
        *,
        support: str = "double",
        anchors: Mapping[str, np.ndarray] | None = None,
    ) -> dict[str, np.ndarray]:
        """Scale one sample with the configured method.

        Args:
            human: Human key-points, name -> ``(3,)`` [m].
            support: ``"left"``, ``"right"`` or ``"double"``: which robot feet are on the ground
                (Poubel: the root of the walk).
            anchors: side -> robot ankle position [m] of the feet on the ground. Without anchors
                (without legs, or when the person's legs are missing in this sample), Poubel
                scaling is rooted at the waist, placed like Dariush's.

        Returns:
            Scaled key-points, name -> ``(3,)``.
        """
        if self.method == "dariush":
            return self.scale_dariush(human)
        if anchors and self.has_legs:
            out = None
            if support == "double" and "left" in anchors and "right" in anchors:
                out = self.scale_double_support(human, anchors["left"], anchors["right"])
            elif support in ("left", "right") and support in anchors:
                out = self.scale_rooted(human, f"{support}_ankle", anchors[support])
            # Legs not seen (marker gaps): the chain from the feet is undefined, so the body is
            # placed from the waist as without anchors.
            if out is not None and (
                np.all(np.isfinite(out["waist"])) or not np.all(np.isfinite(human["waist"]))
            ):
                return out
        cal = self.calibration
        waist = cal.robot_waist + cal.root_scale * (self._R @ (human["waist"] - cal.human_waist))
        return self.scale_rooted(human, "waist", waist)


#: Lowest hip height above a supporting ankle that :func:`limit_leg_extension` asks for, as a
#: share of the allowed reach: where the hip is beyond the reach horizontally, the pelvis target
#: dropped to the ankle's height (0.15 m on the front kicks at 7.45 s).
LOWEST_HIP = 0.5


def limit_leg_extension(
    scaled: Mapping[str, np.ndarray],
    supports: Mapping[str, np.ndarray],
    leg_lengths: Mapping[str, float],
    ratio: float,
    standing: Mapping[str, np.ndarray] | None = None,
) -> tuple[dict[str, np.ndarray], float]:
    r"""Lower the scaled body so that no supporting leg is stretched beyond ``ratio`` of its length.

    A human stands and walks on nearly straight legs; a robot with its ankles fixed on the ground
    would then sit in the straight-knee singularity, where its pelvis can no longer move
    vertically. For each supporting side with ankle :math:`a` (fixed) and scaled hip :math:`h`,
    the body above the ankles is lowered by the smallest :math:`\Delta z \ge 0` with
    :math:`\lVert h - \Delta z\, e_z - a \rVert \le \rho\, \ell_{leg}`:

    .. math::

        \Delta z = \max_{sides}\; h_z - a_z - \sqrt{\max(\rho^2 \ell_{leg}^2 - \lVert h_{xy}
        - a_{xy} \rVert^2,\ (\mu \rho \ell_{leg})^2)},

    with :math:`\mu` = :data:`LOWEST_HIP`: a hip further than the reach horizontally (lowering
    cannot bring it within reach; the horizontal placement has to) is lowered at most to
    :math:`\mu \rho \ell_{leg}` above the ankle, a deep squat, not to the floor.

    Args:
        scaled: Scaled key-points.
        supports: side (``left``/``right``) -> fixed ankle position of each supporting foot.
        leg_lengths: side -> robot hip-to-ankle length at full extension (thigh + shank) [m].
        ratio: :math:`\rho`, the largest allowed fraction of the leg length.
        standing: side -> ankle of a robot foot on the ground that is not a support of the
            scaling (the person lifted that foot, the robot's has not left the floor yet): its
            leg is bounded the same way, but its key-points move down with the body.

    Returns:
        ``(points, dz)``: the key-points with every point but the supporting ankles (and toes,
        heels) moved down by ``dz`` [m].
    """
    dz = 0.0
    for side, ankle in [*supports.items(), *(standing or {}).items()]:
        hip = scaled.get(f"{side}_hip")
        if hip is None or side not in leg_lengths or not np.all(np.isfinite(hip)):
            continue
        reach = ratio * leg_lengths[side]
        dxy = float(np.hypot(hip[0] - ankle[0], hip[1] - ankle[1]))
        low = LOWEST_HIP * reach
        up = math.sqrt(max(reach * reach - dxy * dxy, low * low))
        dz = max(dz, float(hip[2] - ankle[2]) - up)
    if dz <= 0.0:
        return dict(scaled), 0.0
    fixed = {f"{side}_{p}" for side in supports for p in ("ankle", "toe", "heel")}
    down = np.array([0.0, 0.0, dz])
    return {k: (v if k in fixed else v - down) for k, v in scaled.items()}, dz


__all__ = ["LOWEST_HIP", "SCALING_METHODS", "Scaler", "limit_leg_extension"]
