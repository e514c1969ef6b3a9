# SPDX-License-Identifier: Apache-2.0
r"""``qpretarget batch``: retarget every clip of a dataset, one output per clip, and a summary.

Inputs are files, folders (searched recursively) or glob patterns of motion files
(:data:`~qpretarget.motion.load.MOTION_EXTENSIONS`). Each clip is a job (:func:`run_clip`):
load, retarget at the control rate, resample to ``--fps``, export in every ``--format``
(atomically), then write a manifest ``<clip>.manifest.json`` last. A clip whose manifest names
the same config hash, options and qpretarget version, with every output present, is skipped
(resumable; ``--force`` redoes it). A clip that fails is reported with its reason and the others
go on. Engines (:data:`ENGINES`): ``pool`` — a local process pool, embedded; ``ray`` — one Ray
task per clip, on a local Ray instance started for the batch or an existing cluster
(``--address``). Both run the same :func:`run_clip`, so their outputs are the same.
"""

from __future__ import annotations

import csv
import glob
import hashlib
import io
import json
import math
import os
import time
import traceback
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from ..errors import ConfigError, QPRetargetError, missing_dependency
from ..fileio import write_atomic

#: Columns of summary.csv, in order (per-task RMSE columns follow as ``rmse_mm/<task>``).
SUMMARY_COLUMNS = (
    "clip", "status", "frames", "duration_s", "output_frames", "joint_limit_violations",
    "penetrating_frames", "min_pair_distance_mm", "relaxed_ticks", "held_ticks", "wall_time_s",
    "outputs", "notes", "error",
)  # fmt: skip


@dataclass(frozen=True)
class ClipJob:
    """One clip to retarget (picklable: it crosses process and Ray boundaries).

    Attributes:
        clip: the motion file.
        stem: output path without suffix.
        config: the controller YAML file.
        config_sha256: hash of the config text and the options (what makes an output current).
        formats: export format names.
        fps: output rate [Hz], ``None``: the control rate.
        force: redo even when the manifest says the outputs are current.
        audit: run the all-pairs self-collision audit for the summary.
    """

    clip: str
    stem: str
    config: str
    config_sha256: str
    formats: tuple[str, ...]
    fps: float | None
    force: bool = False
    audit: bool = True
    physics: bool = False  # replay in MuJoCo: physics/<column> summary columns (docs/physics.md)


@dataclass
class ClipResult:
    """One row of the summary (:data:`SUMMARY_COLUMNS`)."""

    clip: str
    status: str
    frames: int = 0
    duration_s: float = 0.0
    output_frames: int = 0
    joint_limit_violations: int = 0
    penetrating_frames: int = 0
    min_pair_distance_mm: float = math.nan
    relaxed_ticks: int = 0
    held_ticks: int = 0
    wall_time_s: float = 0.0
    outputs: list[str] = field(default_factory=list)
    #: The run's notes on its input, " | "-joined: frames dropped on loading, a corrected
    #: skeleton (waist lift, rest pose), a start in the air, a person lying down.
    notes: str = ""
    error: str = ""
    rmse_mm: dict[str, float] = field(default_factory=dict)
    physics: dict[str, Any] = field(default_factory=dict)


# ------------------------------------------------------------------------------------ inputs
def discover_inputs(inputs: Sequence[str]) -> list[tuple[Path, Path]]:
    """Motion files named by ``inputs`` as ``(file, root)``; outputs mirror paths below root.

    Raises:
        ConfigError: an input that exists nowhere, or no motion file at all.
    """
    from ..motion.load import MOTION_EXTENSIONS, SCANNED_ENDINGS, is_scanned_motion_file

    found: dict[Path, Path] = {}
    for item in inputs:
        p = Path(item)
        if p.is_dir():
            for f in sorted(p.rglob("*")):
                if f.is_file() and is_scanned_motion_file(f):
                    found.setdefault(f.resolve(), p.resolve())
        elif p.is_file():
            found.setdefault(p.resolve(), p.resolve().parent)
        else:
            matches = sorted(glob.glob(item, recursive=True))
            if not matches:
                raise ConfigError(
                    f"input {item!r} is neither a file, a folder nor a matching glob."
                )
            for m in matches:
                mp = Path(m)
                if mp.is_file() and mp.suffix.lower() in MOTION_EXTENSIONS:
                    found.setdefault(mp.resolve(), mp.resolve().parent)
    if not found:
        raise ConfigError(
            "no motion file found in the inputs (folders: "
            f"{', '.join(SCANNED_ENDINGS)}; files and globs: {', '.join(MOTION_EXTENSIONS)}; "
            ".asf skeletons are read with their .amc)."
        )
    return sorted(found.items())


