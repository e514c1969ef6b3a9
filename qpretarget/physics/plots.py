# SPDX-License-Identifier: Apache-2.0
"""The figure of a physics replay (matplotlib, Agg backend): one PNG per clip."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..errors import missing_dependency
from ..fileio import atomic_path
from .metrics import FALL_HEIGHT_M, FALL_TILT_DEG, feet_share_per_frame, joint_rms_per_frame


def write_figure(free: Any, assisted: Any | None, path: str | Path, title: str = "") -> Path:
    """Draw the replay series and write them to ``path`` (PNG, atomically).

    Panels: pelvis height (simulated, reference, fall threshold); torso tilt and base errors;
    joint tracking RMS and saturated joints per frame; feet weight share (unassisted and
    assisted) and the assisting force as % of body weight; the reference ZMP's margin to the
    stance soles (when :func:`~qpretarget.physics.replay.check_run` computed it).

    Raises:
        MissingDependencyError: matplotlib is not installed (``plot`` extra).
    """
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise missing_dependency("plot", "drawing the physics figure") from None
    t = free.t - free.t[0]
    zmp = getattr(free, "ref_zmp_margin", None)
    rows = 5 if zmp is not None else 4
    fig, axes = plt.subplots(rows, 1, figsize=(9, 2.5 * rows), sharex=True)
    ax = axes[0]
    ax.plot(t, free.pelvis_height_ref, "k--", lw=1, label="reference")
    ax.plot(t, free.pelvis_height, label="unassisted")
    if assisted is not None:
        ax.plot(t, assisted.pelvis_height, alpha=0.7, label="assisted")
    ax.plot(t, free.pelvis_height_ref - FALL_HEIGHT_M, "r:", lw=1, label="fall threshold")
    if free.fallen_at is not None:
        ax.axvline(t[free.fallen_at], color="r", lw=1)
    ax.set_ylabel("pelvis height [m]")
    ax.legend(loc="lower left", fontsize=8)
    ax = axes[1]
    ax.plot(t, free.tilt_deg, label="torso tilt vs reference [deg]")
    ax.plot(t, free.root_ori_err_deg, label="base orientation error [deg]")
    ax.plot(t, free.root_pos_err * 100.0, label="base position error [cm]")
    ax.axhline(FALL_TILT_DEG, color="r", ls=":", lw=1)
    ax.legend(loc="upper left", fontsize=8)
    ax = axes[2]
    ax.plot(t, np.degrees(joint_rms_per_frame(free)), label="joint tracking RMS [deg]")
    n_sat = np.count_nonzero(free.saturated, axis=1).astype(float)
    n_sat[free.simulated :] = np.nan  # not simulated after the fall
    ax.plot(t, n_sat, label="joints at torque limit")
    ax.legend(loc="upper left", fontsize=8)
    ax = axes[3]
    ax.plot(t, feet_share_per_frame(free) * 100.0, label="feet share, unassisted [% BW]")
    if assisted is not None:
        ax.plot(t, feet_share_per_frame(assisted) * 100.0, label="feet share, assisted [% BW]")
        ax.plot(t, assisted.assist_force / assisted.weight * 100.0, label="assist force [% BW]")
    ax.legend(loc="upper left", fontsize=8)
    if zmp is not None:
        ax = axes[4]
        margin = np.clip(np.asarray(zmp, float) * 100.0, -30.0, None)  # spikes in landings
        ax.plot(t, margin, label="reference ZMP margin to the stance soles [cm] (clipped at -30)")
        ax.axhline(0.0, color="r", ls=":", lw=1)
        ax.legend(loc="lower left", fontsize=8)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(title or "physics replay")
    fig.tight_layout()
    path = Path(path)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=80)
    plt.close(fig)
    return path
