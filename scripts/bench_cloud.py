# SPDX-License-Identifier: Apache-2.0
"""Benchmark of point-cloud retargeting: time per frame for 2,500 cloud / 5,000 template points.

G1 posed by known joint motion, rendered at full Kinect V2 resolution 2.3 m away (about 7,000
points, voxel-averaged and subsampled to 2,500), 5 mm noise, 5 % outliers; every frame is
tracked from the previous ones (AR prediction) as in a live run. Prints median / p95 / p99 time
per frame and iterations, with the machine and versions (``--profile N``: the E-step's share and
the N costliest functions; the run is then profiled, and its times are slower; ``--stages``: CPU
milliseconds per frame spent in each stage of the fit and in the kd-tree searches, measured by
timers around those functions, which add about 1 ms per frame; the 3-D searches include the
cloud normals' own). The k-nearest-neighbour searches and the E-step's sums use the compiled
point-cloud kernel when it is built (``versions.knn``, ``versions.cloud_kernel``; src/kernel/
cloud.cpp), else pykdtree when it is installed; ``QPRETARGET_KNN=scipy`` (or ``pykdtree``)
forces that search, ``QPRETARGET_CLOUD_KERNEL=0`` the numpy code throughout. With the compiled
kernel a frame's cloud normals are computed on a second thread while its first stages run
(``QPRETARGET_CLOUD_OVERLAP=0``: not; ``QPRETARGET_CLOUD_THREADS=2``: the searches and
posteriors on 2 threads as well), so
``cpu_ms_*`` (the fitting thread's CPU time) can be below the wall time's figures; the
``process_cpu_ms_*`` count every thread.

With ``--clip`` the human model follows a mocap clip at 30 Hz instead (the issue's figure: CMU
14_37 drink, 2,500 cloud points), fitted with the shipped ``configs/cloud_g1.yaml`` (calibration
and joint-centre learning on); the calibration frame is not counted. It also prints the arm
direction error (``qpretarget.cloud.measures.arm_direction_errors``) and, with ``--bound``, its
reachability bound (``reachable_bound_*``, ``qpretarget.cloud.measures.arm_direction_bound``:
the arms nearest the person's within G1's joint limits, the trunk as fitted or free; computed
after the timing, about 1-2 s a frame).

    python scripts/bench_cloud.py [--frames 60] [--json out.json]
    python scripts/bench_cloud.py --clip ../shared/data/mocap/cmu_14_37_drink_soda.bvh
    python scripts/bench_cloud.py --clip ../shared/data/mocap/cmu_14_37_drink_soda.bvh --stages
    python scripts/bench_cloud.py --clip ../shared/data/mocap/cmu_14_07_reach_up_tiptoe.bvh \
        --frames 90 --bound
"""

from __future__ import annotations