def make_jobs(
    config: str | Path,
    inputs: Sequence[str],
    out_dir: str | Path,
    *,
    formats: Sequence[str],
    fps: float | None,
    force: bool = False,
    audit: bool = True,
    physics: bool = False,
) -> list[ClipJob]:
    """One :class:`ClipJob` per motion file, outputs under ``out_dir`` mirroring the inputs."""
    config = Path(config)
    if not config.is_file():
        raise ConfigError(f"config file {str(config)!r} does not exist.")
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"output folder {str(out)!r} is a file; give a folder with -o.")
    options = {"formats": sorted(formats), "fps": fps, "audit": audit, "version": _version()}
    if physics:
        options["physics"] = True
    sha = hashlib.sha256(config.read_bytes() + json.dumps(options).encode()).hexdigest()
    jobs = []
    for clip, root in discover_inputs(inputs):
        rel = clip.relative_to(root) if clip.is_relative_to(root) else Path(clip.name)
        stem = out / rel.parent / rel.stem
        jobs.append(
            ClipJob(
                str(clip), str(stem), str(config.resolve()), sha, tuple(formats), fps, force, audit
            )
        )
    if physics:
        jobs = [replace(j, physics=True) for j in jobs]
    return jobs


def _version() -> str:
    from .. import __version__

    return str(__version__)


# --------------------------------------------------------------------------------- one clip
_CONTROLLERS: dict[str, Any] = {}


def _controller(config: str) -> Any:
    """A controller per config file and process, built once and reset per clip."""
    from ..control.controller import Controller

    if config not in _CONTROLLERS:
        _CONTROLLERS[config] = Controller.from_yaml(config)
    return _CONTROLLERS[config]


def _manifest_path(job: ClipJob) -> Path:
    return Path(job.stem + ".manifest.json")


def is_current(job: ClipJob) -> bool:
    """The manifest names this job's config hash and every output it lists exists."""
    path = _manifest_path(job)
    if job.force or not path.is_file():
        return False
    try:
        man = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return man.get("config_sha256") == job.config_sha256 and all(
        Path(f).is_file() for f in man.get("outputs", [])
    )


def run_clip(job: ClipJob) -> ClipResult:
    """Retarget one clip, export it, write its manifest; never raises (a failure is a row)."""
    t0 = time.perf_counter()
    name = job.clip
    try:
        if is_current(job):
            man = json.loads(_manifest_path(job).read_text(encoding="utf-8"))
            row = ClipResult(**{**man["row"], "status": "skipped"})
            return row
        row = _retarget_and_export(job)
    except QPRetargetError as exc:
        row = ClipResult(name, "failed", error=str(exc).splitlines()[0])
    except (OSError, ValueError, KeyError, IndexError, TypeError, ArithmeticError) as exc:
        row = ClipResult(name, "failed", error=f"{type(exc).__name__}: {exc}")
    except Exception as exc:  # noqa: BLE001  (a batch never dies from one clip)
        last = traceback.format_exc().strip().splitlines()[-1]
        row = ClipResult(name, "failed", error=f"unexpected {type(exc).__name__}: {last}")
    row.wall_time_s = time.perf_counter() - t0
    return row


