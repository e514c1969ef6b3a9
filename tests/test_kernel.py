# SPDX-License-Identifier: Apache-2.0
"""The compiled kernel (qpretarget/_kernel, src/kernel): the same ticks as the Python modules.

Tolerances: the kernel runs the same pinocchio algorithms on the same data, but its matrix
products sum in another order than numpy's, so a tick differs by a few ulp (1e-15). Where nothing
discrete depends on them (no collision witness point switching facets), 300 ticks stay within
1e-10 rad; the bound leaves four orders of magnitude of margin over the measured 1e-14.
"""

from __future__ import annotations

import copy
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from qpretarget import Controller
from qpretarget.errors import ConfigError
from qpretarget.kernel import daqp_kernel, kernel, python_only, why_not
from qpretarget.problem import QPProblem
from qpretarget.yamlio import load_yaml

IN_CI = bool(os.environ.get("CI"))
needs_kernel = pytest.mark.skipif(
    kernel() is None and not IN_CI, reason=f"compiled kernel not built here: {why_not()}"
)


def test_kernel_is_built_where_ci_installs_a_compiler() -> None:
    if kernel() is None and not IN_CI:
        pytest.skip(f"compiled kernel not built here: {why_not()}")
    assert kernel() is not None, why_not()
    assert daqp_kernel() is not None  # DAQP's C entry points found and its settings layout checked


def _workload(shared_dir: Path, variant: str = "A"):  # noqa: ANN202
    """Controller config, targets(k) and the start of the shared G1 workload."""
    bench = shared_dir / "bench"
    wl = load_yaml((bench / "workload_g1.yaml").read_text())
    tg = np.load(bench / wl["targets_file"])
    name = {"A": "qpretarget_g1_A.yaml", "B": "qpretarget_g1_B.yaml"}[variant]
    cfg = load_yaml((bench / "anchors" / name).read_text())
    cfg["solver"] = {"name": "daqp"}
    t = wl["tasks"]
    frames = ("pelvis", "torso", "left_hand", "right_hand", "left_elbow", "right_elbow", "head")
    T = {n: tg[f"T_{t[n]['frame']}"] for n in frames}

    def targets(k: int) -> dict:
        d = {"pelvis": T["pelvis"][k], "torso": T["torso"][k][:3, :3], "com": tg["com"][k]}
        for n in ("left_hand", "right_hand", "left_elbow", "right_elbow", "head"):
            d[n] = T[n][k][:3, 3]
        return d

    return cfg, targets, np.asarray(tg["q_init"], float), np.asarray(tg["q_nominal"], float)


def _run(cfg: dict, targets, q0, q_nom, n: int, edit=None) -> np.ndarray:  # noqa: ANN001
    ctrl = Controller(cfg)
    ctrl.reset(q0)
    ctrl.task("posture").set_target(q_nom)
    out = []
    for k in range(n):
        tk = targets(k)
        if edit is not None:
            edit(k, tk)
        out.append(np.array(ctrl.step(tk).q))
    return np.asarray(out)


@needs_kernel
def test_workload_a_compiled_equals_python(shared_dir: Path) -> None:
    cfg, targets, q0, q_nom = _workload(shared_dir, "A")
    ctrl = Controller(cfg)
    assert ctrl.compiled is not None, ctrl.compiled_reason
    assert ctrl.compiled.compiled_tasks == set(ctrl.tasks)  # every task of A has a compiled part
    assert ctrl.compiled.all_bounds and not ctrl.compiled.python_rows
    q_c = _run(cfg, targets, q0, q_nom, 300)
    with python_only():
        q_p = _run(cfg, targets, q0, q_nom, 300)
    err = np.abs(q_c - q_p).max()
    assert err <= 1e-10, f"compiled vs Python: {err:.2e} rad"
    assert np.abs(q_c[-1] - q_c[0]).max() > 0.05  # the targets did move the robot


@needs_kernel
def test_missing_target_ramps_back_as_in_python(shared_dir: Path) -> None:
    """A NaN target sends that task through Python (weight ramp) for a while: same run."""
    cfg, targets, q0, q_nom = _workload(shared_dir, "A")

    def edit(k: int, tk: dict) -> None:
        if 20 <= k < 25:
            tk["left_hand"] = np.full(3, np.nan)

    q_c = _run(cfg, targets, q0, q_nom, 80, edit)
    with python_only():
        q_p = _run(cfg, targets, q0, q_nom, 80, edit)
    assert np.abs(q_c - q_p).max() <= 1e-10


