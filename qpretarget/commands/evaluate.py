# SPDX-License-Identifier: Apache-2.0
"""``qpretarget evaluate``: metrics.json and figures of a saved run (docs/metrics.md)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from . import add_command, add_output

SUMMARY = "metrics (metrics.json) and figures of a saved run"
DESCRIPTION = (
    "Recompute the metrics of a run from its trajectory and robot model (tracking RMSE, "
    "joint-limit and self-collision violations per frame, pair distances, CoM margin, "
    "foot slip, velocity/acceleration/jerk peaks, average absolute power of CRAC eq. 43, "
    "solve times), write metrics.json and PNG figures."
)

HELP = """examples:
  qpretarget evaluate run.npz -o report/
      metrics.json + tracking, pair distances, joint angles, violations, CoM, power figures
  qpretarget evaluate run.npz -o report/ --before run_unconstrained.npz
      the same motion retargeted with the constraints off, shown beside (CRAC Fig. 3-4, 11)
  qpretarget evaluate run.npz -o report/ --no-figures --pairs left_wrist_yaw_link:torso_link
      metrics only, for the collision pairs given (the mesh audit below still covers every pair)
  qpretarget evaluate run.npz -o report/ --physics
      also replay the run in MuJoCo (physics.json, physics.png): does the robot stay up, which
      joints hit their torque limits, what a virtual root wrench had to add (docs/physics.md)
  qpretarget evaluate run.npz -o report/ --physics --physics-gains unitree --no-assist
      the vendor's PD gains, unassisted replay only

A point-cloud run (retarget-cloud) of make-cloud's clouds is also scored against the rendered
person: the "arm directions" line, metrics.json "cloud_arm_directions", arm_directions.png.

Every run is also audited for self-collision over every body pair on the meshes, whatever the
config or --pairs say (metrics.json "mesh_self_collision", self_collision_all_pairs.png, and the
"mesh collision" line: penetrating frames and minimum distance; docs/collisions.md).
"""


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``evaluate`` subcommand."""
    p = add_command(sub, "evaluate", help=SUMMARY, description=DESCRIPTION, examples=HELP)
    p.add_argument("run", help="run file (.npz) written by qpretarget")
    add_output(p, "output directory")
    p.add_argument("--before", help="the same motion run with the constraints off (.npz)")
    p.add_argument(
        "--pairs",
        nargs="+",
        metavar="LINK_A:LINK_B",
        help="collision pairs to measure (default: the config's self-collision pairs, else 16 "
        "upper-body pairs)",
    )
    p.add_argument("--safety-distance", type=float, help="safety distance [m] drawn and counted")
    p.add_argument(
        "--joints", nargs="+", help="joints of the joint-angle figure (default: right arm)"
    )
    p.add_argument("--no-figures", action="store_true", help="write metrics.json only")
    p.add_argument(
        "--no-per-frame", action="store_true", help="leave per-frame arrays out of metrics.json"
    )
    p.add_argument(
        "--physics",
        action="store_true",
        help="replay the run in MuJoCo (needs the physics extra): physics.json and physics.png",
    )
    p.add_argument(
        "--physics-gains",
        default=None,
        help="PD gain profile: stiff (default), unitree, beyondmimic (G1), generic",
    )
    p.add_argument("--physics-timestep", type=float, default=None, help="physics step [s]")
    p.add_argument(
        "--physics-feedforward",
        choices=("gravity", "none"),
        default="gravity",
        help="torque feed-forward added to the PD: the static torques holding the reference "
        "posture on its stance feet (default), or none",
    )
    p.add_argument("--no-assist", action="store_true", help="skip the assisted replay")
    p.set_defaults(func=run)