def _retarget_and_export(job: ClipJob) -> ClipResult:
    import numpy as np

    from ..analysis.mesh_audit import audit_self_collision
    from ..motion import load_motion
    from ..retarget import Retargeter
    from ..retarget.summary import summarize_run
    from .exports import export_run
    from .resample import resample_run

    controller = _controller(job.config)
    controller.reset()
    motion = load_motion(job.clip)
    retargeter = Retargeter(controller)
    run = retargeter.retarget(motion, progress=False)
    run.meta["config_name"] = Path(job.config).name
    run.meta["config_sha256"] = job.config_sha256
    run.meta["source_clip"] = job.clip
    summary = summarize_run(run, controller)
    out_run = run if job.fps is None else resample_run(run, job.fps, robot=controller.robot)
    Path(job.stem).parent.mkdir(parents=True, exist_ok=True)
    files = export_run(out_run, job.stem, job.formats, robot=controller.robot, source=job.clip)
    status = np.asarray(run.status if run.status is not None else [], dtype=str)
    row = ClipResult(
        job.clip,
        "ok",
        frames=len(run.t),
        duration_s=float(run.t[-1] - run.t[0]) if len(run.t) > 1 else 0.0,
        output_frames=len(out_run.t),
        joint_limit_violations=int(summary.get("joint_limit_violations", 0)),
        relaxed_ticks=int(np.count_nonzero(status == "relaxed")),
        held_ticks=int(np.count_nonzero(status == "held")),
        outputs=[str(f) for f in files],
        notes=" | ".join([*run.meta.get("motion_notes", []), *retargeter.notes]),
        rmse_mm={k: float(v) for k, v in summary.get("rmse_mm", {}).items()},
    )
    if job.audit:
        audit = audit_self_collision(controller.robot, np.asarray(run.q), stride=2)
        row.penetrating_frames = audit.penetrating_frames
        row.min_pair_distance_mm = audit.min_distance_mm
    if job.physics:
        row.physics = _physics(run, controller.robot, job.stem, row.outputs)
    manifest = {"config_sha256": job.config_sha256, "outputs": row.outputs, "row": asdict(row)}
    write_atomic(_manifest_path(job), lambda f: f.write(json.dumps(manifest)), binary=False)
    return row


def _physics(run: Any, robot: Any, stem: str, outputs: list[str]) -> dict[str, Any]:
    """MuJoCo replay of a clip: ``<stem>.physics.json`` and ``.png``; the summary columns."""
    from ..physics.metrics import dumps, per_frame_series, summary_row
    from ..physics.replay import check_run

    metrics, free, helped = check_run(run, robot=robot)
    metrics["per_frame"] = per_frame_series(free, helped)
    text = dumps(metrics)
    outputs.append(str(write_atomic(stem + ".physics.json", lambda f: f.write(text), binary=False)))
    try:
        from ..physics.plots import write_figure

        outputs.append(str(write_figure(free, helped, stem + ".physics.png", Path(stem).name)))
    except ImportError:  # matplotlib missing: the metrics are written, the figure is not
        pass
    return summary_row(metrics)


# ---------------------------------------------------------------------------------- engines
def _pool(jobs: Sequence[ClipJob], workers: int, address: str | None) -> Iterator[ClipResult]:
    if workers <= 1 or len(jobs) <= 1:
        for job in jobs:
            yield run_clip(job)
        return
    with ProcessPoolExecutor(max_workers=workers) as ex:
        futures = [ex.submit(run_clip, job) for job in jobs]
        for fut in as_completed(futures):
            yield fut.result()


def _ray(jobs: Sequence[ClipJob], workers: int, address: str | None) -> Iterator[ClipResult]:
    try:
        import ray
    except ImportError:
        raise missing_dependency("ray", "--engine ray (Ray)") from None
    started = not ray.is_initialized()
    if started:
        if address:
            ray.init(address=address, log_to_driver=False)
        else:
            ray.init(num_cpus=max(1, workers), include_dashboard=False, log_to_driver=False)
    try:
        remote = ray.remote(num_cpus=1)(run_clip)
        pending = [remote.remote(job) for job in jobs]
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            yield ray.get(done[0])
    finally:
        if started:
            ray.shutdown()


#: Batch engines by ``--engine`` name: ``(jobs, workers, address) -> results as they finish``.
ENGINES: dict[str, Callable[[Sequence[ClipJob], int, str | None], Iterator[ClipResult]]] = {
    "pool": _pool,
    "ray": _ray,
}


