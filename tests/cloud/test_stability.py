# SPDX-License-Identifier: Apache-2.0
"""Balance (Wang 2017 eq. 18-19): CoM rows in the sole frame, restoring balance, the hip rule."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

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


@pytest.mark.parametrize("frame", ["sole", "upright"])
def test_com_rows_match_finite_differences(g1, frame):
    rows = StabilityRows(g1, margin=0.01, frame=frame)
    q = leaning(g1)  # a tilted sole: the upright frame's heading rate is not omega_z
    rows.set_support(Support(["left_foot"], "left_foot"), q)
    c0, J = rows.com_in_sole(q, jacobian=True)
    eps = 1e-7
    for k in range(g1.nv):
        dv = np.zeros(g1.nv)
        dv[k] = eps
        c1, _ = rows.com_in_sole(pin.integrate(g1.model, q, dv))
        # Forward difference, step 1e-7: error ~1e-7 m/rad.
        assert np.allclose((c1 - c0) / eps, J[:, k], atol=1e-6)
    # Relative to the sole the base's position does not matter, nor (sole frame) its turn.
    assert np.abs(J[:, : 6 if frame == "sole" else 3]).max() < 1e-9


def test_balance_is_the_floor_projection(g1):
    """The CoM and the soles are projected along the vertical, as ``evaluate`` measures the
    margin (on the world's xy), not along a tilted sole's normal: ``leaning`` turns the base by 0.1 /
    0.2 rad of roll / pitch, which tilts the sole, and with the sole's own frame the margin
    was off by the CoM's height times the tilt (a few cm here). Equal to 1e-9 m (rounding);
    turning the whole robot about the vertical changes nothing (1e-9 m)."""
    from qpretarget.constraints.support_polygon import polygon_halfplanes
    from qpretarget.geometry2d import convex_hull_2d

    rows = StabilityRows(g1, margin=0.0, frame="upright")
    for feet in (["left_foot"], ["left_foot", "right_foot"]):
        q = leaning(g1)
        rows.set_support(Support(feet, feet[0]), q)
        data = g1.model.createData()
        pin.framesForwardKinematics(g1.model, data, q)
        corners = []
        for f in feet:
            x0, x1, y0, y1 = g1.feet[f].rectangle
            M = data.oMf[g1.model.getFrameId(g1.feet[f].frame)]
            local = np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]])
            corners.append((local @ M.rotation.T + M.translation)[:, :2])
        com = pin.centerOfMass(g1.model, data, q, False)
        n, o = polygon_halfplanes(convex_hull_2d(np.vstack(corners)), 0.0)
        world = float(np.min(o - n @ com[:2]))  # the rows' measure, on the world's xy
        assert abs(rows.margin_of(q, full=True) - world) < 1e-9, (rows.margin_of(q), world)
        turned = q.copy()
        base = pin.XYZQUATToSE3(q[:7])
        turned[:7] = pin.SE3ToXYZQUAT(pin.SE3(pin.rpy.rpyToMatrix(0, 0, 1.2), np.zeros(3)) * base)
        assert abs(rows.margin_of(turned, full=True) - world) < 1e-9


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
