# SPDX-License-Identifier: Apache-2.0
r"""Where a person's joint centres sit, from the standing height (a generic human model).

Wang 2017 (HUMROB, IV.A) takes the joint centres of its template from a parametric human
model adapted to the subject and sets the robot's proportions on it. qpretarget's template is
the robot's surface; its joint centres are the robot's, which on a G1 fitted to a person sit
6-12 cm up the arm from the person's. This module gives the person's centres from the
segment lengths of Winter's anthropometric table (D. A. Winter, *Biomechanics and Motor Control
of Human Movement*, 4th ed., 2009, Fig. 4.1, after Drillis and Contini 1966), as fractions of
the standing height :math:`H`:

* arms, from the fingertip up the limb: wrist :math:`0.108 H` (hand), elbow
  :math:`0.108 + 0.146 = 0.254 H` (+ forearm), shoulder :math:`0.254 + 0.186 = 0.440 H`
  (+ upper arm);
* legs, heights above the floor: hip :math:`0.530 H`, knee :math:`0.285 H`, ankle
  :math:`0.039 H`.

:func:`anthropometric_offsets` turns them into offsets of the template's articulation centres
along its limbs in the calibrated pose (arms slightly away from the body, legs straight): the
fingertip is the template's (personalised) hand point furthest down the limb, the floor is at
z = 0. People differ from the table by a few per cent of a segment (1-2 cm), hence a prior
that the tracking refines (``calibration.centre_prior``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .template import Template

#: Distance of the centre starting each arm segment from the fingertip, along the limb [H].
#: The shoulder (upper arm, 0.440 H) is left out: three segments from the fingertip, the
#: table's spread adds up there; on the human model of the tests it put the shoulders
#: 13-15 cm from the model's, where the robot's are 6-7 cm away (docs/point_clouds.md).
ARM_FROM_FINGERTIP = {"forearm": 0.254, "hand": 0.108}
#: Height above the floor of the centre starting each leg segment, standing [H].
LEG_HEIGHT = {"thigh": 0.530, "shank": 0.285, "foot": 0.039}
#: Smallest vertical component of a leg's limb axis for its height rule (straight legs).
_MIN_VERTICAL = 0.5


def anthropometric_offsets(
    template: Template, points: np.ndarray, height: float, axes: np.ndarray
) -> np.ndarray:
    r"""Offsets (A, 3) moving each articulation's centre to the table's place along its limb.

    Args:
        template: the calibrated template; its rest configuration (``set_centre_rest``) is
            the calibrated pose, whose joint positions :math:`p_a` are used.
        points: (M, 3) the template's points posed at that configuration (world).
        height: the person's standing height :math:`H` [m].
        axes: (A, 3) unit limb directions (:meth:`Template.limb_axes`), pointing down the limb.

    Returns:
        For an arm articulation starting segment k, :math:`e_a = (D_a - f_k H)\, u_a` with
        :math:`D_a = \max_m (v_m - p_a)^\top u_a` over the hand points below it (the
        fingertip's distance down the limb) and :math:`f_k` = :data:`ARM_FROM_FINGERTIP`; for a
        leg articulation, :math:`e_a = \frac{h_k H - p_{a,z}}{u_{a,z}} u_a` with
        :math:`h_k` = :data:`LEG_HEIGHT`; zero for the others (trunk) and for a leg whose
        axis is not near vertical.
    """
    T = template
    names = T.segment_names
    p0 = T._p0
    out = np.zeros((T.n_centres, 3))
    hand = names.index("hand") if "hand" in names else -1
    for a, group in enumerate(T.articulations):
        j = int(max(group))
        seg = names[int(T.seg_of_joint[j])]
        u = axes[a]
        if seg in ARM_FROM_FINGERTIP and hand >= 0:
            below = (T._ancestors[T.joint, j] > 0) & (T.point_segment == hand)
            if not below.any():
                continue
            reach = float(np.max((points[below] - p0[j]) @ u))
            out[a] = (reach - ARM_FROM_FINGERTIP[seg] * height) * u
        elif seg in LEG_HEIGHT and abs(u[2]) >= _MIN_VERTICAL:
            out[a] = (LEG_HEIGHT[seg] * height - p0[j, 2]) / u[2] * u
    return out


__all__ = ["ARM_FROM_FINGERTIP", "LEG_HEIGHT", "anthropometric_offsets"]
