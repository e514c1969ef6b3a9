# SPDX-License-Identifier: Apache-2.0
"""The figure of a point-cloud run's arm-direction errors (matplotlib, Agg backend)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import missing_dependency
from ..fileio import atomic_path
from .measures import ARM_LOST_DEG, ARM_SEGMENTS, ARM_TOLERANCE_DEG


def plot_arm_directions(
    errors: np.ndarray, t: np.ndarray, path: str | Path, title: str = ""
) -> Path:
    """Draw each arm segment's direction error over time and write it to ``path`` (PNG).

    ``errors``: (T, 4) from :func:`~qpretarget.cloud.measures.arm_direction_errors` [deg],
    columns :data:`~qpretarget.cloud.measures.ARM_SEGMENTS`; ``t``: (T,) [s]. The tolerance
    (:data:`~qpretarget.cloud.measures.ARM_TOLERANCE_DEG`) and the *lost* threshold
    (:data:`~qpretarget.cloud.measures.ARM_LOST_DEG`) are drawn as lines. Written atomically.

    Raises:
        MissingDependencyError: matplotlib is not installed (``plot`` extra).
    """
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        raise missing_dependency("plot", "drawing the arm-direction figure") from None
    e = np.asarray(errors, float)
    tt = np.asarray(t, float)
    tt = tt - tt[0]
    fig = Figure(figsize=(9, 3.5), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    for k, name in enumerate(ARM_SEGMENTS):
        ax.plot(tt, e[:, k], lw=1.2, label=name.replace("_", " "))
    ax.axhline(ARM_TOLERANCE_DEG, color="k", ls="--", lw=1, label=f"{ARM_TOLERANCE_DEG:g} deg")
    ax.axhline(ARM_LOST_DEG, color="r", ls=":", lw=1, label=f"lost ({ARM_LOST_DEG:g} deg)")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("arm direction error [deg]")
    ax.set_ylim(0, max(ARM_LOST_DEG + 5, float(np.nanmax(e)) * 1.05 if e.size else 0.0))
    ax.set_title(title or "robot's arm segments vs the rendered person's")
    ax.legend(loc="upper left", fontsize=8, ncol=3)
    out = Path(path)
    with atomic_path(out, suffix=out.suffix) as tmp:  # no half-written figure
        fig.savefig(tmp)
    return out


__all__ = ["plot_arm_directions"]