def _pairs(values: list[str] | None) -> list[tuple[str, str]] | None:
    from ..analysis.metrics import MetricsError

    if not values:
        return None
    out = []
    for v in values:
        parts = v.split(":")
        if len(parts) != 2 or not all(parts):
            raise MetricsError(
                f"--pairs: {v!r} must be LINK_A:LINK_B, e.g. left_wrist_yaw_link:torso_link."
            )
        out.append((parts[0], parts[1]))
    return out


def run(args: argparse.Namespace) -> int:
    """Compute the metrics, write metrics.json and the figures, print a summary."""
    from ..analysis.human_metrics import human_metrics_or_reason
    from ..analysis.metrics import compute_series, dumps, summarize
    from ..fileio import write_atomic
    from ..trajectory import RobotTrajectory

    out = Path(args.output)
    pairs = _pairs(args.pairs)
    traj = RobotTrajectory.load(args.run)
    if args.physics:  # a missing or old mujoco is said before any work
        from ..physics.model import import_mujoco

        import_mujoco()
    series = compute_series(traj, pairs=pairs, safety_distance=args.safety_distance)
    metrics = summarize(series, per_frame=not args.no_per_frame)
    human, reason = human_metrics_or_reason(traj)
    cloud_run = traj.meta.get("command") == "retarget-cloud"
    if human is None and cloud_run:
        reason = (
            "a point-cloud run has no human key-points (its arms are scored against the "
            "rendered person below when the clouds came from make-cloud)"
        )
    metrics["human"] = human if human is not None else {"unavailable": reason}
    from ..analysis.mesh_audit import audit_lines, audit_run, plot_audit

    robot = traj.make_controller().robot
    arm_errors = _cloud_arms(traj, robot, metrics, per_frame=not args.no_per_frame)
    audit = audit_run(traj.q, robot)  # every pair, whatever the config
    metrics["mesh_self_collision"] = audit.to_dict() if audit else {"unavailable": "no geometry"}
    before = None
    if args.before:
        btraj = RobotTrajectory.load(args.before)
        named = [p.split("/", 1) for p in series.pair_names]
        same_pairs = pairs or [(a, b) for a, b in named] or None
        before = compute_series(btraj, pairs=same_pairs, safety_distance=series.safety_distance)
        bm = summarize(before, per_frame=False)
        metrics["before"] = {
            "run": str(args.before),
            "joint_limits": bm["joint_limits"],
            "self_collision": {k: v for k, v in bm["self_collision"].items() if k != "pairs"},
            "violations": bm["violations"],
            "power": bm["power"],
            "tracking_rmse_mean_m": bm["tracking_rmse_mean_m"],
        }
        metrics["before_per_frame"] = {
            "joint_limit_violations": [int(x) for x in before.joint_violations_per_frame],
            "self_collision_violations": [int(x) for x in before.collision_violations_per_frame],
        }
    out.mkdir(parents=True, exist_ok=True)
    text = dumps(metrics)
    write_atomic(out / "metrics.json", lambda f: f.write(text), binary=False)
    written = [out / "metrics.json"]
    if not args.no_figures:
        from ..analysis.plots import write_figures

        written += list(write_figures(series, out, before=before, joints=args.joints).values())
        if audit:
            written.append(plot_audit(audit, traj.t, out / "self_collision_all_pairs.png"))
        if arm_errors is not None:
            from ..cloud.plots import plot_arm_directions

            written.append(plot_arm_directions(arm_errors, traj.t, out / "arm_directions.png"))
    _print_summary(metrics)
    print("\n".join(f"{'mesh collision' if i == 0 else '':16s} {x}"
                    for i, x in enumerate(audit_lines(audit))))  # fmt: skip
    if args.physics:
        written += _physics(traj, args, out, metrics)
    print("wrote " + ", ".join(str(p) for p in written))
    return 0