import argparse
import cProfile
import json
import os
import platform
import pstats
import time
from collections.abc import Callable
from typing import Any

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--frames", type=int, default=60, help="frames at 30 Hz (default 60 = 2 s)")
    ap.add_argument("--json", help="write the numbers here")
    ap.add_argument("--clip", help="mocap clip the human model follows (default: posed G1)")
    ap.add_argument("--config", default=None, help="cloud config (with --clip; default shipped)")
    ap.add_argument("--profile", type=int, default=0, help="print the N costliest functions")
    ap.add_argument("--rate", type=float, default=30.0, help="clip frames per second (--clip)")
    ap.add_argument("--stages", action="store_true", help="CPU time per stage of the fit")
    ap.add_argument(
        "--bound",
        action="store_true",
        help="reachability bound of the arm-direction error (--clip; 1-2 s a frame)",
    )
    args = ap.parse_args()

    import proxsuite
    import scipy

    import qpretarget as qp
    from qpretarget.cloud.compiled import describe as cloud_kernel_line
    from qpretarget.cloud.em import CloudRetargeter
    from qpretarget.cloud.meshes import load_link_meshes
    from qpretarget.cloud.neighbours import backend as knn_backend
    from qpretarget.cloud.render import kinect_camera, render_sequence
    from qpretarget.cloud.template import Template

    sys_path = os.path.join(os.path.dirname(__file__), "..", "tests", "cloud")
    import sys

    sys.path.insert(0, os.path.abspath(sys_path))
    from conftest import g1_truth  # the known motion of the tests

    g1 = qp.load_robot("g1")
    meshes = load_link_meshes(g1.model, g1.urdf_path)
    t = np.arange(args.frames) / args.rate
    t0 = time.perf_counter()
    if args.clip:
        from qpretarget.cloud.config import CloudConfig
        from qpretarget.cloud.render import clip_cloud_sequence

        syn, poser = clip_cloud_sequence(
            args.clip, rate=args.rate, duration=(args.frames - 1) / args.rate
        )
        config_path = args.config or os.path.join(
            os.path.dirname(__file__), "..", "configs", "cloud_g1.yaml"
        )
        cfg = CloudConfig.from_yaml(config_path)
    else:
        cam = kinect_camera([2.3, 0.4, 1.1], [0.0, 0.0, 0.65], downscale=1)
        syn = render_sequence(g1.model, meshes, g1_truth(g1, t), t, cam)
        cfg = {"robot": "g1", "stability": {"mode": "qp"}, "calibration": {"enabled": False}}
    render_s = (time.perf_counter() - t0) / len(syn.q)
    t0 = time.perf_counter()
    if args.clip:  # the config's template
        rt = CloudRetargeter(cfg, robot=g1)
    else:
        template = Template(g1, n_points=5000, meshes=meshes, link_density_exponent=0.5)
        rt = CloudRetargeter(cfg, robot=g1, template=template)
    template_s = time.perf_counter() - t0
    stage_ms: dict[str, float] = {}
    if args.stages:
        _time_stages(rt, stage_ms)
    prof = cProfile.Profile() if args.profile else None  # the profiler slows the run down
    if prof is not None:
        prof.enable()
    cpu = [time.thread_time()]  # CPU time of this thread per frame: what other load can't add
    pcpu = [time.process_time()]  # ... and of every thread (the compiled kernel's helpers too)

    def tick(i: int, _r: object) -> None:
        cpu.append(time.thread_time())
        pcpu.append(time.process_time())
        if i == 0:
            stage_ms.clear()  # the calibration frame is not counted

    traj, results = rt.run(syn.sequence, callback=tick)
    if prof is not None:
        prof.disable()
    times = np.array([r.time for r in results[1:]])  # the first frame starts from afar
    iters = np.array([r.iterations for r in results[1:]])
    if args.clip:  # the docs' arm-direction error (qpretarget.cloud.measures)
        from qpretarget.cloud.measures import (
            arm_direction_bound,
            arm_direction_errors,
            arm_direction_summary,
        )

        err = arm_direction_errors(g1, traj.q, poser, syn.q)
        summary = arm_direction_summary(err, syn.sequence.t)  # evaluate's figures too
        arms = {
            "arm_direction_deg_worst": summary["worst_deg"],
            "arm_direction_deg_per_segment": {
                k: round(v, 2) for k, v in summary["per_segment_worst_deg"].items()
            },
            "arm_direction_deg_median": summary["median_deg"],
            "frames_above_12deg": summary["frames_above_tolerance"],
            "seconds_above_45deg_longest": summary["longest_lost_s"],
            "frames_not_ok": int(sum(r.status != "ok" for r in results)),
        }
        if args.bound:  # what no fit can go under: the arms nearest the person's within
            for trunk in ("fit", "free"):  # G1's joint limits, the trunk as fitted / free
                b = arm_direction_bound(g1, traj.q, poser, syn.q, trunk=trunk)
                arms[f"reachable_bound_{trunk}_trunk_deg"] = {
                    "worst": float(b.max()),
                    "median": float(np.median(b)),
                    "per_segment": np.round(b.max(axis=0), 2).tolist(),
                    "frames_above_12": int((b.max(axis=1) > 12.0).sum()),
                }
    estep_share = None
    if prof is not None:
        stats = pstats.Stats(prof)
        estep = sum(v[3] for k, v in stats.stats.items() if k[2] == "e_step")
        estep_share = float(estep / sum(r.time for r in results))
    out = {
        "input": args.clip or "G1 posed by known joint motion",
        "frames": len(results),
        "cloud_points_rendered": int(np.median([len(f.points) for f in syn.sequence])),
        "cloud_points_fitted": 2500,
        "template_points": rt.template.n_points,
        "ms_per_frame_median": 1000 * float(np.median(times)),
        "ms_per_frame_p95": 1000 * float(np.percentile(times, 95)),
        "ms_per_frame_p99": 1000 * float(np.percentile(times, 99)),
        "cpu_ms_per_frame_median": 1000 * float(np.median(np.diff(cpu)[1:])),
        "cpu_ms_per_frame_p95": 1000 * float(np.percentile(np.diff(cpu)[1:], 95)),
        "process_cpu_ms_per_frame_median": 1000 * float(np.median(np.diff(pcpu)[1:])),
        "process_cpu_ms_per_frame_p95": 1000 * float(np.percentile(np.diff(pcpu)[1:], 95)),
        "iterations_median": float(np.median(iters)),
        "ms_per_iteration": 1000 * float(times.sum() / iters.sum()),
        "estep_share_profiled": estep_share,
        "template_build_s": template_s,
        "render_s_per_frame": render_s,
        "machine": f"{platform.machine()} {os.cpu_count()} cpu, load {os.getloadavg()[0]:.2f}",
        "versions": {
            "numpy": np.__version__,
            "scipy": scipy.__version__,
            "proxsuite": proxsuite.__version__,
            "knn": knn_backend(),
            "cloud_kernel": cloud_kernel_line(),
        },
        "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS", "unset"),
    }
    if args.clip:
        out.update(arms)
    if args.stages:
        n = max(len(results) - 1, 1)
        out["stages_cpu_ms_per_frame"] = {
            k: round(1000.0 * v / n, 2) for k, v in sorted(stage_ms.items(), key=lambda kv: -kv[1])
        }
    print(json.dumps(out, indent=2))
    if prof is not None:
        stats.sort_stats("tottime").print_stats(args.profile)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=2)


