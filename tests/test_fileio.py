# SPDX-License-Identifier: Apache-2.0
"""Atomic file writing (qpretarget/fileio.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from qpretarget.fileio import _umask, atomic_path, write_atomic


def test_atomic_files_get_the_usual_mode(tmp_path: Path) -> None:
    """Files written atomically are readable like any other (mkstemp alone leaves 0600)."""
    out = write_atomic(tmp_path / "x.json", lambda f: f.write("{}"), binary=False)
    assert out.read_text() == "{}"
    assert (out.stat().st_mode & 0o777) == (0o666 & ~_umask())


def test_a_failed_write_leaves_neither_the_file_nor_a_temporary(tmp_path: Path) -> None:
    target = tmp_path / "y.bin"
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        tmp.write_bytes(b"partial")
        raise RuntimeError("writer failed")
    assert not target.exists() and list(tmp_path.iterdir()) == []


def test_run_files_figures_and_comparisons_are_written_atomically(
    tmp_path: Path, monkeypatch
) -> None:
    """``RobotTrajectory.save`` (the library's and ``qpretarget demo``'s run file), the
    evaluation figures and ``compare-solvers``' tables go through a temporary file: a writer
    that fails leaves the old file as it was and no temporary behind."""
    import numpy as np

    from qpretarget.trajectory import RobotTrajectory

    traj = RobotTrajectory(
        t=np.arange(3) * 0.01,
        q=np.zeros((3, 8)),
        v=np.zeros((3, 7)),
        joint_names=["j"],
        robot="g1",
        config_yaml="",
    )
    out = traj.save(tmp_path / "run.npz")
    before = out.read_bytes()
    assert np.array_equal(RobotTrajectory.load(out).q, traj.q)

    def broken(file, *_a, **_k) -> None:  # noqa: ANN001
        Path(file).write_bytes(b"PK\x03\x04 half a zip")  # then the disk is full
        raise OSError("disk full")

    monkeypatch.setattr(np, "savez_compressed", broken)
    with pytest.raises(OSError, match="disk full"):
        traj.save(out)
    assert out.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.npz"]

    from qpretarget.analysis.plots import FIGSIZE, _figure, _save

    png = _save(_figure(next(iter(FIGSIZE))), tmp_path / "fig.png")
    assert png.read_bytes()[:4] == b"\x89PNG"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fig.png", "run.npz"]