def _cloud_arms(traj: Any, robot: Any, metrics: dict, *, per_frame: bool) -> Any:
    """A point-cloud run's arm-direction errors against its rendered person (or None).

    Adds ``metrics["cloud_arm_directions"]``
    (:func:`qpretarget.cloud.measures.arm_direction_summary`, and the (T, 4) errors per frame
    unless ``per_frame`` is false) to a ``retarget-cloud`` run; says why when its clouds carry
    no rendered person (a real sensor's). Other runs: nothing.
    """
    if traj.meta.get("command") != "retarget-cloud":
        return None
    from ..cloud.measures import (
        ARM_SEGMENTS,
        HUMAN_Q_KEY,
        arm_direction_summary,
        run_arm_direction_errors,
    )
    from ..errors import ConfigError

    try:
        errors = run_arm_direction_errors(traj, robot)
    except ValueError as exc:
        raise ConfigError(f"{exc}.") from None
    if errors is None:
        metrics["cloud_arm_directions"] = {
            "unavailable": f"the clouds carry no rendered person ({HUMAN_Q_KEY}: make-cloud "
            "writes it); a sensor's clouds have no truth to score the arms against"
        }
        return None
    summary = arm_direction_summary(errors, traj.t)
    if per_frame:
        summary["per_frame_deg"] = {
            name: [float(x) for x in errors[:, k]] for k, name in enumerate(ARM_SEGMENTS)
        }
    metrics["cloud_arm_directions"] = summary
    return errors


def _physics(traj: object, args: argparse.Namespace, out: Path, metrics: dict) -> list[Path]:
    """Replay in MuJoCo; write physics.json (+ figure); add a summary to metrics.json."""
    import sys

    from ..fileio import write_atomic
    from ..physics.metrics import dumps, summary_row
    from ..physics.replay import check_run

    m, free, helped = check_run(
        traj,
        gains=args.physics_gains,
        timestep=args.physics_timestep,
        assisted=not args.no_assist,
        progress=sys.stderr.isatty(),
        feedforward=args.physics_feedforward,
    )
    if not args.no_per_frame:
        from ..physics.metrics import per_frame_series

        m["per_frame"] = per_frame_series(free, helped)
    text = dumps(m)
    written = [write_atomic(out / "physics.json", lambda f: f.write(text), binary=False)]
    metrics["physics"] = summary_row(m)
    mtext = dumps_metrics(metrics)
    write_atomic(out / "metrics.json", lambda f: f.write(mtext), binary=False)
    if not args.no_figures:
        from ..physics.plots import write_figure

        written.append(write_figure(free, helped, out / "physics.png", title=str(args.run)))
    _print_physics(m)
    return written


def dumps_metrics(metrics: dict) -> str:
    """metrics.json text (the analysis module's strict JSON)."""
    from ..analysis.metrics import dumps

    return dumps(metrics)


def _print_physics(m: dict) -> None:
    """Print the headline numbers of physics.json."""
    u = m["unassisted"]
    sat = u["saturation"]
    feet = u["feet"]
    share = feet["weight_share_mean"]
    lines = [
        f"physics          {m['verdict']}: survived {u['survived_fraction'] * 100:.1f} % "
        + ("" if u["fallen_at_s"] is None else f"(fell at {u['fallen_at_s']:.2f} s) ")
        + f"with {m['model']['gains']} gains, {u['real_time_factor']:.1f}x real time",
        f"  root error     p95 {u['root_position_error_mm']['p95']:.1f} mm, "
        f"{u['root_orientation_error_deg']['p95']:.2f} deg; joint RMS "
        f"{u['joint_tracking_rms_deg']['overall']:.2f} deg",
        f"  saturation     {sat['frames']} frames ({sat['fraction'] * 100:.1f} %)",
        "  feet share     " + ("-" if share is None else f"{share * 100:.1f} % of body weight"),
    ]
    z = m.get("reference_zmp")
    if z is not None:
        first = "" if z["first_outside_s"] is None else f", first at {z['first_outside_s']:.2f} s"
        lines.append(
            f"  reference ZMP  outside the stance soles in {z['frames_outside']} of "
            f"{z['stance_frames']} stance frames{first}"
        )
    if "assisted" in m:
        a = m["assisted"]["assist"]
        lines.append(
            f"  assist         force p95 {a['force_bw_pct']['p95']:.1f} % BW, torque p95 "
            f"{a['torque_Nm']['p95']:.1f} N m"
        )
    print("\n".join(lines))


