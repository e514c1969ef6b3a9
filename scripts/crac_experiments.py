# SPDX-License-Identifier: Apache-2.0
"""Reproduce the experiments of CRAC section 5 on the Unitree G1 with real CMU clips.

CRAC (Bin Hammam et al. 2015) retargets four pre-recorded CMU motions (boxing, chicken dance,
exercise, reaching) with three task sets and reports:

* Fig. 3: average joint-limit + self-collision violations per frame *before filtering* (the motion
  retargeted with the kinematic constraints off), Task Sets 1 and 2;
* Fig. 4: the violations per frame of the reaching motion, Task Set 2, before filtering;
* Fig. 5: minimum distances of collision pairs after filtering (reaching, Task Set 1);
* Fig. 6: right-arm joint angles with their limits (reaching, Task Set 1);
* Fig. 7: right-wrist tracking, Task Sets 1 and 2;
* Fig. 8: Task Set 3, torso/right-wrist distance and lateral wrist tracking with and without
  collision avoidance;
* Fig. 9 / eq. 43: average absolute power with the inertia weighting W_D = H versus W_D = I, at
  (nearly) equal RMSD; "about 20 % less power" for Task Set 2.

Here: the G1 configs ``configs/crac_ts{1,2,3}_<level>_crac.yaml`` (hierarchy, feet first; CRAC
weighting W = W_K + W_D; paper gains), plus a ``self_collision`` constraint on the 16 upper-body
pairs of :data:`~qpretarget.analysis.metrics.DEFAULT_PAIRS` (CRAC: N_c = 16). "Before
filtering" is the same config with ``joint_limits`` and ``self_collision`` removed and
``W = I`` (no kinematic weighting).
Clips (../shared/data/mocap): reaching = ``cmu_14_07_reach_up_tiptoe``, boxing =
``cmu_17_10_boxing``, exercise = ``cmu_14_14_exercise_squats_twists``, chicken =
``cmu_29_22_chicken_flapping`` (the chicken dance itself is not available).

Every number is measured by :mod:`qpretarget.analysis.metrics` on the saved runs. The script writes
``results.json``, the figures, and ``docs/results.md`` (``--write-docs``)::

    python scripts/crac_experiments.py --write-docs            # full clips (up to --seconds 10)
    python scripts/crac_experiments.py --quick --out /tmp/crac # CI: 2 s of the reaching clip

``--quick`` checks the acceptance of issue 6: zero violations after filtering, more than zero
before (exit code 1 otherwise).
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[1]
MOCAP = REPO.parent / "shared" / "data" / "mocap"

CLIPS = {
    "reaching": "cmu_14_07_reach_up_tiptoe.bvh",
    "boxing": "cmu_17_10_boxing.bvh",
    "exercise": "cmu_14_14_exercise_squats_twists.bvh",
    "chicken": "cmu_29_22_chicken_flapping.bvh",
}
TASK_SETS = (1, 2, 3)
FEET = ("left_foot", "right_foot")
#: Self-collision constraint added to every "after" config (CRAC: 16 upper-body pairs).
D_S, D_I = 0.01, 0.05


# ---------------------------------------------------------------------------------- configs
def load_config(ts: int, level: str) -> dict[str, Any]:
    """The CRAC Task Set ``ts`` config (CRAC weighting, hierarchy with feet first)."""
    path = REPO / "configs" / f"crac_ts{ts}_{level}_crac.yaml"
    return yaml.safe_load(path.read_text(encoding="utf-8"))


def with_self_collision(cfg: dict[str, Any]) -> dict[str, Any]:
    """``cfg`` with a ``self_collision`` constraint on the 16 default pairs (if it has none)."""
    from qpretarget.analysis.metrics import DEFAULT_PAIRS

    out = copy.deepcopy(cfg)
    cons = out.setdefault("constraints", [])
    if not any(c.get("type") == "self_collision" for c in cons):
        pairs = [list(p) for p in DEFAULT_PAIRS["g1"]]
        cons.append({"type": "self_collision", "pairs": pairs, "d_s": D_S, "d_i": D_I})
    return out


def unconstrained(cfg: dict[str, Any]) -> dict[str, Any]:
    """ "Before filtering": no joint-limit or self-collision constraint, ``W = I``."""
    out = copy.deepcopy(cfg)
    out["constraints"] = [
        c
        for c in out.get("constraints", [])
        if c.get("type") not in ("joint_limits", "self_collision")
    ]
    damping = (out.get("regularization") or {}).get("damping", 0.1)
    out["regularization"] = {"type": "identity", "damping": damping}
    return out


def no_collision_avoidance(cfg: dict[str, Any]) -> dict[str, Any]:
    """Task Set 3 without collision avoidance (CRAC Fig. 8: joint limits not enforced either)."""
    out = unconstrained(cfg)
    out["regularization"] = copy.deepcopy(cfg.get("regularization"))
    if isinstance(out["regularization"], dict) and out["regularization"].get("type") == "crac":
        out["regularization"]["collisions"] = False
    return out


def inertia(cfg: dict[str, Any], on: bool) -> dict[str, Any]:
    """CRAC weighting with ``W_D = H`` (``on``) or ``W_D = I``."""
    out = copy.deepcopy(cfg)
    out["regularization"] = {**out["regularization"], "inertia": bool(on)}
    return out


def retarget_spec(cfg: dict[str, Any]) -> dict[str, Any]:
    """The config's ``retarget:`` section, else every non-foot task tracks its key-point."""
    from qpretarget.motion import KEYPOINT_NAMES

    if cfg.get("retarget"):
        return cfg["retarget"]
    tasks = {
        t["name"]: t["name"]
        for t in cfg["tasks"]
        if t["name"] in KEYPOINT_NAMES and t["name"] not in FEET
    }
    return {"tasks": tasks}


