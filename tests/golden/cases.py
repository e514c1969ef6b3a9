# SPDX-License-Identifier: Apache-2.0
"""Golden runs: the configurations q of fixed runs, recorded before a refactor.

``python -m tests.golden.cases --write`` (from the repository root) records them into
``tests/golden/golden.npz``; ``tests/test_golden.py`` re-runs them and compares. Cases: three
shared clips retargeted with the shipped G1 whole-body config (a gesture clip, a walk-and-stop,
the dance spin), the whole-body demo controller with support phases on a walk, 200 ticks of
workload B of ../shared/bench, and scripted targets through the acceleration-level (CRAC) and
hierarchy controllers, so every tick path is covered.

Every golden run executes in a child process with a pinned floating-point environment
(:func:`pinned_env`): the same numbers on every x86-64 machine. Without it the recording is a
property of the CPU it was made on: OpenBLAS picks its kernels by CPU model (Haswell on an AVX2
AMD EPYC, SkylakeX on an AVX-512 Xeon) and numpy dispatches its loops by CPU feature, and their
different summation orders differ in the last bit, which the acceleration-level CRAC run
amplifies to 2e-5 rad in 2 s (measured: the same commit, Haswell vs Sandybridge kernels on one
machine, 2.0e-5; Haswell vs the Xeon's recording, 2.0e-5). Pinned: OpenBLAS's generic SSE3
kernels (``OPENBLAS_CORETYPE=Prescott``, every x86-64 CPU runs them), numpy's baseline loops
(``NPY_DISABLE_CPU_FEATURES`` = every dispatch target of the installed numpy), one thread.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import tempfile
from collections.abc import Callable, Sequence
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


#: Key of the golden file that records the platform of the recording (not a case).
PLATFORM_KEY = "_platform"


def pinned_env() -> dict[str, str]:
    """The environment of a golden run: the process's own, with the floating-point paths pinned.

    ``OPENBLAS_CORETYPE=Prescott`` (x86-64 only: OpenBLAS's SSE3 kernels, which every x86-64
    CPU has), ``NPY_DISABLE_CPU_FEATURES`` listing every SIMD dispatch target numpy was built
    with (so it runs its baseline loops), and one BLAS/OpenMP thread.
    """
    from numpy._core import _multiarray_umath as umath

    env = dict(os.environ)
    env.update(OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    env["NPY_DISABLE_CPU_FEATURES"] = " ".join(getattr(umath, "__cpu_dispatch__", []))
    if platform.machine().lower() in ("x86_64", "amd64"):
        env["OPENBLAS_CORETYPE"] = "Prescott"
    return env


def platform_tag() -> str:
    """What a recording depends on beyond the code: machine architecture and numpy version."""
    return f"{platform.machine()} numpy {np.__version__} python {platform.python_version()}"


def run_pinned(names: Sequence[str]) -> dict[str, np.ndarray]:
    """Run the named cases in one child process with :func:`pinned_env`; return their q."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "runs.npz"
        cmd = [sys.executable, str(Path(__file__).resolve()), "--run", *names, "--out", str(out)]
        proc = subprocess.run(cmd, env=pinned_env(), capture_output=True, text=True, check=False)
        if proc.returncode != 0:
            raise RuntimeError(
                f"golden cases {list(names)} failed in the child process "
                f"(exit {proc.returncode}):\n{proc.stderr[-4000:]}"
            )
        with np.load(out) as z:
            return {k: z[k] for k in z.files}


def _run_child(argv: list[str]) -> int:
    """``--run NAME ... --out FILE``: the child side of :func:`run_pinned`."""
    i, j = argv.index("--run"), argv.index("--out")
    names, out = argv[i + 1 : j], Path(argv[j + 1])
    np.savez(out, **{name: run_case(name) for name in names})
    return 0


def main(argv: list[str]) -> int:
    """``--write`` records every case; ``--write NAME ...`` re-records only those (the others are
    kept as recorded), for a change that moves some cases on purpose. Each is run by
    :func:`run_pinned`."""
    if "--run" in argv and "--out" in argv:
        return _run_child(argv)
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
            data = {k: z[k] for k in z.files if k != PLATFORM_KEY}
    data.update(run_pinned(names))
    for name in names:
        print(f"{name}: {data[name].shape}")
    data[PLATFORM_KEY] = np.array(json.dumps({"platform": platform_tag()}))
    from qpretarget.fileio import atomic_path

    with atomic_path(GOLDEN, suffix=".npz") as tmp:
        np.savez_compressed(tmp, **data)
    print(f"wrote {GOLDEN}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
