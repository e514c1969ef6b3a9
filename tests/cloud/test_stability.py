# SPDX-License-Identifier: Apache-2.0
"""Balance (Wang 2017 eq. 18-19): CoM rows in the sole frame, restoring balance, the hip rule."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from qpretarget.cloud.em import CloudRetargeter
from qpretarget.cloud.stability import (
    HipRuleState,
    StabilityRows,
    Support,
    hip_joint_indices,
    hip_offset_rule,
)


def leaning(g1) -> np.ndarray:
    """G1 on its left foot with the torso and arms thrown forward: CoM ahead of the sole."""
    q = g1.q_reference.copy()
    for name, v in {"waist_pitch_joint": 0.5, "left_shoulder_pitch_joint": -1.5,
                    "right_shoulder_pitch_joint": -1.5, "left_hip_pitch_joint": -0.9}.items():  # fmt: skip
        q[g1.joint_q_index[g1.joint_index(name)]] = v
    q[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(0.1, 0.2, 0.7)).coeffs()  # any base pose
    return q


def test_com_rows_match_finite_differences(g1):
    rows = StabilityRows(g1, margin=0.01)
    q = leaning(g1)
    rows.set_support(Support(["left_foot"], "left_foot"), q)
    c0, J = rows.com_in_sole(q, jacobian=True)
    eps = 1e-7
    for k in range(g1.nv):
        dv = np.zeros(g1.nv)
        dv[k] = eps
        c1, _ = rows.com_in_sole(pin.integrate(g1.model, q, dv))
        # Forward difference, step 1e-7: error ~1e-7 m/rad.
        assert np.allclose((c1 - c0) / eps, J[:, k], atol=1e-6)
    # Relative to the sole, the base pose does not matter: zero base columns.
    assert np.abs(J[:, :6]).max() < 1e-9


def test_balance_is_restored_by_the_joints(g1, g1_template):
    cfg = {"robot": "g1", "calibration": {"enabled": False}}
    rt = CloudRetargeter(cfg, robot=g1, template=g1_template)
    q = leaning(g1)
    rt.rows.set_support(Support(["left_foot"], "left_foot"), q)
    assert rt.rows.margin_of(q) < -0.05  # well outside the sole
    q2, ok = rt._restore_balance(q)
    # Back inside the shrunk sole (linearization error below 1 micrometre after the loop).
    assert ok and rt.rows.margin_of(q2) >= -1e-6
    qi = g1.joint_q_index
    assert np.all(q2[qi] >= g1.q_min[qi] - 1e-9) and np.all(q2[qi] <= g1.q_max[qi] + 1e-9)


def test_paper_hip_rule(g1):
    rows = StabilityRows(g1, margin=0.0)
    q = leaning(g1)
    rows.set_support(Support(["left_foot"], "left_foot"), q)
    hips = hip_joint_indices(g1)
    assert len(hips) == 4
    before = rows.margin_of(q, full=True)
    q2, what = hip_offset_rule(rows, q, hips, HipRuleState())
    assert what == "outside"
    dv = pin.difference(g1.model, q, q2)
    changed = np.flatnonzero(np.abs(dv) > 1e-12)
    # Only hip pitch/roll moved, by the paper's 0.3 rad (unless a limit clipped it).
    assert set(changed) <= set(hips) and np.all(np.abs(dv[changed]) <= 0.3 + 1e-12)
    assert rows.margin_of(q2, full=True) > before  # the CoM moved towards the sole