# ---------------------------------------------------------------------------------- runs
def run(cfg: dict[str, Any], clip: str, seconds: float | None, out: Path, tag: str) -> Any:
    """Retarget ``clip`` with ``cfg``, save the run, return its metric series and summary."""
    from qpretarget.analysis.metrics import compute_series, summarize
    from qpretarget.control.controller import Controller
    from qpretarget.motion import load_motion
    from qpretarget.retarget.retargeter import Retargeter

    human = load_motion(MOCAP / clip)
    ctrl = Controller(cfg, base_dir=REPO / "configs")
    t0 = time.perf_counter()
    traj = Retargeter(ctrl, retarget_spec(cfg)).retarget(human, end=seconds)
    wall = time.perf_counter() - t0
    traj.save(out / "runs" / f"{tag}.npz")
    # Measure every run on the same pairs (the 16 defaults), whatever its own constraints.
    from qpretarget.analysis.metrics import DEFAULT_PAIRS

    series = compute_series(traj, controller=ctrl, pairs=DEFAULT_PAIRS["g1"], safety_distance=D_S)
    summary = summarize(series, per_frame=False)
    summary["wall_time_s"] = wall
    summary["ticks_per_second"] = len(traj.t) / wall if wall > 0 else None
    print(
        f"  {tag:38s} {len(traj.t):5d} ticks {wall:6.1f} s  violations/frame "
        f"{summary['violations']['total_per_frame_mean']:.3f}  "
        f"P {summary['power']['mean_abs_power_W']:.2f} W",
        flush=True,
    )
    return series, summary


def wrist_rmsd(summary: dict[str, Any]) -> float | None:
    """RMSD of the tracked upper-body points (mean over the non-foot tasks) [m]."""
    vals = [
        v["rmse_m"]
        for k, v in summary["tracking"].items()
        if k not in FEET and v["rmse_m"] is not None
    ]
    return float(np.mean(vals)) if vals else None


# ---------------------------------------------------------------------------------- figures
def _figure(size: tuple[float, float]) -> Any:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=size, dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def fig_violation_bars(results: dict[str, Any], path: Path) -> None:
    """CRAC Fig. 3: mean violations per frame before filtering, per clip and task set."""
    fig = _figure((11, 4.5))
    axes = fig.subplots(1, 2, sharey=True)
    for ax, ts in zip(axes, (1, 2), strict=True):
        clips = [c for c in results["clips"] if f"ts{ts}" in results["kinematic"][c]]
        jl = [results["kinematic"][c][f"ts{ts}"]["before"]["joint_limits_per_frame"] for c in clips]
        sc = [
            results["kinematic"][c][f"ts{ts}"]["before"]["self_collisions_per_frame"] for c in clips
        ]
        after = [results["kinematic"][c][f"ts{ts}"]["after"]["violations_per_frame"] for c in clips]
        x = np.arange(len(clips))
        ax.bar(x, jl, color="tab:blue", label="joint limits (before)")
        ax.bar(x, sc, bottom=jl, color="tab:red", label="self-collisions (before)")
        for i, a in enumerate(after):
            ax.text(x[i], jl[i] + sc[i], f"after: {a:.2f}", ha="center", va="bottom", fontsize=9)
        ax.set_xticks(x, clips)
        ax.set_title(f"Task Set {ts}: violations per frame before filtering", fontsize=10)
        ax.grid(alpha=0.3, axis="y")
    axes[0].set_ylabel("average violations per frame")
    axes[0].legend(fontsize=8)
    fig.savefig(path, dpi=100)


