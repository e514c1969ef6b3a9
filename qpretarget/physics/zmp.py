# SPDX-License-Identifier: Apache-2.0
"""Zero-moment point of the *reference* motion: does the run ask for a CoP outside the feet?

A static-balance retarget keeps the CoM's ground projection inside the support polygon; dynamic
balance needs the ZMP there. From the run alone (no simulation), per frame, with ``c`` the CoM,
``L`` the centroidal angular momentum (pinocchio), ``m`` the mass, ``g`` gravity and ``z0`` the
floor height — the point on the floor about which the ground reaction has no horizontal moment,
from Newton's and Euler's equations of the whole body (the ZMP of the centroidal dynamics, as in
Kajita et al., *Introduction to Humanoid Robotics*, ch. 3):

    x_zmp = c_x - (c_z - z0) cddot_x / (cddot_z + g) - Ldot_y / (m (cddot_z + g))
    y_zmp = c_y - (c_z - z0) cddot_y / (cddot_z + g) + Ldot_x / (m (cddot_z + g))

``cddot`` and ``Ldot`` are central differences of the run's samples, averaged over
:data:`SMOOTH_FRAMES` frames (two differentiations of a 100 Hz output amplify its last digits).
The margin is the signed distance of the ZMP to the convex hull of the stance soles' rectangles
(> 0 inside), as the CoM margin of ``qpretarget evaluate``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..analysis.measures import signed_distance_to_polygon
from ..geometry2d import convex_hull_2d

#: Frames of the centred moving average applied to the CoM acceleration and ``Ldot``.
SMOOTH_FRAMES = 5


def _smooth(x: np.ndarray, n: int) -> np.ndarray:
    if n <= 1 or len(x) < n:
        return x
    kernel = np.ones(n) / n
    pad = n // 2
    xp = np.pad(x, ((pad, pad), (0, 0)), mode="edge")
    return np.stack([np.convolve(xp[:, i], kernel, mode="valid") for i in range(x.shape[1])], 1)


def reference_zmp_margin(
    robot: Any, t: np.ndarray, q: np.ndarray, v: np.ndarray, stance: np.ndarray, floor: float
) -> tuple[np.ndarray, np.ndarray]:
    """ZMP of the reference and its signed margin to the stance soles' polygon.

    Args:
        robot: :class:`~qpretarget.robot.RobotModel` (free flyer).
        t: (T,) times [s].
        q: (T, nq) configurations, pinocchio's order.
        v: (T, nv) velocities, pinocchio's convention.
        stance: (T, F) stance feet, columns in ``robot.feet`` order.
        floor: floor height [m].

    Returns:
        ``(zmp (T, 2), margin (T,))``; margin NaN in frames without a stance foot.
    """
    import pinocchio as pin

    model, data = robot.model, robot.data
    T = len(t)
    com = np.empty((T, 3))
    L = np.empty((T, 3))
    for k in range(T):
        pin.computeCentroidalMomentum(model, data, q[k], v[k])
        com[k] = data.com[0]
        L[k] = data.hg.angular
    mass = float(pin.computeTotalMass(model))
    g = 9.81
    acc = np.zeros((T, 3))
    dL = np.zeros((T, 3))
    if T >= 3:
        acc = np.asarray(np.gradient(np.gradient(com, t, axis=0), t, axis=0), float)
        dL = np.asarray(np.gradient(L, t, axis=0), float)
    acc = _smooth(acc, SMOOTH_FRAMES)
    dL = _smooth(dL, SMOOTH_FRAMES)
    gz = acc[:, 2] + g
    h = com[:, 2] - floor
    zmp = np.stack(
        [
            com[:, 0] - h * acc[:, 0] / gz - dL[:, 1] / (mass * gz),
            com[:, 1] - h * acc[:, 1] / gz + dL[:, 0] / (mass * gz),
        ],
        axis=1,
    )
    feet = list(robot.feet.values())
    fids = [robot.frame_id(f.frame) for f in feet]
    corners_local = [
        np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]])
        for (x0, x1, y0, y1) in (f.rectangle for f in feet)
    ]
    margin = np.full(T, np.nan)
    for k in range(T):
        on = np.nonzero(stance[k])[0]
        if len(on) == 0:
            continue
        pin.framesForwardKinematics(model, data, q[k])
        pts = []
        for i in on:
            M = data.oMf[fids[i]]
            pts.append((corners_local[i] @ M.rotation.T + M.translation)[:, :2])
        margin[k] = signed_distance_to_polygon(zmp[k], convex_hull_2d(np.vstack(pts)))
    return zmp, margin
