# SPDX-License-Identifier: Apache-2.0
"""Golden runs: the configurations q of fixed runs, recorded before a refactor.

``python -m tests.golden.cases --write`` (from the repository root) records them into
``tests/golden/golden.npz``; ``tests/test_golden.py`` re-runs them and compares. Cases: three
shared clips retargeted with the shipped G1 whole-body config (a gesture clip, a walk-and-stop,
the dance spin), the whole-body demo controller with support phases on a walk, 200 ticks of
workload B of ../shared/bench, and scripted targets through the acceleration-level (CRAC) and
hierarchy controllers, so every tick path is covered.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
SHARED = REPO.parent / "shared"
MOCAP = SHARED / "data" / "mocap"
BENCH = SHARED / "bench"
GOLDEN = Path(__file__).resolve().parent / "golden.npz"


#: Solver of every golden run. ProxSuite's dense solver is not bit-reproducible (the same QP
#: solved twice in one process can differ in the last bit: its workspace alignment varies, see
#: docs/reliability.md), and chaotic clips amplify that; daqp is, so the golden runs use it and
#: test every other part of the tick to the last bit. Recorded through qpsolvers' daqp (cold
#: start each tick), before the direct hot-started backend existed: that path is kept as is.
SOLVER = {"name": "qpsolvers/daqp"}


def _controller(path: Path):  # noqa: ANN202
    from qpretarget import Controller
    from qpretarget.yamlio import load_yaml

    cfg = load_yaml(path.read_text(encoding="utf-8"))
    cfg["solver"] = dict(SOLVER)
    return Controller(cfg, base_dir=path.parent)


def _clip_run(config: str, clip: str, start: float, end: float) -> np.ndarray:
    from qpretarget.motion import load_motion
    from qpretarget.retarget.retargeter import Retargeter

    ctrl = _controller(REPO / "configs" / config)
    motion = load_motion(MOCAP / clip).slice(start, end)
    traj = Retargeter(ctrl).retarget(motion, progress=False)
    return np.asarray(traj.q)


def _demo_walk() -> np.ndarray:
    from qpretarget import Controller
    from qpretarget.motion import load_motion
    from qpretarget.retarget.retargeter import Retargeter, whole_body_config
    from qpretarget.yamlio import load_yaml

    path = REPO / "configs" / "g1_whole_body.yaml"
    cfg = whole_body_config("g1", base=load_yaml(path.read_text(encoding="utf-8")))
    cfg["solver"] = dict(SOLVER)
    ctrl = Controller(cfg, base_dir=path.parent)
    motion = load_motion(MOCAP / "cmu_16_15_walk.bvh").slice(0.0, 2.5)
    traj = Retargeter(ctrl).retarget(motion, progress=False)
    return np.asarray(traj.q)


def _workload_b(n_ticks: int = 200) -> np.ndarray:
    import yaml

    wl = yaml.safe_load((BENCH / "workload_g1.yaml").read_text())
    tg = np.load(BENCH / wl["targets_file"])
    ctrl = _controller(BENCH / "anchors" / "qpretarget_g1_B.yaml")
    t = wl["tasks"]
    frames = ("pelvis", "torso", "left_hand", "right_hand", "left_elbow", "right_elbow", "head")
    T = {name: tg[f"T_{t[name]['frame']}"] for name in frames}
    ctrl.reset(np.asarray(tg["q_init"], dtype=float))
    ctrl.task("posture").set_target(np.asarray(tg["q_nominal"], dtype=float))
    out = []
    for k in range(1, n_ticks + 1):
        d = {"pelvis": T["pelvis"][k], "torso": T["torso"][k][:3, :3], "com": tg["com"][k]}
        for name in ("left_hand", "right_hand", "left_elbow", "right_elbow", "head"):
            d[name] = T[name][k][:3, 3]
        out.append(np.array(ctrl.step(d).q))
    return np.asarray(out)


def _scripted(config: str, seconds: float = 2.0) -> np.ndarray:
    from qpretarget.analysis.solver_comparison import scripted_targets

    ctrl = _controller(REPO / "configs" / config)
    out = []
    for targets in scripted_targets(ctrl, seconds, amplitude=1.5):
        out.append(np.array(ctrl.step(targets).q))
    return np.asarray(out)


CASES: dict[str, Callable[[], np.ndarray]] = {
    "teapot_whole_body": lambda: _clip_run(
        "g1_whole_body.yaml", "cmu_29_03_teapot_arm_gestures.bvh", 0.0, 3.0
    ),
    "walk_stop_whole_body": lambda: _clip_run(
        "g1_whole_body.yaml", "cmu_16_33_walk_stop.bvh", 0.0, 3.0
    ),
    "dance_spin_whole_body": lambda: _clip_run(
        "g1_whole_body.yaml", "cmu_131_04_dance_spin.bvh", 0.0, 2.0
    ),
    "demo_walk_support": _demo_walk,
    "workload_b_200": _workload_b,
    "crac_acceleration_ts2": lambda: _scripted("crac_ts2_acceleration_crac.yaml"),
    "hierarchy_velocity_ts2": lambda: _scripted("crac_ts2_velocity_hierarchy.yaml"),
}


def run_case(name: str) -> np.ndarray:
    """Run one case on the Python path of every module.

    The golden runs were recorded in Python; the compiled kernel gives the same ticks to
    round-off, which the chaotic clips amplify (tests/test_kernel.py compares the two paths).
    """
    from qpretarget.kernel import python_only

    with python_only():
        return CASES[name]()


def main(argv: list[str]) -> int:
    """``--write`` records every case; ``--write NAME ...`` re-records only those (the others are
    kept as recorded), for a change that moves some cases on purpose."""
    if "--write" not in argv:
        print(__doc__)
        return 2
    names = argv[argv.index("--write") + 1 :] or list(CASES)
    unknown = [n for n in names if n not in CASES]
    if unknown:
        print(f"unknown case(s) {unknown}; cases: {', '.join(CASES)}")
        return 2
    data: dict[str, np.ndarray] = {}
    if GOLDEN.exists() and len(names) < len(CASES):
        with np.load(GOLDEN) as z:
            data = {k: z[k] for k in z.files}
    for name in names:
        data[name] = run_case(name)
        print(f"{name}: {data[name].shape}")
    np.savez_compressed(GOLDEN, **data)
    print(f"wrote {GOLDEN}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
