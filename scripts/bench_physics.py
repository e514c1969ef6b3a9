"""Physics replay of shared clips: metrics table (docs/physics.md) and real-time factor.

    python scripts/bench_physics.py configs/g1_whole_body.yaml ../shared/data/mocap/*.bvh \
        --ramp 2.0 --gains stiff --out bench_physics.json

Retargets each clip with CONFIG (optionally with the start ramp lengthened to --ramp seconds),
replays it unassisted and assisted, prints one Markdown row per clip and the wall time of the
replays (median, p95, p99 of the per-clip real-time factors).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np


def _config(path: Path, ramp: float | None, tmp: Path) -> Path:
    """``path`` itself, or a copy whose ``retarget.calibration.ramp_time`` is ``ramp``."""
    if ramp is None:
        return path
    import yaml

    from qpretarget.yamlio import load_yaml

    cfg = load_yaml(path.read_text(encoding="utf-8"))
    calib = dict(cfg["retarget"].get("calibration") or {})
    calib["ramp_time"] = ramp
    cfg["retarget"]["calibration"] = calib
    p = tmp / f"{path.stem}_ramp{ramp}.yaml"
    p.write_text(yaml.safe_dump(cfg, sort_keys=False), encoding="utf-8")
    return p


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("config")
    ap.add_argument("clips", nargs="+")
    ap.add_argument("--ramp", type=float, default=None, help="calibration ramp_time [s]")
    ap.add_argument("--gains", default=None)
    ap.add_argument("--end", type=float, default=None, help="clip end [s]")
    ap.add_argument("--out", default=None, help="JSON with every clip's metrics")
    args = ap.parse_args()

    from qpretarget.control.controller import Controller
    from qpretarget.motion import load_motion
    from qpretarget.physics.metrics import summary_row
    from qpretarget.physics.model import build_physics_model
    from qpretarget.physics.replay import check_run
    from qpretarget.retarget import Retargeter

    tmp = Path(tempfile.mkdtemp())
    cfg = _config(Path(args.config), args.ramp, tmp)
    controller = Controller.from_yaml(cfg)
    pm = build_physics_model(controller.robot, gains=args.gains)
    rows, factors = {}, []
    print(
        "| clip | s | verdict | survived | sat. frames | root p95 mm | joint RMS deg "
        "| feet share | assist F p95 %BW | horiz. p95 %BW | assist n p95 N m | x real time |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for clip in args.clips:
        controller.reset()
        motion = load_motion(clip)
        if args.end is not None:
            motion = motion.slice(0.0, args.end) if hasattr(motion, "slice") else motion
        run = Retargeter(controller).retarget(motion, progress=False)
        t0 = time.perf_counter()
        m, free, helped = check_run(run, pm=pm)
        wall = time.perf_counter() - t0
        r = summary_row(m)
        dur = float(run.t[-1] - run.t[0])
        factors.append(2 * dur / wall)  # two replays per clip
        rows[Path(clip).name] = {"row": r, "metrics": m, "duration_s": dur}
        print(
            f"| {Path(clip).stem} | {dur:.1f} | {r['verdict']} | {r['survived'] * 100:.0f} % | "
            f"{r['saturated_frames']} | {r['root_pos_p95_mm']:.0f} | {r['joint_rms_deg']:.2f} | "
            f"{r['feet_share'] * 100:.0f} % | {r['assist_force_p95_bw_pct']:.1f} | "
            f"{r['assist_horizontal_p95_bw_pct']:.1f} | "
            f"{r['assist_torque_p95_Nm']:.1f} | {r['real_time_factor']:.0f} |",
            flush=True,
        )
    f = np.array(factors)
    print(
        f"real-time factor of both replays together: median {np.median(f):.1f}, "
        f"slowest 5 % {np.percentile(f, 5):.1f}, slowest 1 % {np.percentile(f, 1):.1f}"
    )
    if args.out:
        Path(args.out).write_text(json.dumps(rows, indent=1, default=str), encoding="utf-8")


if __name__ == "__main__":
    main()
