# SPDX-License-Identifier: Apache-2.0
"""Figures of a run's metrics (``qpretarget evaluate``), drawn with matplotlib's Agg canvas.

matplotlib is an optional dependency (the ``plot`` extra), imported when a figure is
drawn. Figures are built on a :class:`matplotlib.figure.Figure` with the Agg canvas, never through
``pyplot``, so nothing here changes the user's matplotlib backend.

===================  =====================================================================
file                 content (paper figure it mirrors)
===================  =====================================================================
tracking.png         reference vs robot position of the tracked points (CRAC Fig. 7)
pair_distances.png   minimum distance of the collision pairs, safety zone (Dariush 2009
                     Fig. 11-12, CRAC Fig. 5)
joint_angles.png     joint angles of one arm with their limits (CRAC Fig. 6)
violations.png       joint-limit and self-collision violations per frame, before/after
                     (CRAC Fig. 3-4, 11)
com_support.png      ground projection of the CoM inside the support polygon, and its margin
power.png            instantaneous |tau' qdot| and the average absolute power (CRAC eq. 43, Fig. 9)
===================  =====================================================================
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import MissingDependencyError, install_hint
from ..fileio import atomic_path
from .metrics import MetricSeries

#: Resolution of every figure [dots per inch].
DPI = 100
#: Size of each figure [inch]; the PNG is ``size * DPI`` pixels.
FIGSIZE: dict[str, tuple[float, float]] = {
    "tracking": (12.0, 9.0),
    "pair_distances": (11.0, 6.0),
    "joint_angles": (11.0, 9.0),
    "violations": (12.0, 7.0),
    "com_support": (12.0, 5.5),
    "power": (12.0, 4.5),
}


class PlotDependencyError(MissingDependencyError):
    """matplotlib is not installed."""


def _figure(name: str) -> Any:
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        raise PlotDependencyError(
            install_hint("plot", "drawing figures (matplotlib)"), extra="plot"
        ) from None
    fig = Figure(figsize=FIGSIZE[name], dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Any, path: Path) -> Path:
    with atomic_path(path, suffix=path.suffix) as tmp:  # no half-written figure
        fig.savefig(tmp, dpi=DPI)
    return path


def _pretty(name: str) -> str:
    return name.replace("_link", "").replace("_joint", "").replace("_", " ")


# ---------------------------------------------------------------------------------- figures
def plot_tracking(
    series: MetricSeries, path: str | Path, *, tasks: Sequence[str] | None = None
) -> Path:
    """Reference and reached x, y, z of up to four position tasks over time (CRAC Fig. 7)."""
    fig = _figure("tracking")
    names = list(tasks) if tasks else _tracking_order(list(series.reached))
    names = names[:4]
    if not names:
        ax = fig.add_subplot(1, 1, 1)
        ax.text(
            0.5, 0.5, "no position task with a stored target in this run", ha="center", va="center"
        )
        ax.set_axis_off()
        return _save(fig, Path(path))
    axes = fig.subplots(len(names), 3, sharex=True, squeeze=False)
    t = series.t
    for i, name in enumerate(names):
        ref, act = series.targets[name], series.reached[name]
        err = np.sqrt(np.nanmean(np.sum((ref - act) ** 2, axis=1)))
        for j, axis in enumerate("xyz"):
            ax = axes[i, j]
            ax.plot(t, ref[:, j], "k--", lw=1.2, label="reference")
            ax.plot(t, act[:, j], color="tab:blue", lw=1.4, label="robot")
            ax.set_title(
                f"{_pretty(name)}  {axis}" + (f"   (RMSE {1e3 * err:.1f} mm)" if j == 0 else ""),
                fontsize=10,
            )
            if j == 0:
                ax.set_ylabel("position [m]")
            ax.grid(alpha=0.3)
        axes[i, 0].legend(loc="best", fontsize=8)
    for j in range(3):
        axes[-1, j].set_xlabel("time [s]")
    fig.suptitle("Task tracking: reference (scaled human) vs robot, world frame")
    return _save(fig, Path(path))


def _tracking_order(names: list[str]) -> list[str]:
    """Hands/wrists first (the paper's figures), then elbows, then the rest."""

    def rank(n: str) -> int:
        n = n.lower()
        return 0 if ("hand" in n or "wrist" in n) else 1 if "elbow" in n else 2

    return sorted(names, key=rank)


def plot_pair_distances(
    series: MetricSeries,
    path: str | Path,
    *,
    max_pairs: int = 8,
    before: MetricSeries | None = None,
) -> Path:
    """Closest collision pairs' distances over time with the safety zone (Dariush 2009 Fig. 11-12).

    The ``max_pairs`` pairs that come closest are drawn in colour, the others in grey. With
    ``before``, the closest pair of the unconstrained run is drawn dashed for comparison
    (CRAC Fig. 8).
    """
    fig = _figure("pair_distances")
    ax = fig.add_subplot(1, 1, 1)
    t, D = series.t, series.pair_distance
    if D.size == 0:
        ax.text(0.5, 0.5, "no collision pair measured", ha="center", va="center")
        ax.set_axis_off()
        return _save(fig, Path(path))
    mins = np.nanmin(D, axis=0)
    order = np.argsort(mins)
    shown = order[:max_pairs]
    for p in order[max_pairs:]:
        ax.plot(t, 100 * D[:, p], color="0.75", lw=0.8)
    cmap = _cmap(len(shown))
    for c, p in enumerate(shown):
        ax.plot(
            t,
            100 * D[:, p],
            color=cmap[c],
            lw=1.5,
            label=f"{_pretty(series.pair_names[p])} (min {100 * mins[p]:.1f} cm)",
        )
    if before is not None and before.pair_distance.size:
        bm = np.nanmin(before.pair_distance, axis=0)
        bp = int(np.argmin(bm))
        label = f"{_pretty(before.pair_names[bp])}, constraints off (min {100 * bm[bp]:.1f} cm)"
        ax.plot(before.t, 100 * before.pair_distance[:, bp], "k--", lw=1.2, label=label)
    ds = 100 * series.safety_distance
    lo = min(float(np.nanmin(D)) * 100, -0.5 * max(ds, 1.0))
    if before is not None and before.pair_distance.size:
        lo = min(lo, float(np.nanmin(before.pair_distance)) * 100)
    ax.axhspan(lo - 1.0, 0.0, color="tab:red", alpha=0.15, label="collision (d < 0)")
    ax.axhspan(0.0, ds, color="tab:orange", alpha=0.2, label=f"safety zone (d < {ds:.1f} cm)")
    ax.set_ylim(lo - 1.0, None)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("pair distance [cm]")
    ax.set_title(
        f"Self-collision pair distances ({len(series.pair_names)} pairs, convex hulls; "
        f"closest {len(shown)} in colour)"
    )
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    return _save(fig, Path(path))


def _cmap(n: int) -> list[Any]:
    from matplotlib import colormaps

    cm = colormaps["tab10"]
    return [cm(i % 10) for i in range(n)]


def default_arm_joints(joint_names: Sequence[str]) -> list[str]:
    """The right arm's joints (CRAC Fig. 6), else the first seven joints."""
    arm = [
        n
        for n in joint_names
        if re.search(
            r"right.*(shoulder|elbow|wrist)|(shoulder|elbow|wrist).*right|^r_?(shoulder|elbow|wrist)|arm_right",
            n,
        )
    ]
    return arm or list(joint_names[:7])


def plot_joint_angles(
    series: MetricSeries, path: str | Path, *, joints: Sequence[str] | None = None
) -> Path:
    """Joint angles with their limits (dashed), one panel per joint (CRAC Fig. 6)."""
    fig = _figure("joint_angles")
    names = list(joints) if joints else default_arm_joints(series.joint_names)
    names = [n for n in names if n in series.joint_names][:8]
    ncol = 2
    nrow = max(1, (len(names) + ncol - 1) // ncol)
    axes = fig.subplots(nrow, ncol, sharex=True, squeeze=False)
    for i, name in enumerate(names):
        ax = axes[i % nrow, i // nrow]
        j = series.joint_names.index(name)
        q = series.q_joints[:, j]
        ax.plot(series.t, q, color="tab:blue", lw=1.4, label="joint angle")
        lo, hi = series.q_min[j], series.q_max[j]
        for lim, lab in ((lo, "limits"), (hi, None)):
            if np.isfinite(lim):
                ax.axhline(lim, color="tab:red", ls="--", lw=1.2, label=lab)
        viol = series.joint_violation[:, j]
        if viol.any():
            ax.plot(series.t[viol], q[viol], "rx", ms=4, label="violation")
        margin = min(q.min() - lo, hi - q.max())
        ax.set_title(f"{_pretty(name)}   (closest to a limit: {margin:+.3f} rad)", fontsize=10)
        ax.set_ylabel("[rad]")
        ax.grid(alpha=0.3)
        if i == 0:
            ax.legend(loc="best", fontsize=8)
    for i in range(len(names), nrow * ncol):
        axes[i % nrow, i // nrow].set_axis_off()
    for c in range(ncol):
        used = [r for r in range(nrow) if c * nrow + r < len(names)]
        if used:  # the lowest panel of each column carries the time axis
            axes[used[-1], c].tick_params(labelbottom=True)
            axes[used[-1], c].set_xlabel("time [s]")
    fig.suptitle("Joint angles and their limits")
    return _save(fig, Path(path))


def plot_violations(
    series: MetricSeries, path: str | Path, *, before: MetricSeries | None = None
) -> Path:
    """Joint-limit and self-collision violations per frame (CRAC Fig. 3-4, 11).

    Top: stacked counts per frame; bottom: how many frames have 0, 1, 2... violations. With
    ``before`` (the same motion with the constraints off) the two runs are side by side.
    """
    fig = _figure("violations")
    runs = (
        [("constraints off (before)", before), ("constraints on (after)", series)]
        if before is not None
        else [("this run", series)]
    )
    axes = fig.subplots(2, len(runs), squeeze=False)
    ymax = 1
    for _, s in runs:
        ymax = max(
            ymax,
            int((s.joint_violations_per_frame + s.collision_violations_per_frame).max(initial=0)),
        )
    for c, (label, s) in enumerate(runs):
        jl = s.joint_violations_per_frame
        sc = s.collision_violations_per_frame
        frames = np.arange(len(s.t))
        ax = axes[0, c]
        # Stacked step areas (one polygon each; a bar per frame is slow on long runs).
        ax.fill_between(frames, 0, jl, step="mid", color="tab:blue", lw=0, label="joint limits")
        ax.fill_between(
            frames, jl, jl + sc, step="mid", color="tab:red", lw=0, label="self-collisions"
        )
        ax.set_ylim(0, ymax + 0.5)
        ax.set_xlim(-0.5, len(frames) - 0.5)
        ax.set_xlabel("frame")
        ax.set_ylabel("violations in the frame")
        tot = jl + sc
        ax.set_title(
            f"{label}: {tot.mean():.2f} violations per frame on average, "
            f"{int(np.sum(tot > 0))} of {len(tot)} frames",
            fontsize=10,
        )
        ax.grid(alpha=0.3, axis="y")
        ax.legend(loc="upper left", fontsize=8)
        ax2 = axes[1, c]
        counts = np.bincount(tot.astype(int), minlength=ymax + 1)
        ax2.bar(np.arange(len(counts)), counts, color="0.4")
        ax2.set_xlabel("violations in a frame")
        ax2.set_ylabel("number of frames")
        ax2.set_xticks(np.arange(len(counts)))
        ax2.grid(alpha=0.3, axis="y")
    fig.suptitle(
        "Constraint violations per frame (joint limits: q outside [q_min, q_max] by more than "
        f"{series.joint_limit_tolerance:g} rad; self-collision: pair distance < 0)"
    )
    return _save(fig, Path(path))


def plot_com_support(series: MetricSeries, path: str | Path) -> Path:
    """Ground projection of the CoM inside the support polygon (left) and its margin (right)."""
    fig = _figure("com_support")
    ax, ax2 = fig.subplots(1, 2, width_ratios=[1, 1.4])
    drawn = 0
    last = None
    for k, poly in enumerate(series.support_polygons):
        if poly is None or len(poly) < 2:
            continue
        key = (poly.shape, np.round(poly, 3).tobytes())
        if key == last or (drawn >= 15 and k != len(series.support_polygons) - 1):
            continue
        closed = np.vstack([poly, poly[:1]])
        first = drawn == 0
        style = (
            {"lw": 1.2, "alpha": 1.0, "label": "support polygon"}
            if first
            else {"lw": 0.6, "alpha": 0.4}
        )
        ax.plot(closed[:, 0], closed[:, 1], color="tab:green", **style)
        drawn += 1
        last = key
    c = series.com
    sc = ax.scatter(
        c[:, 0], c[:, 1], c=series.t, s=6, cmap="viridis", label="CoM (ground projection)"
    )
    ax.plot(c[0, 0], c[0, 1], "ko", ms=5, label="start")
    ax.plot(c[-1, 0], c[-1, 1], "ks", ms=5, label="end")
    fig.colorbar(sc, ax=ax, label="time [s]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    title = "CoM path and support polygon"
    if series.contacts_assumed:
        title += "\n(run without contact data: every foot assumed in support)"
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    m = series.com_margin
    ax2.plot(series.t, 100 * m, color="tab:blue", lw=1.4, label="CoM margin")
    ax2.axhline(0.0, color="tab:red", ls="--", lw=1.0, label="polygon edge")
    ax2.set_xlabel("time [s]")
    ax2.set_ylabel("distance to the polygon edge [cm] (> 0 inside)")
    fin = m[np.isfinite(m)]
    ax2.set_title(
        f"CoM margin to the support polygon (min {100 * fin.min():.1f} cm)"
        if fin.size
        else "CoM margin (no support)",
        fontsize=10,
    )
    ax2.grid(alpha=0.3)
    ax2.legend(loc="best", fontsize=8)
    return _save(fig, Path(path))


def plot_power(
    series: MetricSeries, path: str | Path, *, before: MetricSeries | None = None
) -> Path:
    r"""Instantaneous :math:`|\tau^\top \dot q|` and its average per run (CRAC eq. 43, Fig. 9)."""
    fig = _figure("power")
    ax, ax2 = fig.subplots(1, 2, width_ratios=[2.6, 1])
    runs = (
        [("constraints off", before), ("this run", series)]
        if before is not None
        else [("this run", series)]
    )
    colors = ["0.5", "tab:blue"] if before is not None else ["tab:blue"]
    means = []
    for (label, s), col in zip(runs, colors, strict=True):
        tp = s.t[s.power_index]
        ax.plot(tp, s.power, color=col, lw=1.0, label=f"{label}: |tau' qdot|")
        mean = float(np.mean(s.power)) if s.power.size else float("nan")
        means.append(mean)
        ax.axhline(mean, color=col, ls="--", lw=1.2, label=f"{label}: mean {mean:.2f} W")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("power [W]")
    src = "controller torques" if series.power_source == "tau" else "RNEA on finite-difference q"
    ax.set_title(
        f"Power of the actuated joints ({src}; base wrench carried by the feet)", fontsize=10
    )
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    labels = [r[0] for r in runs]
    bars = ax2.bar(labels, means, color=colors)
    for b, v in zip(bars, means, strict=True):
        ax2.text(
            b.get_x() + b.get_width() / 2, v, f"{v:.2f} W", ha="center", va="bottom", fontsize=9
        )
    ax2.set_ylabel("average absolute power P [W]")
    ax2.set_title("P = mean |tau' qdot| (CRAC eq. 43)", fontsize=10)
    ax2.grid(alpha=0.3, axis="y")
    return _save(fig, Path(path))


def write_figures(
    series: MetricSeries,
    out_dir: str | Path,
    *,
    before: MetricSeries | None = None,
    joints: Sequence[str] | None = None,
    tasks: Sequence[str] | None = None,
) -> dict[str, Path]:
    """Draw every figure of the module docstring into ``out_dir``; returns name -> path.

    Raises:
        PlotDependencyError: when matplotlib is missing.
    """
    out = Path(out_dir)
    return {
        "tracking": plot_tracking(series, out / "tracking.png", tasks=tasks),
        "pair_distances": plot_pair_distances(series, out / "pair_distances.png", before=before),
        "joint_angles": plot_joint_angles(series, out / "joint_angles.png", joints=joints),
        "violations": plot_violations(series, out / "violations.png", before=before),
        "com_support": plot_com_support(series, out / "com_support.png"),
        "power": plot_power(series, out / "power.png", before=before),
    }


def figure_pixels(name: str) -> tuple[int, int]:
    """(width, height) in pixels of figure ``name``."""
    w, h = FIGSIZE[name]
    return int(round(w * DPI)), int(round(h * DPI))
