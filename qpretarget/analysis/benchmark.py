# SPDX-License-Identifier: Apache-2.0
"""Per-tick timing of a controller: ticks per second, median and p95 of step and solve time.

Times are also split by stage (tasks, bounds, each row constraint, assembly, solve, kinematics).

Used by ``qpretarget bench`` and ``scripts/bench_step.py``. Timing uses ``time.perf_counter``
around the public :meth:`Controller.step` (targets in, solve, integrate, kinematics out), after
a warm-up, like the anchors of ``../shared/bench``.
"""

from __future__ import annotations

import copy
import os
import platform
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..control.controller import Controller
from ..yamlio import load_yaml


def machine_info() -> dict[str, Any]:
    """CPU, Python and library versions, printed with every benchmark."""
    import pinocchio
    import proxsuite
    import qpsolvers

    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "pinocchio": pinocchio.__version__,
        "proxsuite": proxsuite.__version__,
        "qpsolvers": qpsolvers.__version__,
    }


def _stats(x: Sequence[float]) -> dict[str, float]:
    a = np.asarray(x, dtype=float) * 1e6
    return {
        "median_us": float(np.median(a)),
        "p95_us": float(np.percentile(a, 95)),
        "max_us": float(a.max()),
    }


def load_config(config: str | Path | dict[str, Any]) -> tuple[dict[str, Any], Path | None]:
    """Return the config mapping and its folder."""
    if isinstance(config, dict):
        return copy.deepcopy(config), None
    path = Path(config)
    return load_yaml(path.read_text()), path.parent


def bench_config(
    config: str | Path | dict[str, Any],
    *,
    solver: str | dict[str, Any] | None = None,
    ticks: int = 1000,
    warmup: int = 200,
    passes: int = 3,
) -> dict[str, Any]:
    """Run ``passes`` timed passes of ``ticks`` ticks on scripted targets and return statistics.

    Args:
        config: YAML path or mapping.
        solver: solver name or mapping overriding the config's ``solver:``.
        ticks: timed ticks per pass.
        warmup: untimed ticks before the timed passes.
        passes: timed passes, each from the reference posture.

    Returns:
        ``{"step": {...}, "solve": {...}, "stages": {name: {...}}, "ticks_per_s": float,
        "failures": int, "solver": str}``; times in microseconds.
    """
    from .solver_comparison import scripted_targets

    cfg, base = load_config(config)
    if solver is not None:
        cfg["solver"] = solver if isinstance(solver, dict) else {"name": solver}
    ctrl = Controller(cfg, base_dir=base)
    targets = list(scripted_targets(ctrl, (warmup + ticks) * ctrl.dt))
    ctrl.reset()
    for k in range(warmup):
        ctrl.step(targets[k])
    step_t, solve_t, wall = [], [], []
    stages: dict[str, list[float]] = {}
    failures = 0
    perf = time.perf_counter
    for _ in range(passes):
        ctrl.reset()
        w0 = perf()
        for k in range(ticks):
            t0 = perf()
            res = ctrl.step(targets[warmup // 2 + k] if warmup // 2 + k < len(targets) else None)
            step_t.append(perf() - t0)
            solve_t.append(res.solve_time)
            failures += res.status == "held"
            for name, v in ctrl.last_timings.items():
                stages.setdefault(name, []).append(v)
        wall.append(perf() - w0)
    return {
        "config": str(config) if not isinstance(config, dict) else cfg.get("name", "config"),
        "solver": (cfg.get("solver") or {}).get("name", "proxsuite")
        if isinstance(cfg.get("solver"), dict)
        else str(cfg.get("solver", "proxsuite")),
        "ticks": ticks * passes,
        "ticks_per_s": float(ticks / np.median(wall)),
        "step": _stats(step_t),
        "solve": _stats(solve_t),
        "stages": {k: _stats(v) for k, v in stages.items()},
        "failures": failures,
    }


def format_table(results: list[dict[str, Any]]) -> str:
    """Markdown table of :func:`bench_config` results."""
    lines = [
        "| config | solver | ticks/s | step median µs | step p95 µs | solve median µs "
        "| solve p95 µs | held |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in results:
        lines.append(
            f"| {Path(r['config']).stem} | {r['solver']} | {r['ticks_per_s']:.0f} | "
            f"{r['step']['median_us']:.1f} | {r['step']['p95_us']:.1f} | "
            f"{r['solve']['median_us']:.1f} | {r['solve']['p95_us']:.1f} | {r['failures']} |"
        )
    return "\n".join(lines)


def format_stages(result: dict[str, Any]) -> str:
    """Markdown table of the per-stage split of one result."""
    lines = ["| stage | median µs | p95 µs |", "|---|---:|---:|"]
    for k, s in result["stages"].items():
        lines.append(f"| {k} | {s['median_us']:.1f} | {s['p95_us']:.1f} |")
    return "\n".join(lines)