def _print_summary(m: dict) -> None:
    """Print the headline numbers of ``metrics.json``."""

    def fmt(x: float | None, scale: float = 1.0, unit: str = "", spec: str = ".2f") -> str:
        return "-" if x is None else f"{x * scale:{spec}} {unit}".strip()

    def mm(x: float | None) -> str:
        return fmt(x, 1e3, "mm", ".1f")

    def ms(x: float | None) -> str:
        return fmt(x, unit="ms", spec=".3f")

    run, jl, sc = m["run"], m["joint_limits"], m["self_collision"]
    sup, pw, st, mo = m["support"], m["power"], m["solve_time"], m["joint_motion"]
    tracking = ", ".join(f"{k} {mm(v['rmse_m'])}" for k, v in m["tracking"].items())
    slip = ", ".join(f"{f} {mm(v['max_slip_m'])}" for f, v in m["foot_slip"].items())
    velocity = fmt(mo["velocity_peak_rad_s"]["value"], unit="rad/s")
    jerk = fmt(mo["jerk_peak_rad_s3"]["value"], unit="rad/s^3", spec=".3g")
    lines = [
        f"run              {run['robot']}, {run['samples']} samples, "
        f"{fmt(run['duration_s'], unit='s')}",
        f"tracking RMSE    mean {mm(m['tracking_rmse_mean_m'])}  {tracking}",
        f"joint limits     {jl['total_violations']} violations in "
        f"{jl['frames_with_violation']} frames (max {fmt(jl['max_violation_rad'], unit='rad')})",
        f"self-collision   {sc['total_violations']} violations in "
        f"{sc['frames_with_violation']} frames, min distance {mm(sc['min_distance_m'])} over "
        f"{len(sc['pairs'])} pairs",
        f"CoM margin       min {mm(sup['min_com_margin_m'])}"
        + (" (no contact data: every foot assumed in support)" if sup["contacts_assumed"] else ""),
        f"foot slip        {slip}",
        f"peaks            velocity {velocity}, jerk {jerk}",
        f"power            {fmt(pw['mean_abs_power_W'], unit='W')} average absolute "
        f"(CRAC eq. 43, torques: {pw['source']})",
        f"solve time       median {ms(st['median_ms'])}, p95 {ms(st['p95_ms'])}, "
        f"max {ms(st['max_ms'])}",
    ]
    if "before" in m:
        b = m["before"]
        lines.append(
            f"before           {b['violations']['total_per_frame_mean']:.2f} violations per "
            f"frame ({b['joint_limits']['total_violations']} joint-limit, "
            f"{b['self_collision']['total_violations']} self-collision)"
        )
    human = m.get("human") or {}
    if "unavailable" in human:
        lines.append(f"vs the person    not measured: {human['unavailable']}")
    elif human:
        from ..analysis.human_metrics import format_human_metrics

        lines += format_human_metrics(human)
    arms = m.get("cloud_arm_directions")
    if arms and "unavailable" in arms:
        lines.append(f"arm directions   not measured: {arms['unavailable']}")
    elif arms:
        lines.append(
            f"arm directions   worst {arms['worst_deg']:.1f} deg "
            f"({arms['worst_segment'].replace('_', ' ')} at {arms['worst_time_s']:.2f} s), "
            f"median {arms['median_deg']:.1f} deg; {arms['frames_above_tolerance']} of "
            f"{arms['frames']} frames above {arms['tolerance_deg']:g} deg; longest above "
            f"{arms['lost_deg']:g} deg {arms['longest_lost_s']:.2f} s (vs the rendered person)"
        )
    print("\n".join(lines))