def fig_wrist_tracking(series: dict[str, Any], path: Path) -> None:
    """CRAC Fig. 7: right wrist x, y, z, reference and robot, Task Sets 1 and 2."""
    fig = _figure((12, 7))
    keys = [k for k in ("ts1", "ts2") if k in series]
    axes = fig.subplots(3, len(keys), sharex=True, squeeze=False)
    for c, key in enumerate(keys):
        s = series[key]
        ref, act = s.targets["right_wrist"], s.reached["right_wrist"]
        for r, axis in enumerate("xyz"):
            ax = axes[r, c]
            ax.plot(s.t, ref[:, r], "k--", lw=1.2, label="reference")
            ax.plot(s.t, act[:, r], color="tab:blue", lw=1.3, label="robot")
            ax.set_ylabel(f"{axis} [m]")
            ax.grid(alpha=0.3)
        rms = 1e3 * np.sqrt(np.nanmean(np.sum((ref - act) ** 2, axis=1)))
        axes[0, c].set_title(f"Task Set {key[-1]}: right wrist (RMSE {rms:.1f} mm)", fontsize=10)
        axes[-1, c].set_xlabel("time [s]")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle("Right wrist tracking, reaching motion (CRAC Fig. 7)")
    fig.savefig(path, dpi=100)


def fig_ts3(with_ca: Any, without_ca: Any, path: Path, clip: str) -> None:
    """CRAC Fig. 8: torso/right-wrist distance and lateral tracking, with and without avoidance."""
    fig = _figure((12, 6))
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    pair = "right_wrist_yaw_link/torso_link"
    for s, label, style in (
        (without_ca, "without collision avoidance", "--"),
        (with_ca, "with collision avoidance", "-"),
    ):
        p = s.pair_names.index(pair)
        ax1.plot(s.t, 100 * s.pair_distance[:, p], style, lw=1.3, label=label)
        ax2.plot(s.t, s.reached["right_wrist"][:, 1], style, lw=1.3, label=f"robot, {label}")
    ax2.plot(with_ca.t, with_ca.targets["right_wrist"][:, 1], "k:", lw=1.2, label="reference")
    low = min(ax1.get_ylim()[0], -2.0)
    ax1.axhspan(low, 0, color="tab:red", alpha=0.15, label="collision (d < 0)")
    ax1.axhline(100 * D_S, color="tab:orange", lw=1.0, label=f"safety distance {100 * D_S:.0f} cm")
    ax1.set_ylim(low, None)
    ax1.set_ylabel("torso / right wrist [cm]")
    ax2.set_ylabel("right wrist y [m]")
    ax2.set_xlabel("time [s]")
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper right")
    fig.suptitle(f"Task Set 3, {clip}: collision avoidance against lateral tracking (CRAC Fig. 8)")
    fig.savefig(path, dpi=100)


def fig_power(results: dict[str, Any], path: Path) -> None:
    """CRAC Fig. 9: average absolute power, W_D = H versus W_D = I, per clip and task set."""
    fig = _figure((11, 4.5))
    axes = fig.subplots(1, 2, sharey=True)
    for ax, ts in zip(axes, (1, 2), strict=True):
        clips = [c for c in results["clips"] if f"ts{ts}" in results["dynamic"][c]]
        h = [results["dynamic"][c][f"ts{ts}"]["H"]["power_W"] for c in clips]
        i = [results["dynamic"][c][f"ts{ts}"]["I"]["power_W"] for c in clips]
        x = np.arange(len(clips))
        ax.bar(x - 0.2, i, 0.4, color="0.6", label="W_D = I (kinematic)")
        ax.bar(x + 0.2, h, 0.4, color="tab:blue", label="W_D = H (kinodynamic)")
        for k in range(len(clips)):
            if i[k]:
                ax.text(
                    x[k] + 0.2,
                    h[k],
                    f"{100 * (h[k] - i[k]) / i[k]:+.0f}%",
                    ha="center",
                    va="bottom",
                    fontsize=9,
                )
        ax.set_xticks(x, clips)
        ax.set_title(f"Task Set {ts}", fontsize=10)
        ax.grid(alpha=0.3, axis="y")
    axes[0].set_ylabel("average absolute power P [W] (CRAC eq. 43)")
    axes[0].legend(fontsize=8)
    fig.savefig(path, dpi=100)


