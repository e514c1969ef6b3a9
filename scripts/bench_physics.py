"""Physics replay of shared clips: metrics table (docs/physics.md) and real-time factor.

    python scripts/bench_physics.py configs/g1_whole_body.yaml ../shared/data/mocap/*.bvh \
        --ramp 2.0 --gains stiff --out bench_physics.json

Retargets each clip with CONFIG (optionally with the start ramp lengthened to --ramp seconds),
replays it unassisted and assisted, prints one Markdown row per clip and the wall time of the
replays (median, p95, p99 of the per-clip real-time factors).

    python scripts/bench_physics.py --stance g1 talos

holds each robot's reference posture for 2 s with every gain profile that applies to it (the
docs' quiet-stance table).
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


def stance(robots: list[str], feedforward: str) -> None:
    """Quiet stance: each robot's reference posture held for 2 s, per gain profile."""
    from qpretarget.physics.gains import GAIN_PROFILES
    from qpretarget.physics.model import build_physics_model
    from qpretarget.physics.replay import check_run
    from qpretarget.robot import RobotModel
    from qpretarget.trajectory import RobotTrajectory

    print("| robot | gains | verdict | base error p95 | joint RMS | feet share |")
    print("|---|---|---|---|---|---|")
    for name in robots:
        robot = RobotModel.from_name(name)
        T = 200
        traj = RobotTrajectory(
            t=np.arange(T) * 0.01,
            q=np.tile(robot.q_reference, (T, 1)),
            v=np.zeros((T, robot.nv)),
            joint_names=list(robot.joint_names),
            robot=name,
            config_yaml=f"robot: {name}\n",
        )
        for g, prof in GAIN_PROFILES.items():
            if prof.robots and name not in prof.robots:
                continue
            pm = build_physics_model(robot, gains=g)
            m, _, _ = check_run(traj, pm=pm, assisted=False, feedforward=feedforward)
            u = m["unassisted"]
            fell = u["fallen_at_s"]
            verdict = m["verdict"] if fell is None else f"falls at {fell:.2f} s"
            print(
                f"| {name} | `{g}` | {verdict} | {u['root_position_error_mm']['p95']:.1f} mm | "
                f"{u['joint_tracking_rms_deg']['overall']:.2f} deg | "
                f"{u['feet']['weight_share_mean'] * 100:.0f} % |"
            )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("config", nargs="?")
    ap.add_argument("clips", nargs="*")
    ap.add_argument("--stance", nargs="+", metavar="ROBOT", help="quiet-stance table instead")
    ap.add_argument("--feedforward", default="gravity", help="gravity (default) or none")
    ap.add_argument("--ramp", type=float, default=None, help="calibration ramp_time [s]")
    ap.add_argument("--gains", default=None)
    ap.add_argument("--end", type=float, default=None, help="clip end [s]")
    ap.add_argument("--out", default=None, help="JSON with every clip's metrics")
    args = ap.parse_args()
    if args.stance:
        stance(args.stance, args.feedforward)
        return
    if not args.config or not args.clips:
        ap.error("give CONFIG and clips, or --stance ROBOT...")

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
        "| feet share | assist F p95 %BW | horiz. p95 %BW | assist n p95 N m "
        "| ref. ZMP out (first s) | x real time |"
    )
    print("|---" * 13 + "|")
    for clip in args.clips:
        controller.reset()
        motion = load_motion(clip)
        if args.end is not None:
            motion = motion.slice(0.0, args.end)
        run = Retargeter(controller).retarget(motion, progress=False)
        t0 = time.perf_counter()
        m, free, helped = check_run(run, pm=pm, feedforward=args.feedforward)
        wall = time.perf_counter() - t0
        r = summary_row(m)
        dur = float(run.t[-1] - run.t[0])
        factors.append(2 * dur / wall)  # two replays per clip
        rows[Path(clip).name] = {"row": r, "metrics": m, "duration_s": dur}
        z = m.get("reference_zmp", {})
        first = z.get("first_outside_s")
        zmp = f"{z.get('frames_outside', '-')}" + ("" if first is None else f" ({first:.2f})")
        print(
            f"| {Path(clip).stem} | {dur:.1f} | {r['verdict']} | {r['survived'] * 100:.0f} % | "
            f"{r['saturated_frames']} | {r['root_pos_p95_mm']:.0f} | {r['joint_rms_deg']:.2f} | "
            f"{r['feet_share'] * 100:.0f} % | {r['assist_force_p95_bw_pct']:.1f} | "
            f"{r['assist_horizontal_p95_bw_pct']:.1f} | "
            f"{r['assist_torque_p95_Nm']:.1f} | {zmp} | "
            f"{r['real_time_factor']:.0f} |",
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