def _time_stages(rt: Any, acc: dict[str, float]) -> None:
    """Wrap the fit's stages (and scipy's kd-tree searches) with CPU timers adding into ``acc``.

    Nested: a stage's time includes the searches and E-steps inside it.
    """
    import qpretarget.cloud.em as em_module
    import qpretarget.cloud.io as io_module

    def timed(fn: Callable[..., Any], label: str) -> Callable[..., Any]:
        def wrapper(*a: Any, **k: Any) -> Any:
            t0 = time.thread_time()
            try:
                return fn(*a, **k)
            finally:
                acc[label] = acc.get(label, 0.0) + time.thread_time() - t0

        return wrapper

    em_stage = rt._em_stage

    def stage(name: str, *a: Any, **k: Any) -> Any:
        return timed(em_stage, f"stage {name}")(name, *a, **k)

    rt._em_stage = stage
    for attr, label in (
        ("_prepare", "cloud preparation (crop, voxels, normals)"),
        ("_centre_stage", "stage centres"),
        ("final_nll", "final NLL"),
        ("_active", "visible template points"),
        ("_solve_step", "M-step QPs (with priors, rows)"),
        ("_line_search", "line searches"),
    ):
        setattr(rt, attr, timed(getattr(rt, attr), label))
    em_module.e_step = timed(em_module.e_step, "E-steps (with their searches)")
    io_module.estimate_normals = timed(io_module.estimate_normals, "cloud normals")
    em_module.estimate_normals = io_module.estimate_normals

    import qpretarget.cloud.neighbours as nn_module

    knn = nn_module.knn

    def timed_knn(data: Any, query: Any, k: int) -> Any:
        t0 = time.thread_time()
        try:
            return knn(data, query, k)
        finally:
            label = f"kd-tree searches {np.shape(data)[1]}-D"
            acc[label] = acc.get(label, 0.0) + time.thread_time() - t0

    import qpretarget.cloud.estep as estep_module

    nn_module.knn = timed_knn
    estep_module.knn = timed_knn  # the E-step's searches (its module holds its own name)


if __name__ == "__main__":
    main()