@needs_kernel
def test_a_task_without_compiled_part_runs_in_python_beside_compiled_ones(
    shared_dir: Path,
) -> None:
    cfg, targets, q0, q_nom = _workload(shared_dir, "A")
    # chain_shape (Tosun) has no compiled part: it runs in Python, the rest in the kernel.
    cfg["tasks"].append(
        {"type": "chain_shape", "name": "arm", "weight": 1.0, "reference_frame": "torso_link",
         "frames": ["left_shoulder_pitch_link", "left_elbow_link", "left_wrist_yaw_link"]}
    )  # fmt: skip
    ctrl = Controller(cfg)
    assert ctrl.compiled is not None and "arm" not in ctrl.compiled.compiled_tasks
    assert "left_hand" in ctrl.compiled.compiled_tasks
    q_c = _run(cfg, targets, q0, q_nom, 150)
    with python_only():
        q_p = _run(cfg, targets, q0, q_nom, 150)
    # The chain's normalized pose divides by its length: round-off grows faster (3.7e-10 rad
    # measured after 150 ticks), still far below any motion (1e-8).
    assert np.abs(q_c - q_p).max() <= 1e-8


@needs_kernel
def test_workload_b_same_tracking_as_python(shared_dir: Path) -> None:
    """B's collision rows: the same distances; round-off may move a witness point (a facet
    switch) for a few ticks, so the runs agree to 1e-6 rad almost everywhere, not to 1e-10."""
    cfg, targets, q0, q_nom = _workload(shared_dir, "B")
    q_c = _run(cfg, targets, q0, q_nom, 200)
    with python_only():
        q_p = _run(cfg, targets, q0, q_nom, 200)
    d = np.abs(q_c - q_p).max(axis=1)
    assert np.mean(d <= 1e-6) >= 0.95, f"ticks within 1e-6: {np.mean(d <= 1e-6):.2f}"


@needs_kernel
def test_daqp_from_c_equals_python_daqp_to_the_bit() -> None:
    from qpretarget.solvers.daqp_ import DaqpSolver

    if daqp_kernel() is None:
        pytest.fail("DAQP's C entry points were not loaded")
    rng = np.random.default_rng(3)
    n, m = 35, 30
    s_c, s_p = DaqpSolver(), DaqpSolver()
    s_p.compiled = False
    for _ in range(20):  # a slowly changing QP: the hot start is exercised
        A = rng.normal(size=(n, n))
        p = QPProblem(n, m)
        p.H[...] = A @ A.T + np.eye(n)
        p.g[...] = rng.normal(size=n)
        C = rng.normal(size=(m, n))
        u = rng.random(m)
        lo = np.full(m, -np.inf)
        lo[:6] = u[:6]  # equalities
        u[20:24] = np.inf  # rows with no finite side are left out
        lo[20:24] = -np.inf
        p.set_constraints(C, lo, u, np.full(n, -0.3), np.full(n, 0.3))
        a, b = s_c.solve(p), s_p.solve(p)
        assert a.success and b.success and a.status == b.status
        assert np.array_equal(a.x, b.x)
        assert a.iterations == b.iterations


@needs_kernel
def test_collision_distances_from_the_kernel_equal_python_to_the_bit(repo_dir: Path) -> None:
    from qpretarget.collision import CollisionModel
    from qpretarget.robot import RobotState, load_robot

    robot = load_robot("g1")
    pairs = [("left_wrist_yaw_link", "torso_link"), ("right_wrist_yaw_link", "pelvis_contour_link"),
             ("left_wrist_yaw_link", "right_wrist_yaw_link"), ("left_elbow_link", "torso_link")]  # fmt: skip
    m_c = CollisionModel(robot, pairs)
    with python_only():
        m_p = CollisionModel(robot, pairs)
    assert m_c._kernel is not None and m_p._kernel is None
    rng = np.random.default_rng(0)
    state = RobotState(robot)
    for _ in range(30):
        q = robot.q_reference.copy()
        q[robot.joint_q_index] += rng.uniform(-0.5, 0.5, len(robot.joint_q_index))
        state.update(q)
        for m in (m_c, m_p):
            m.update(state, 0.1)
        assert np.array_equal(m_c.distances, m_p.distances)
        assert np.array_equal(m_c.active, m_p.active)
        assert np.array_equal(m_c.witness_a, m_p.witness_a)
        assert np.array_equal(m_c.normals, m_p.normals)
        assert np.array_equal(m_c.gradients(state), m_p.gradients(state))