# ---------------------------------------------------------------------------------- experiments
def kinematic_row(before: dict[str, Any], after: dict[str, Any]) -> dict[str, Any]:
    def row(m: dict[str, Any]) -> dict[str, Any]:
        n = max(m["run"]["samples"], 1)
        return {
            "violations_per_frame": m["violations"]["total_per_frame_mean"],
            "joint_limits_per_frame": m["joint_limits"]["total_violations"] / n,
            "self_collisions_per_frame": m["self_collision"]["total_violations"] / n,
            "max_per_frame": m["violations"]["total_per_frame_max"],
            "min_distance_m": m["self_collision"]["min_distance_m"],
            "rmsd_m": wrist_rmsd(m),
            "status": m["status"],
        }

    return {"before": row(before), "after": row(after)}


def experiments(args: argparse.Namespace) -> dict[str, Any]:
    from qpretarget.analysis.plots import plot_joint_angles, plot_pair_distances, plot_violations

    out: Path = args.out
    figs: Path = args.figures or out / "figures"
    figs.mkdir(parents=True, exist_ok=True)
    clips = ["reaching"] if args.quick else list(args.clips)
    task_sets = (2,) if args.quick else (1, 2)
    seconds = args.seconds
    results: dict[str, Any] = {
        "level": args.level,
        "seconds": seconds,
        "clips": clips,
        "clip_files": {c: CLIPS[c] for c in clips},
        "pairs": "qpretarget.analysis.metrics.DEFAULT_PAIRS['g1'] (16)",
        "d_s_m": D_S,
        "d_i_m": D_I,
        "kinematic": {},
        "dynamic": {},
        "figures": {},
    }
    keep: dict[str, Any] = {}
    for clip in clips:
        print(f"{clip} ({CLIPS[clip]})", flush=True)
        results["kinematic"][clip] = {}
        results["dynamic"][clip] = {}
        for ts in task_sets:
            base = with_self_collision(load_config(ts, args.level))
            sb, mb = run(unconstrained(base), CLIPS[clip], seconds, out, f"{clip}_ts{ts}_before")
            sa, ma = run(base, CLIPS[clip], seconds, out, f"{clip}_ts{ts}_after")
            results["kinematic"][clip][f"ts{ts}"] = kinematic_row(mb, ma)
            keep[(clip, ts, "before")], keep[(clip, ts, "after")] = sb, sa
            if args.quick:
                continue
            si, mi = run(inertia(base, False), CLIPS[clip], seconds, out, f"{clip}_ts{ts}_identity")
            results["dynamic"][clip][f"ts{ts}"] = {
                "H": {"power_W": ma["power"]["mean_abs_power_W"], "rmsd_m": wrist_rmsd(ma)},
                "I": {"power_W": mi["power"]["mean_abs_power_W"], "rmsd_m": wrist_rmsd(mi)},
            }
    if "reaching" in clips:
        ts_h = 2 if 2 in task_sets else task_sets[0]
        b, a = keep[("reaching", ts_h, "before")], keep[("reaching", ts_h, "after")]
        results["figures"]["histogram"] = _name(
            plot_violations(a, figs / "violations_reaching.png", before=b)
        )
        ts_f = 1 if 1 in task_sets else task_sets[0]
        a1 = keep[("reaching", ts_f, "after")]
        b1 = keep[("reaching", ts_f, "before")]
        results["figures"]["distances"] = _name(
            plot_pair_distances(a1, figs / "pair_distances_reaching.png", before=b1)
        )
        results["figures"]["joint_angles"] = _name(
            plot_joint_angles(a1, figs / "joint_angles_reaching.png")
        )
        if not args.quick:
            fig_wrist_tracking(
                {f"ts{t}": keep[("reaching", t, "after")] for t in task_sets},
                figs / "wrist_tracking.png",
            )
            results["figures"]["wrist_tracking"] = _name(figs / "wrist_tracking.png")
            # Task Set 3 on the clip whose raw retargeting collides most (Task Set 2, before).
            ts3_clip = max(
                clips,
                key=lambda c: (
                    results["kinematic"][c]["ts2"]["before"]["self_collisions_per_frame"]
                    if "ts2" in results["kinematic"][c]
                    else 0.0
                ),
            )
            base3 = with_self_collision(load_config(3, args.level))
            s3, m3 = run(base3, CLIPS[ts3_clip], seconds, out, f"{ts3_clip}_ts3_after")
            s3n, m3n = run(
                no_collision_avoidance(base3),
                CLIPS[ts3_clip],
                seconds,
                out,
                f"{ts3_clip}_ts3_no_avoidance",
            )
            results["ts3"] = {"clip": ts3_clip}
            for key, ser, summ in (("with", s3, m3), ("without", s3n, m3n)):
                p = ser.pair_names.index("right_wrist_yaw_link/torso_link")
                err = ser.targets["right_wrist"][:, 1] - ser.reached["right_wrist"][:, 1]
                results["ts3"][key] = {
                    "min_distance_torso_right_wrist_m": float(np.nanmin(ser.pair_distance[:, p])),
                    "self_collisions_per_frame": summ["self_collision"]["total_violations"]
                    / max(summ["run"]["samples"], 1),
                    "lateral_rmse_m": float(np.sqrt(np.nanmean(err**2))),
                }
            fig_ts3(s3, s3n, figs / "ts3_collision_tracking.png", ts3_clip)
            results["figures"]["ts3"] = _name(figs / "ts3_collision_tracking.png")
    if not args.quick:
        # Repeatability: the same run again (same process, same inputs).
        rc = "boxing" if "boxing" in clips else clips[0]
        first = keep[(rc, 2, "after")]
        again, m_again = run(
            with_self_collision(load_config(2, args.level)),
            CLIPS[rc],
            seconds,
            out,
            f"{rc}_ts2_again",
        )
        first_row = results["dynamic"][rc]["ts2"]["H"]
        results["repeatability"] = {
            "clip": rc,
            "max_joint_difference_rad": float(np.max(np.abs(first.q_joints - again.q_joints))),
            "power_W": [first_row["power_W"], m_again["power"]["mean_abs_power_W"]],
            "rmsd_m": [first_row["rmsd_m"], wrist_rmsd(m_again)],
        }
        fig_violation_bars(results, figs / "violations_before.png")
        fig_power(results, figs / "power.png")
        results["figures"]["violation_bars"] = _name(figs / "violations_before.png")
        results["figures"]["power"] = _name(figs / "power.png")
    return results


