# SPDX-License-Identifier: Apache-2.0
"""Benchmark of point-cloud retargeting: time per frame for 2,500 cloud / 5,000 template points.

G1 posed by known joint motion, rendered at full Kinect V2 resolution 2.3 m away (about 7,000
points, voxel-averaged and subsampled to 2,500), 5 mm noise, 5 % outliers; every frame is
tracked from the previous ones (AR prediction) as in a live run. Prints median / p95 time per
frame, iterations and the E-step's share, with the machine and versions.

    python scripts/bench_cloud.py [--frames 60] [--json out.json]
"""

from __future__ import annotations

import argparse
import cProfile
import json
import os
import platform
import pstats
import time

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--frames", type=int, default=60, help="frames at 30 Hz (default 60 = 2 s)")
    ap.add_argument("--json", help="write the numbers here")
    args = ap.parse_args()

    import proxsuite
    import scipy

    import qpretarget as qp
    from qpretarget.cloud.em import CloudRetargeter
    from qpretarget.cloud.meshes import load_link_meshes
    from qpretarget.cloud.render import kinect_camera, render_sequence
    from qpretarget.cloud.template import Template

    sys_path = os.path.join(os.path.dirname(__file__), "..", "tests", "cloud")
    import sys

    sys.path.insert(0, os.path.abspath(sys_path))
    from conftest import g1_truth  # the known motion of the tests

    g1 = qp.load_robot("g1")
    meshes = load_link_meshes(g1.model, g1.urdf_path)
    t = np.arange(args.frames) / 30.0
    cam = kinect_camera([2.3, 0.4, 1.1], [0.0, 0.0, 0.65], downscale=1)
    t0 = time.perf_counter()
    syn = render_sequence(g1.model, meshes, g1_truth(g1, t), t, cam)
    render_s = (time.perf_counter() - t0) / len(t)
    t0 = time.perf_counter()
    template = Template(g1, n_points=5000, meshes=meshes, link_density_exponent=0.5)
    template_s = time.perf_counter() - t0
    cfg = {"robot": "g1", "stability": {"mode": "qp"}, "calibration": {"enabled": False}}
    rt = CloudRetargeter(cfg, robot=g1, template=template)
    prof = cProfile.Profile()
    prof.enable()
    _, results = rt.run(syn.sequence)
    prof.disable()
    times = np.array([r.time for r in results[1:]])  # the first frame starts from afar
    iters = np.array([r.iterations for r in results[1:]])
    stats = pstats.Stats(prof)
    estep = sum(v[3] for k, v in stats.stats.items() if k[2] == "e_step")
    total = sum(r.time for r in results)
    out = {
        "frames": len(results),
        "cloud_points_rendered": int(np.median([len(f.points) for f in syn.sequence])),
        "cloud_points_fitted": 2500,
        "template_points": template.n_points,
        "ms_per_frame_median": 1000 * float(np.median(times)),
        "ms_per_frame_p95": 1000 * float(np.percentile(times, 95)),
        "iterations_median": float(np.median(iters)),
        "ms_per_iteration": 1000 * float(times.sum() / iters.sum()),
        "estep_share": float(estep / total),
        "template_build_s": template_s,
        "render_s_per_frame": render_s,
        "machine": f"{platform.machine()} {os.cpu_count()} cpu, load {os.getloadavg()[0]:.2f}",
        "versions": {
            "numpy": np.__version__,
            "scipy": scipy.__version__,
            "proxsuite": proxsuite.__version__,
        },
        "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS", "unset"),
    }
    print(json.dumps(out, indent=2))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=2)


if __name__ == "__main__":
    main()
