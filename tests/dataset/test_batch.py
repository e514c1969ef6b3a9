# SPDX-License-Identifier: Apache-2.0
"""``qpretarget batch``: a folder of real clips, a corrupt one among them, resume, engines."""

from __future__ import annotations

import csv
import json
import subprocess
import sys

import numpy as np
import pytest

from qpretarget.dataset.batch import make_jobs, run_batch
from qpretarget.errors import ConfigError


def _batch(args: list[str], cwd) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "qpretarget", "batch", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=600)  # fmt: skip


def test_folder_with_a_corrupt_clip(tmp_path, clip_dir, repo_dir):
    data = tmp_path / "data"
    data.mkdir()
    for f in clip_dir.rglob("*.bvh"):
        (data / f.name).write_bytes(f.read_bytes())
    (data / "broken.bvh").write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0")  # truncated
    out = tmp_path / "out"
    cfg = str(repo_dir / "configs" / "g1_whole_body.yaml")
    r = _batch([cfg, str(data), "-o", str(out), "--format", "csv,pkl,npz", "--fps", "30",
                "--workers", "2", "--no-audit"], repo_dir)  # fmt: skip
    assert r.returncode == 1, r.stdout + r.stderr  # one clip failed
    assert "Traceback" not in r.stderr
    rows = list(csv.DictReader(open(out / "summary.csv")))
    status = {row["clip"].split("/")[-1]: row["status"] for row in rows}
    assert status == {"teapot.bvh": "ok", "walk_stop.bvh": "ok", "boxing.bvh": "ok",
                      "broken.bvh": "failed"}  # fmt: skip
    broken = next(row for row in rows if row["clip"].endswith("broken.bvh"))
    assert broken["error"] and "broken.bvh" in broken["error"]
    # CMU skeletons need no correction: their rows carry no note (docs/datasets.md).
    assert all(row["notes"] == "" for row in rows)
    for stem in ("teapot", "walk_stop", "boxing"):
        for suffix in (".csv", ".json", ".pkl", ".npz", ".manifest.json"):
            assert (out / f"{stem}{suffix}").is_file()
    assert not list(out.glob(".*"))  # no half-written temporary file
    summary = json.loads((out / "summary.json").read_text())
    assert len(summary["clips"]) == 4
    # Resumable: a second run skips every current clip.
    r2 = _batch([cfg, str(data), "-o", str(out), "--format", "csv,pkl,npz", "--fps", "30",
                 "--workers", "1", "--no-audit"], repo_dir)  # fmt: skip
    assert "3 skipped" in r2.stdout, r2.stdout


def test_pool_and_ray_give_identical_outputs(tmp_path, clip_dir, repo_dir):
    pytest.importorskip("ray", reason="the Ray engine needs the `ray` extra (CI installs it)")
    # The shipped config's solver (daqp) is bit-reproducible across processes.
    daqp_cfg = repo_dir / "configs" / "g1_whole_body.yaml"
    assert "solver: {name: daqp}" in daqp_cfg.read_text()
    outs = {}
    for engine in ("pool", "ray"):
        jobs = make_jobs(daqp_cfg, [str(clip_dir)], tmp_path / engine, formats=["npz"],
                         fps=None, audit=False)  # fmt: skip
        rows = run_batch(jobs, engine=engine, workers=2)
        assert [r.status for r in rows] == ["ok"] * 3, [r.error for r in rows]
        outs[engine] = {p.name: np.load(p)["q"] for p in (tmp_path / engine).rglob("*.npz")}
    assert outs["pool"].keys() == outs["ray"].keys()
    for name in outs["pool"]:
        np.testing.assert_array_equal(outs["pool"][name], outs["ray"][name])


def test_output_path_that_is_a_file_is_one_clear_line(tmp_path, clip_dir, repo_dir):
    target = tmp_path / "out"
    target.write_text("not a folder")
    with pytest.raises(ConfigError, match="is a file"):
        make_jobs(repo_dir / "configs" / "g1_whole_body.yaml", [str(clip_dir)], target,
                  formats=["npz"], fps=None)  # fmt: skip
    r = _batch([str(repo_dir / "configs" / "g1_whole_body.yaml"), str(clip_dir), "-o",
                str(target)], repo_dir)  # fmt: skip
    assert r.returncode != 0 and "Traceback" not in r.stderr
    assert "is a file" in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_a_corrected_skeleton_is_noted_in_the_summary(tmp_path, repo_dir):
    """A clip whose skeleton was corrected (here: the waist key-point at the hip joints,
    raised) says so in its summary row's ``notes`` (csv and json) and under the table; a
    clip without notes has an empty cell (the shared CMU clips: test above)."""
    from qpretarget.dataset.batch import ClipResult, format_table, summary_rows

    rows = [
        ClipResult("a.bvh", "ok", notes="key-points: the skeleton's waist ... raised by 10.0 cm"),
        ClipResult("b.bvh", "ok"),
    ]
    cols, table = summary_rows(rows)
    assert cols[-3:] == ["outputs", "notes", "error"]
    assert "raised by" in table[0]["notes"] and table[1]["notes"] == ""
    assert "    note: key-points" in format_table(rows)