# ---------------------------------------------------------------------------------- report
def results_markdown(results: dict[str, Any], fig_rel: str) -> str:
    """docs/results.md from the results (every number comes from ``results``)."""
    lines = [
        "# CRAC experiments on the Unitree G1",
        "",
        "<!-- Generated by `python scripts/crac_experiments.py --write-docs`; do not edit. -->",
        "",
        f"Level: {results['level']}; clips (`../shared/data/mocap`), first {results['seconds']} s: "
        + ", ".join(f"{c} = `{f}`" for c, f in results["clip_files"].items())
        + f". Self-collision pairs: {results['pairs']}, d_s = {results['d_s_m']} m, "
        f"d_i = {results['d_i_m']} m. Before filtering: joint-limit and self-collision "
        "constraints off, W = I. After: the CRAC config (hierarchy with feet first, "
        "W = W_K + W_D, W_D = H) with the constraints on.",
        "",
        "## Kinematic constraints (CRAC Fig. 3-8)",
        "",
        _row(
            "clip",
            "task set",
            "before: violations / frame (joint limits + collisions)",
            "max in a frame",
            "after: violations / frame",
            "min pair distance after [mm]",
            "RMSD before [mm]",
            "RMSD after [mm]",
        ),
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for clip, sets in results["kinematic"].items():
        for ts, r in sets.items():
            b, a = r["before"], r["after"]
            before = (
                f"{b['violations_per_frame']:.2f} ({b['joint_limits_per_frame']:.2f} + "
                f"{b['self_collisions_per_frame']:.2f})"
            )
            lines.append(
                _row(
                    clip,
                    ts[-1],
                    before,
                    b["max_per_frame"],
                    f"{a['violations_per_frame']:.3f}",
                    _mm(a["min_distance_m"]),
                    _mm(b["rmsd_m"]),
                    _mm(a["rmsd_m"]),
                )
            )
    lines += ["", *kinematic_summary(results)]
    figs = results["figures"]
    for key, caption in (
        ("violation_bars", "Average violations per frame before filtering (CRAC Fig. 3)"),
        ("histogram", "Violations per frame, reaching, before and after (CRAC Fig. 4)"),
        ("distances", "Pair distances after filtering, reaching (CRAC Fig. 5)"),
        ("joint_angles", "Right-arm joint angles and limits, reaching (CRAC Fig. 6)"),
        ("wrist_tracking", "Right wrist tracking, Task Sets 1 and 2 (CRAC Fig. 7)"),
        ("ts3", "Task Set 3, with and without collision avoidance (CRAC Fig. 8)"),
    ):
        if key in figs:
            lines += ["", f"![{caption}]({fig_rel}/{Path(figs[key]).name})", "", f"*{caption}.*"]
    if any(results["dynamic"].values()):
        lines += [
            "",
            "## Dynamic consistency (CRAC Fig. 9, eq. 43)",
            "",
            _row(
                "clip",
                "task set",
                "P, W_D = I [W]",
                "P, W_D = H [W]",
                "change",
                "RMSD, W_D = I [mm]",
                "RMSD, W_D = H [mm]",
            ),
            "|---|---|---:|---:|---:|---:|---:|",
        ]
        for clip, sets in results["dynamic"].items():
            for ts, r in sets.items():
                pi, ph = r["I"]["power_W"], r["H"]["power_W"]
                change = f"{100 * (ph - pi) / pi:+.1f} %" if pi else "-"
                lines.append(
                    _row(
                        clip,
                        ts[-1],
                        f"{pi:.2f}",
                        f"{ph:.2f}",
                        change,
                        _mm(r["I"]["rmsd_m"]),
                        _mm(r["H"]["rmsd_m"]),
                    )
                )
        lines += ["", *dynamic_summary(results)]
        if "power" in figs:
            lines += ["", f"![Average absolute power]({fig_rel}/{Path(figs['power']).name})"]
    lines += [
        "",
        "P = mean |tau' qdot| over the actuated joints (CRAC eq. 43), with the torques of the "
        "acceleration-level controller (CRAC eq. 30) once the supporting feet carry the floating "
        "base's wrench (minimum-norm contact wrenches); RMSD: mean over the tracked upper-body "
        "points of their RMSE. Definitions: docs/metrics.md.",
        "",
    ]
    return "\n".join(lines)


def _pct(a: float, b: float) -> float:
    return 100.0 * (b - a) / a if a else float("nan")


def kinematic_summary(results: dict[str, Any]) -> list[str]:
    """Sentences on the kinematic table, every number taken from ``results``."""
    rows = [r for sets in results["kinematic"].values() for r in sets.values()]
    if not rows:
        return []
    clean = sum(1 for r in rows if r["after"]["violations_per_frame"] == 0)
    before = [r["before"]["violations_per_frame"] for r in rows]
    worst = max(r["before"]["max_per_frame"] for r in rows)
    mins = [r["after"]["min_distance_m"] for r in rows if r["after"]["min_distance_m"] is not None]
    out = [
        f"After filtering, {clean} of {len(rows)} runs have no joint-limit or self-collision "
        f"violation in any frame; the closest pair stays {1e3 * min(mins):.1f} mm apart "
        f"(d_s = {1e3 * results['d_s_m']:.0f} mm). Before filtering the same clips give "
        f"{min(before):.2f} to {max(before):.2f} violations per frame on average and at most "
        f"{worst} in one frame, fewer than on CRAC's 29-DoF model (its Fig. 3: more than 9 per "
        "frame for the exercise motion in Task Set 2).",
    ]
    ts3 = results.get("ts3")
    if ts3:
        w, wo = ts3["with"], ts3["without"]
        out += [
            "",
            f"Task Set 3 ({ts3['clip']}, the clip that collides most before filtering): the "
            f"torso/right-wrist distance reaches {1e3 * wo['min_distance_torso_right_wrist_m']:.1f}"
            f" mm without collision avoidance and {1e3 * w['min_distance_torso_right_wrist_m']:.1f}"
            f" mm with it (self-collisions per frame over the 16 pairs: "
            f"{wo['self_collisions_per_frame']:.3f} and {w['self_collisions_per_frame']:.3f}); the "
            "lateral wrist RMSE is "
            f"{1e3 * wo['lateral_rmse_m']:.1f} mm without and {1e3 * w['lateral_rmse_m']:.1f} mm "
            "with avoidance.",
        ]
    return out


def dynamic_summary(results: dict[str, Any]) -> list[str]:
    """Sentences on the power table, every number taken from ``results``."""
    out = []
    for ts, paper in (
        ("ts1", "CRAC finds no significant change for this over-constrained set"),
        ("ts2", "CRAC reports about 20 % less power for this set"),
    ):
        rows = [sets[ts] for sets in results["dynamic"].values() if ts in sets]
        if not rows:
            continue
        ch = [_pct(r["I"]["power_W"], r["H"]["power_W"]) for r in rows]
        dr = [1e3 * (r["H"]["rmsd_m"] - r["I"]["rmsd_m"]) for r in rows]
        lower = sum(1 for c in ch if c < 0)
        out.append(
            f"Task Set {ts[-1]}: W_D = H changes P by {np.mean(ch):+.1f} % on average "
            f"({min(ch):+.1f} % to {max(ch):+.1f} %; lower in {lower} of {len(ch)} clips) and the "
            f"RMSD by {np.mean(dr):+.1f} mm on average ({paper})."
        )
    rep = results.get("repeatability")
    if rep:
        out.append(
            f"Repeatability: the Task Set 2 run of {rep['clip']} done twice in one process gives "
            f"joint angles up to {rep['max_joint_difference_rad']:.3g} rad apart, "
            f"P = {rep['power_W'][0]:.2f} and {rep['power_W'][1]:.2f} W, RMSD = "
            f"{1e3 * rep['rmsd_m'][0]:.1f} and {1e3 * rep['rmsd_m'][1]:.1f} mm: the closed loop "
            "amplifies differences of floating-point rounding between runs, so differences of "
            "that size in the tables are noise."
        )
    return [" ".join(out)] if out else []


def _name(path: Any) -> str:
    """File name of a figure (results.json holds no machine paths)."""
    return Path(path).name


def _row(*cells: Any) -> str:
    return "| " + " | ".join(str(c) for c in cells) + " |"


def _mm(x: float | None) -> str:
    return "-" if x is None else f"{1e3 * x:.1f}"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--out", type=Path, default=Path("crac_results"), help="output directory")
    p.add_argument("--level", choices=("acceleration", "velocity"), default="acceleration")
    p.add_argument("--seconds", type=float, default=10.0, help="excerpt length of each clip [s]")
    p.add_argument("--clips", nargs="+", choices=sorted(CLIPS), default=list(CLIPS))
    p.add_argument(
        "--quick",
        action="store_true",
        help="CI: 2 s of the reaching clip, Task Set 2, acceptance checks",
    )
    p.add_argument(
        "--from-json",
        type=Path,
        help="only rewrite docs/results.md from a results.json of an earlier run",
    )
    p.add_argument(
        "--write-docs", action="store_true", help="write docs/results.md and docs/figures/results/"
    )
    args = p.parse_args(argv)
    if args.from_json:
        results = json.loads(args.from_json.read_text(encoding="utf-8"))
        md = results_markdown(results, "figures/results")
        (REPO / "docs" / "results.md").write_text(md, encoding="utf-8")
        return 0
    if args.quick and args.seconds == 10.0:
        args.seconds = 2.0
    args.figures = None
    if args.write_docs:
        # Figures and results.json into the docs; the runs stay in --out (not in the repository).
        args.figures = REPO / "docs" / "figures" / "results"
    args.out.mkdir(parents=True, exist_ok=True)
    results = experiments(args)
    (args.out / "results.json").write_text(json.dumps(results, indent=1), encoding="utf-8")
    if args.write_docs:
        (args.figures / "results.json").write_text(json.dumps(results, indent=1), encoding="utf-8")
        md = results_markdown(results, "figures/results")
        (REPO / "docs" / "results.md").write_text(md, encoding="utf-8")
    if args.quick:
        ok = True
        for clip, sets in results["kinematic"].items():
            for ts, r in sets.items():
                after = r["after"]["violations_per_frame"]
                before = r["before"]["violations_per_frame"]
                print(f"{clip} {ts}: violations per frame before {before:.3f}, after {after:.3f}")
                ok &= after == 0 and before > 0
        if not ok:
            print(
                "FAILED: expected zero violations after filtering and some before.", file=sys.stderr
            )
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
