# SPDX-License-Identifier: Apache-2.0
"""Regularization metrics ``wln`` (Dariush 2009 eq. 13-14) and ``crac`` (CRAC eq. 17-29)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yaml

from qpretarget import Controller, load_robot
from qpretarget.constraints.self_collision import SelfCollision
from qpretarget.errors import ConfigError
from qpretarget.robot import RobotState
from qpretarget.weighting.base import REGULARIZATIONS

JOINT = "left_elbow_joint"


@pytest.fixture(scope="module")
def g1():
    return load_robot("g1")


def H_jl(q, lo, hi):
    """Dariush 2009 joint-limit function H(q) (before eq. 13)."""
    return 0.25 * np.sum((hi - lo) ** 2 / ((hi - q) * (q - lo)))


def test_wln_weights_follow_eq_13_14(g1) -> None:
    reg = REGULARIZATIONS["wln"]()
    reg.bind(g1)
    st = RobotState(g1)
    qi, vi = g1.joint_q_index, g1.joint_v_index
    lo, hi = g1.q_min[qi], g1.q_max[qi]
    q = g1.q_reference.copy()
    q[qi] = lo + (hi - lo) * np.linspace(0.05, 0.95, len(qi))
    v = np.zeros(g1.nv)
    v[vi] = np.where(np.arange(len(qi)) % 2 == 0, 1.0, -1.0)
    st.update(q, v)
    w = np.diag(reg.matrix(st, 0.01))
    # eq. 13 by central differences of H (step 1e-7 rad, relative tolerance 1e-5).
    grad = np.array(
        [
            (H_jl(q[qi] + 1e-7 * e, lo, hi) - H_jl(q[qi] - 1e-7 * e, lo, hi)) / 2e-7
            for e in np.eye(len(qi))
        ]
    )
    toward = grad * v[vi] >= 0  # |dH/dq| grows when the joint moves away from mid-range
    expected = np.where(toward, 1.0 + np.abs(grad), 1.0)  # eq. 14
    assert np.allclose(w[vi], expected, rtol=1e-5)
    assert np.all(w[:6] == 1.0)  # free flyer: no limits
    assert toward.any() and (~toward).any()


def closed_form(tp, W, lam):
    J = np.vstack([np.sqrt(b.weight)[:, None] * b.J for b in tp.blocks])
    v = np.concatenate([np.sqrt(b.weight) * b.v_star for b in tp.blocks])
    Wi = np.linalg.inv(W)
    return Wi @ J.T @ np.linalg.solve(J @ Wi @ J.T + lam**2 * np.eye(len(v)), v)  # CRAC eq. 10


def arms_config(g1, regularization):
    return Controller(
        {
            "robot": g1,
            "regularization": regularization,
            "tasks": [
                {"type": "frame", "name": "left", "frame": "left_rubber_hand", "mode": "position"},
                {"type": "frame", "name": "right", "frame": "right_rubber_hand", "mode": "pose"},
                {"type": "com", "name": "com", "axes": "xy", "weight": 10.0},
            ],
        }
    )


@pytest.mark.parametrize(
    "regularization",
    [
        {"type": "crac", "inertia": True},
        {"type": "crac", "inertia": False, "damping": 0.3},
        {"type": "wln", "damping": 0.1},
    ],
    ids=["crac-inertia", "crac-identity", "wln"],
)
def test_qp_equals_closed_form_with_the_same_W(g1, regularization) -> None:
    ctrl = arms_config(g1, regularization)
    qi = g1.joint_q_index
    q = g1.q_reference.copy()
    lo, hi = g1.q_min[qi], g1.q_max[qi]
    q[qi] = lo + (hi - lo) * np.linspace(0.03, 0.97, len(qi))  # several joints near a limit
    ctrl.reset(q)
    ctrl.state.update(ctrl.state.q, np.linspace(-1.0, 1.0, g1.nv))  # some toward, some away
    st = ctrl.state
    ctrl.set_targets(
        {
            "left": st.frame_placement(g1.frame_id("left_rubber_hand")).translation
            + [0.03, 0, 0.02],
            "right": st.frame_placement(g1.frame_id("right_rubber_hand")).translation.tolist(),
            "com": st.com() + [0.01, 0.0, 0.0],
        },
        [],
    )
    tp = ctrl.build_tick(0.01)
    W = tp.W.copy()
    assert not np.allclose(np.diag(W), np.diag(W)[0])  # adaptive weights are in play
    x = ctrl.strategy.solve(tp).x
    ref = closed_form(tp, W, tp.damping)
    # W up to ~1e6 (capped weights): relative 1e-6 is the solver tolerance on this conditioning.
    assert np.linalg.norm(x - ref) < 1e-6 * max(1.0, np.linalg.norm(ref))


def limit_config(g1, regularization):
    return Controller(
        {
            "robot": g1,
            "regularization": regularization,
            "tasks": [{"type": "posture", "weight": 1.0, "gain": 5.0}],
        }
    )


def test_joint_toward_limit_slows_and_stops_before_it_and_moves_freely_away(g1) -> None:
    j = g1.joint_index(JOINT)
    iq, iv = g1.joint_q_index[j], g1.joint_v_index[j]
    q_max = g1.q_max[iq]
    beyond = {JOINT: q_max + 0.5}  # posture target past the upper limit, no limit constraint
    ctrl = limit_config(g1, {"type": "crac", "inertia": False})
    ctrl.reset()
    qs, vs = [], []
    for _ in range(400):
        res = ctrl.step({"posture": beyond})
        qs.append(res.q[iq])
        vs.append(res.v[iv])
    qs, vs = np.array(qs), np.array(vs)
    assert np.all(qs < q_max)  # never reaches the limit
    assert q_max - qs[-1] < 0.05  # ... but gets close to it
    assert abs(vs[-1]) < 0.02 * max(abs(vs[:20]).max(), 1e-9)  # virtually stopped
    assert np.all(np.diff(vs[50:]) <= 1e-12)  # slowing down monotonically near the limit
    # Without the weights the same target drives the joint through its limit (the test can fail).
    free = limit_config(g1, {"type": "identity", "damping": 0.1})
    free.reset()
    for _ in range(400):
        res = free.step({"posture": beyond})
    assert res.q[iq] > q_max
    # Moving away: after one tick (the previous velocity still points at the limit) the joint's
    # weight is 0 (eq. 21) and W = W_D = I: the closed form without joint-limit weighting.
    inside = {JOINT: q_max - 1.0}
    ctrl.step({"posture": inside})
    ctrl.set_targets({"posture": inside}, [])
    tp = ctrl.build_tick(ctrl.dt)
    assert tp.W[iv, iv] == 1.0
    x = ctrl.strategy.solve(tp).x
    ref = closed_form(tp, np.eye(g1.nv), tp.damping)
    assert x[iv] < 0 and abs(x[iv] - ref[iv]) < 1e-6


class StubCollisions(SelfCollision):
    """A stand-in for the self_collision module: fixed distances and distance gradients."""

    def __init__(self, d, grad):
        self.d, self.grad = d, grad

    def distances_and_gradients(self, state):
        return self.d, self.grad


def test_crac_collision_weights_follow_eq_18_to_27(g1) -> None:
    rng = np.random.default_rng(0)
    d = np.array([0.02, 0.05, 0.4])
    grad = rng.standard_normal((3, g1.nv))
    stub = StubCollisions(d, grad)
    reg = REGULARIZATIONS["crac"](inertia=True)
    reg.bind(g1, [stub])
    st = RobotState(g1)
    v = rng.standard_normal(g1.nv)
    st.update(g1.q_reference.copy(), v)
    W = reg.matrix(st, 0.01)
    rho, alpha, beta = 1.0, 50.0, 2.0  # CRAC section 5
    dg = -rho * np.exp(-alpha * d) * d**-beta * (beta / d + alpha)  # eq. 26
    grad_f = dg[:, None] * grad  # eq. 22
    w_col = np.mean(np.where(grad * v <= 0, np.abs(grad_f), 0.0), axis=0)  # eq. 24, 27
    a = 1.0 / (3 + 1)  # eq. 19
    qi, vi = g1.joint_q_index, g1.joint_v_index
    lo, hi, qq = g1.q_min[qi], g1.q_max[qi], st.q[qi]
    gh = (hi - lo) ** 2 * (2 * qq - hi - lo) / (4 * (hi - qq) ** 2 * (qq - lo) ** 2)  # eq. 20
    w_jl = np.zeros(g1.nv)
    w_jl[vi] = np.where(gh * v[vi] >= 0, np.abs(gh), 0.0)  # eq. 21
    H = pin.crba(g1.model, g1.model.createData(), st.q)
    H = 0.5 * (H + H.T)
    expected = H + np.diag(np.minimum(a * w_jl + (1 - a) * w_col, 1e6))  # eq. 17, 18, 29
    assert np.allclose(W, expected, rtol=1e-12, atol=1e-9)
    assert reg.n_pairs == 3 and w_col.max() > 1.0


def test_crac_without_collision_module_uses_joint_limits_only(g1) -> None:
    reg = REGULARIZATIONS["crac"](inertia=False)
    reg.bind(g1, [])
    st = RobotState(g1)
    W = reg.matrix(st, 0.01)
    assert reg.n_pairs == 0
    assert np.allclose(W - np.eye(g1.nv), np.diag(reg.w_jl))  # a = 1: W_K = W_JL


def test_bad_parameters_are_config_errors(g1) -> None:
    with pytest.raises(ConfigError, match="inertia must be true"):
        REGULARIZATIONS["crac"](inertia="yes")
    with pytest.raises(ConfigError, match="rho"):
        REGULARIZATIONS["crac"](rho=-1.0)
    with pytest.raises(ConfigError, match="unknown key 'gamma'"):
        arms_config(g1, {"type": "crac", "gamma": 1.0})


DOCS = Path(__file__).resolve().parents[1] / "docs" / "schemes"
SNIPPETS = [
    (page, i, block)
    for page in ("augmentation", "hierarchy", "nullspace", "crac")
    for i, block in enumerate(
        re.findall(r"```yaml\n(.*?)```", (DOCS / f"{page}.md").read_text(), re.S)
    )
]


@pytest.mark.parametrize("page, i, block", SNIPPETS, ids=[f"{p}-{i}" for p, i, _ in SNIPPETS])
def test_scheme_docs_yaml_builds_and_runs(page, i, block) -> None:
    """The YAML of docs/schemes/{augmentation,hierarchy,nullspace,crac}.md must not rot."""
    ctrl = Controller(yaml.safe_load(block))
    q0 = ctrl.reset()
    for _ in range(3):
        res = ctrl.step({})
    assert res.status == "ok", res.messages
    if "centering_gain" not in block:  # joint centering (Poubel eq. 7) moves without targets
        assert np.linalg.norm(ctrl.robot.difference(q0, res.q)) < 1e-6  # holds its pose