def run_batch(
    jobs: Sequence[ClipJob],
    *,
    engine: str = "pool",
    workers: int | None = None,
    address: str | None = None,
    progress: bool = False,
) -> list[ClipResult]:
    """Run every job on ``engine``; results in the jobs' order.

    Raises:
        ConfigError: an unknown engine, or Ray missing for ``ray``.
    """
    if engine not in ENGINES:
        raise ConfigError(f"unknown engine {engine!r}; choose from {', '.join(ENGINES)}.")
    workers = workers or os.cpu_count() or 1
    results: dict[str, ClipResult] = {}
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(jobs), unit="clip", desc="batch")
    try:
        for row in ENGINES[engine](jobs, workers, address):
            results[row.clip] = row
            if bar is not None:
                bar.set_postfix_str(f"{Path(row.clip).name}: {row.status}")
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    return [results[j.clip] for j in jobs]


# ---------------------------------------------------------------------------------- summary
def summary_rows(results: Iterable[ClipResult]) -> tuple[list[str], list[dict[str, Any]]]:
    """Columns and rows of the summary table (per-task RMSE columns after the fixed ones)."""
    results = list(results)
    tasks = sorted({k for r in results for k in r.rmse_mm})
    phys = [k for k in dict.fromkeys(k for r in results for k in r.physics)]
    cols = list(SUMMARY_COLUMNS[:-3]) + [f"rmse_mm/{t}" for t in tasks]
    cols += [f"physics/{k}" for k in phys] + ["outputs", "notes", "error"]
    rows = []
    for r in results:
        d = asdict(r)
        ph = d.pop("physics")
        d.update({f"physics/{k}": ph.get(k, math.nan) for k in phys})
        rm = d.pop("rmse_mm")
        d["outputs"] = ";".join(d["outputs"])
        d.update({f"rmse_mm/{t}": rm.get(t, math.nan) for t in tasks})
        rows.append({c: d[c] for c in cols})
    return cols, rows


def write_summary(results: Sequence[ClipResult], out_dir: str | Path) -> tuple[Path, Path]:
    """``summary.csv`` and ``summary.json`` in ``out_dir`` (atomically); return both paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cols, rows = summary_rows(results)
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols)
    w.writeheader()
    w.writerows(rows)
    p_csv = write_atomic(out / "summary.csv", lambda f: f.write(buf.getvalue()), binary=False)
    text = json.dumps({"clips": [asdict(r) for r in results]}, indent=1, default=str)
    p_json = write_atomic(out / "summary.json", lambda f: f.write(text), binary=False)
    return p_csv, p_json


def format_table(results: Sequence[ClipResult]) -> str:
    """The summary as a fixed-width table for the terminal."""
    head = f"{'clip':40s} {'status':8s} {'frames':>7s} {'hand mm':>8s} {'limits':>6s} "
    head += f"{'pen.fr':>6s} {'held':>5s} {'wall s':>7s}"
    physics = any(r.physics for r in results)
    if physics:
        head += f" {'physics':>16s}"
    lines = [head, "-" * len(head)]
    for r in results:
        hands = [v for k, v in r.rmse_mm.items() if "hand" in k]
        hand = f"{sum(hands) / len(hands):8.1f}" if hands else f"{'-':>8s}"
        lines.append(
            f"{Path(r.clip).name[:40]:40s} {r.status:8s} {r.frames:7d} {hand} "
            f"{r.joint_limit_violations:6d} {r.penetrating_frames:6d} {r.held_ticks:5d} "
            f"{r.wall_time_s:7.1f}"
        )
        if physics and r.physics:
            ph = f"{r.physics['verdict']} {r.physics['survived'] * 100:.0f}%"
            lines[-1] += f" {ph:>16s}"
        if r.error:
            lines.append(f"    error: {r.error}")
        for note in filter(None, r.notes.split(" | ")):
            lines.append(f"    note: {note[:160]}")
    return "\n".join(lines)