def test_kernel_can_be_turned_off_and_says_so(repo_dir: Path) -> None:
    code = (
        "import qpretarget.kernel as k; from qpretarget import Controller;"
        f"c = Controller.from_yaml({str(repo_dir / 'configs' / 'g1_augmentation.yaml')!r});"
        "print(k.describe()); print(c.compiled, c.compiled_reason)"
    )
    r = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
        env={**os.environ, "QPRETARGET_KERNEL": "0"},
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "compiled kernel: off (turned off by QPRETARGET_KERNEL=0)" in r.stdout
    assert "None turned off by QPRETARGET_KERNEL=0" in r.stdout


def test_build_without_a_compiler_installs_pure_python_and_says_what_to_install(
    repo_dir: Path, tmp_path: Path
) -> None:
    """The kernel's CMake step with no C++ compiler: one line naming what to install, no error."""
    cmake = shutil.which("cmake")
    if cmake is None:
        try:
            import cmake as cmake_pkg  # the PyPI cmake (test extra)

            cmake = str(Path(cmake_pkg.CMAKE_BIN_DIR) / "cmake")
        except ImportError:
            pytest.fail("cmake is a test dependency (pyproject [test]); it is missing")
    r = subprocess.run(
        [cmake, "-S", str(repo_dir), "-B", str(tmp_path)], capture_output=True, text=True,
        timeout=120, env={**os.environ, "CXX": "/nonexistent/g++"},
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    out = " ".join((r.stdout + r.stderr).split())
    assert "compiled kernel skipped (no C++ compiler)" in out
    assert "apt-get install g++" in out


@needs_kernel
def test_a_kernel_error_never_stops_the_loop(shared_dir: Path) -> None:
    """Should the kernel fail, the tick runs in Python, says so, and the loop goes on."""
    cfg, targets, q0, q_nom = _workload(shared_dir, "A")
    ctrl = Controller(cfg)
    ctrl.reset(q0)
    ctrl.step(targets(0))

    class Broken:
        def build(self, *a: object) -> None:
            raise RuntimeError("simulated kernel failure")

    assert ctrl.compiled is not None
    ctrl.compiled.tick = Broken()
    res = ctrl.step(targets(1))
    assert res.status == "ok" and np.all(np.isfinite(res.q))
    assert any("compiled kernel failed" in m for m in res.messages)
    assert ctrl.compiled is None and "simulated kernel failure" in ctrl.compiled_reason
    assert ctrl.step(targets(2)).status == "ok"


def test_bench_runs_the_shared_workload(shared_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "bench.json"
    r = subprocess.run(
        [sys.executable, "-m", "qpretarget", "bench", "--workload", "A,B", "--ticks", "60",
         "--passes", "1", "--bench-dir", str(shared_dir / "bench"), "--json", str(out)],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "| A | qpretarget / daqp |" in r.stdout and "| B | qpretarget / daqp |" in r.stdout
    import json

    res = json.loads(out.read_text())["results"]
    assert [x["variant"] for x in res] == ["A", "B"]
    for x in res:
        assert x["median_us"] > 0 and x["p95_us"] >= x["median_us"] and x["p99_us"] >= x["p95_us"]
        assert x["qp_fails"] == 0 and x["feet_max_mm"] < 0.01  # the feet hold (hard contacts)
    assert res[1]["dmin_viol_ticks"] == 0  # B: no pair below d_min - 1 mm


def test_bench_without_the_workload_folder_is_one_clear_error(tmp_path: Path) -> None:
    r = subprocess.run(
        [sys.executable, "-m", "qpretarget", "bench", "--workload", "A", "--bench-dir",
         str(tmp_path)], capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert r.returncode != 0 and "no workload_g1.yaml in" in r.stderr
    assert "Traceback" not in r.stderr


@needs_kernel
@pytest.mark.parametrize("pairs", ["auto", "listed"])
def test_self_collision_damper_compiled_equals_python(shared_dir: Path, pairs: str) -> None:
    """The compiled damper (broad phase, capped rows with their slots, trust region, soft rows'
    slacks) against the Python one on the workload's targets: 150 ticks, hands close to the
    body. Same distances from coal; the rows differ by round-off only (1e-10)."""
    cfg, targets, q0, q_nom = _workload(shared_dir, "B")
    col = next(c for c in cfg["constraints"] if c["type"] == "self_collision")
    if pairs == "auto":  # every pair that can collide, the closest max_rows get a row
        col["pairs"] = "auto"
        col["max_rows"] = 12
    cfg["constraints"].append({"type": "support_polygon", "margin": 0.02, "gain": 1.0})
    ctrl = Controller(cfg)
    assert ctrl.compiled is not None and ctrl.compiled.all_bounds, ctrl.compiled_reason
    assert not ctrl.compiled.python_rows  # collision and polygon rows in the kernel
    q_c = _run(cfg, targets, q0, q_nom, 150)
    with python_only():
        q_p = _run(cfg, targets, q0, q_nom, 150)
    err = np.abs(q_c - q_p).max()
    assert err <= 1e-10, f"compiled vs Python: {err:.2e}"


@needs_kernel
def test_plane_trust_region_compiled_equals_python(
    shared_dir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The trust region of pairs against a plane (``ground`` ``plane_trust``: a rotation bounded
    by its tilt from the normal, ``DistanceDamper.compute_bounds``) in the kernel and in Python.
    ``ground`` disarms standing links, which the kernel does not do, so it runs in Python; a
    test subclass without disarming (knees and hands within d_i = 0.3 m of the floor, a 2 um
    trust region so that the box binds) puts the same rows and box in the kernel: workload B,
    80 ticks, 1e-10 (measured 6e-15; the two part after ~90 ticks with or without
    ``plane_trust``, and at once with a knee hull under a raised floor: the kernel's ground
    pairs are not used in a run and are not otherwise checked)."""
    from qpretarget.constraints import CONSTRAINTS
    from qpretarget.constraints.ground import Ground

    class CompiledGround(Ground):
        disarms_rows = False

    monkeypatch.setitem(CONSTRAINTS, "compiled_ground_test", CompiledGround)
    cfg, targets, q0, q_nom = _workload(shared_dir, "B")
    cfg["constraints"].append(
        {"type": "compiled_ground_test", "links": ["left_knee", "right_knee", "left_hand",
         "right_hand"], "d_i": 0.3, "trust_region": 2e-6, "plane_trust": True}
    )  # fmt: skip
    ctrl = Controller(cfg)
    con = next(c for c in ctrl.constraints if isinstance(c, CompiledGround))
    assert con._planar.all()  # every pair is against the floor
    assert ctrl.compiled is not None and ctrl.compiled.computes_box(con), ctrl.compiled_reason
    q_c = _run(cfg, targets, q0, q_nom, 80)
    with python_only():
        q_p = _run(cfg, targets, q0, q_nom, 80)
    err = np.abs(q_c - q_p).max()
    assert err <= 1e-10, f"compiled vs Python: {err:.2e}"
    cfg["constraints"][-1]["plane_trust"] = False  # the bound is at work: another run without it
    assert np.abs(_run(cfg, targets, q0, q_nom, 80) - q_c).max() > 1e-6  # measured 1.8e-5


@needs_kernel
@pytest.mark.parametrize(
    "config",
    ["g1_whole_body.yaml", "g1_augmentation.yaml", "crac_ts1_velocity_crac.yaml",
     "crac_ts2_velocity_hierarchy.yaml"],
)  # fmt: skip
def test_shipped_configs_compiled_equal_python(repo_dir: Path, config: str) -> None:
    """Shipped velocity-level configs, 60 scripted ticks: the whole-body one mixes compiled
    modules with Python ones (feed-forward foot tasks, ground, acceleration limits: the box is
    merged in Python with the kernel's boxes), CRAC weighting reads the compiled collision
    distances, the hierarchy assembles its own QPs from compiled rows. Measured <= 2e-13 rad;
    1e-9 bound. (Talos, with 885 pairs, is not here: a coal GJK distance there moves by up to
    2e-7 m under a 1e-16 change of q — its tolerance — and the runs part by round-off.)"""
    from qpretarget.analysis.solver_comparison import scripted_targets

    path = repo_dir / "configs" / config
    c = Controller.from_yaml(path)
    assert c.compiled is not None, c.compiled_reason
    with python_only():
        p = Controller.from_yaml(path)
    targets = list(scripted_targets(c, 60 * c.dt))
    c.reset()
    p.reset()
    err = 0.0
    for t in targets[:60]:
        a, b = c.step(t), p.step(t)
        assert a.status == b.status
        err = max(err, float(np.abs(a.q - b.q).max()))
    assert err <= 1e-9, f"{config}: compiled vs Python {err:.2e} rad"


def test_pivoting_anchor_compiled_equals_python(repo_dir: Path) -> None:
    """A stance foot pivoting (a moving anchor turned 2 deg per tick, fed forward) on the
    shipped whole-body config, 40 ticks, with its drift-correction caps: the kernel's contact
    rows read the step array as the Python rows do. Measured ~1e-14 rad; 1e-9 bound."""
    import pinocchio as pin

    path = repo_dir / "configs" / "g1_whole_body.yaml"
    c = Controller.from_yaml(path)
    assert c.compiled is not None, c.compiled_reason
    with python_only():
        p = Controller.from_yaml(path)
    c.reset()
    p.reset()
    err = 0.0
    for k in range(40):
        for ctrl in (c, p):
            con = ctrl.constraint("contacts")
            con.clear_anchor_steps()
            if k >= 5:
                M = con.anchor_pose("left_foot")
                R = pin.exp3(np.array([0.0, 0.0, np.radians(2.0)])) @ M.rotation
                con.set_anchor("left_foot", pin.SE3(R, M.translation), moving=True)
        a, b = c.step(), p.step()
        assert a.status == b.status
        err = max(err, float(np.abs(a.q - b.q).max()))
    assert err <= 1e-9, f"compiled vs Python {err:.2e} rad"
    # The foot did turn with its anchor (35 ticks of 2 deg; within 2 deg of it at the end).
    con = c.constraint("contacts")
    fid = con.frame_ids[0]
    R = c.state.frame_placement(fid).rotation
    gap = np.degrees(np.linalg.norm(pin.log3(R.T @ con.anchor_pose("left_foot").rotation)))
    assert gap < 2.0


@needs_kernel
@pytest.mark.parametrize("variant", ["A", "B"])
def test_fused_tick_equals_the_unfused_compiled_tick(shared_dir: Path, variant: str) -> None:
    """The fused call (QP, DAQP, clip, integrate in one) gives the unfused compiled run: to the
    bit with the active-set check off (the same QP, the same DAQP inputs and hot start,
    pinocchio's integrate); with it on (the default), the previous tick's active set verified
    by its KKT conditions gives the same optimum to round-off (measured <= 1e-13 rad over 200
    ticks; bound 1e-9), and on most ticks no DAQP iteration at all."""
    cfg, targets, q0, q_nom = _workload(shared_dir, variant)
    runs, iters = [], []
    for mode in ("shortcut", "fused", "unfused"):
        ctrl = Controller(cfg)
        ctrl.strategy.use_fused = mode != "unfused"
        assert ctrl.compiled is not None
        ctrl.compiled.tick.set_shortcut(mode == "shortcut")
        ctrl.reset(q0)
        ctrl.task("posture").set_target(q_nom)
        res = [ctrl.step(targets(k)) for k in range(200)]
        runs.append(np.array([r.q for r in res]))
        iters.append(np.array([r.iterations for r in res]))
        assert ctrl.strategy.fused_error == ""
    assert np.array_equal(runs[1], runs[2])
    err = np.abs(runs[0] - runs[2]).max()
    assert err <= 1e-9, f"active-set check vs DAQP: {err:.2e} rad"
    assert np.mean(iters[0] == 0) >= 0.5  # the verified active set spared DAQP's iterations


@needs_kernel
def test_the_contacts_corrector_step_is_the_same_in_the_kernel(shared_dir: Path) -> None:
    """``Contacts.refine_rows`` with the compiled tick equals its Python code: the same
    decision and the same shifted rows (1e-9 in row units [m/s, rad/s]: the residual is a
    difference of poses ~1e-16 apart in the two paths, divided by dt = 0.01, with margin).

    At tick 40 of the shared workload, q_next = q + v dt (the last tick's velocity, the feet
    held) is within the 0.05 mm tolerance: no corrector solve; the same with the base moved by
    a few millimetres exceeds it: both paths must agree on both.
    """
    cfg, targets, q0, q_nom = _workload(shared_dir)
    ctrl = Controller(cfg)
    assert ctrl.compiled is not None
    ctrl.reset(q0)
    ctrl.task("posture").set_target(q_nom)
    for k in range(1, 40):
        ctrl.step(targets(k))
    con = ctrl.constraint("contacts")
    ctrl.build_tick(ctrl.dt)  # the tick's rows and kinematics, as the level sees them
    rows = slice(0, 12)
    i = 0
    for c in ctrl.row_constraints:
        if c is con:
            rows = slice(i, i + c.n_rows)
        i += c.n_rows
    for shift in (np.array([0.003, -0.002, 0.001]), np.zeros(3)):
        q_next = ctrl.robot.integrate(ctrl.state.q, ctrl.v, ctrl.dt)
        q_next[:3] += shift
        results = []
        for kern in (ctrl.compiled.tick, None):
            l, u = ctrl._l[rows].copy(), ctrl._u[rows].copy()
            changed = con.refine_rows(ctrl.state, q_next, ctrl.dt, l, u, kern)
            results.append((changed, l, u))
        (c1, l1, u1), (c2, l2, u2) = results
        assert c1 == c2
        np.testing.assert_allclose(l1, l2, rtol=0, atol=1e-9)
        np.testing.assert_array_equal(l1, u1)
        assert c1 == bool(shift.any())


def _run_scaled(cfg: dict, targets, q0, q_nom, n: int, scale) -> np.ndarray:  # noqa: ANN001
    """As :func:`_run`, the left hand's weight scaled by ``scale(k)`` before tick ``k``."""
    ctrl = Controller(cfg)
    ctrl.reset(q0)
    ctrl.task("posture").set_target(q_nom)
    out = []
    for k in range(n):
        ctrl.set_weight_scale("left_hand", scale(k))
        out.append(np.array(ctrl.step(targets(k)).q))
    return np.asarray(out)


def test_a_weight_scale_is_the_scaled_config_in_the_kernel_and_in_python(
    shared_dir: Path,
) -> None:
    """Controller.set_weight_scale: the same QP as a config with the scaled weight."""
    cfg, targets, q0, q_nom = _workload(shared_dir, "A")
    scaled_cfg = copy.deepcopy(cfg)
    for t in scaled_cfg["tasks"]:
        if t["name"] == "left_hand":
            t["weight"] = 0.05 * float(t.get("weight", 1.0))
    q_ref = _run(scaled_cfg, targets, q0, q_nom, 60)
    q_s = _run_scaled(cfg, targets, q0, q_nom, 60, lambda k: 0.05)
    # Same weights, same QP: equal to round-off (1e-10 rad: the product w * rows in another order).
    assert np.abs(q_s - q_ref).max() <= 1e-10

    # A scale changed mid-run (0.05 for ticks 20-39): the kernel takes it as Python does, and
    # the run differs from the unscaled one.
    def mid(k: int) -> float:
        return 0.05 if 20 <= k < 40 else 1.0

    q_c = _run_scaled(cfg, targets, q0, q_nom, 60, mid)
    with python_only():
        q_p = _run_scaled(cfg, targets, q0, q_nom, 60, mid)
    assert np.abs(q_c - q_p).max() <= 1e-10
    assert np.abs(q_c - _run(cfg, targets, q0, q_nom, 60)).max() > 1e-4


def test_a_bad_weight_scale_is_one_clear_error(shared_dir: Path) -> None:
    cfg, _, _, _ = _workload(shared_dir, "A")
    ctrl = Controller(cfg)
    with pytest.raises(ConfigError, match="weight scale must be a finite number >= 0"):
        ctrl.set_weight_scale("left_hand", float("nan"))
    with pytest.raises(ConfigError, match="no task named 'left_hnd'.*left_hand"):
        ctrl.set_weight_scale("left_hnd", 0.5)
    with pytest.raises(ConfigError, match="one finite number >= 0 or 3 of them"):
        ctrl.set_weight_scale("left_hand", [0.5, 0.5])  # a position task has 3 rows
    # One factor per row: the rows' weights scaled each by its own.
    w = ctrl.tasks["left_hand"].weight.copy()
    ctrl.set_weight_scale("left_hand", [1.0, 0.5, 0.0])
    assert np.array_equal(ctrl.tasks["left_hand"].weight, w * [1.0, 0.5, 0.0])
    ctrl.set_weight_scale("left_hand", 1.0)
    assert np.array_equal(ctrl.tasks["left_hand"].weight, w)
