"""`qpretarget evaluate --physics` writes physics.json; the batch summary gets physics columns."""

from __future__ import annotations

import json
import math

import pytest

from qpretarget.cli import main

pytest.importorskip("mujoco")


def test_evaluate_physics(drink_run, tmp_path, capsys):
    out = tmp_path / "report"
    assert main(["evaluate", str(drink_run), "-o", str(out), "--physics", "--no-figures"]) == 0
    m = json.loads((out / "physics.json").read_text())
    assert m["unassisted"]["survived_fraction"] == 1.0
    assert len(m["per_frame"]["pelvis_height_m"]) == len(m["per_frame"]["t"])
    assert json.loads((out / "metrics.json").read_text())["physics"]["verdict"] == m["verdict"]
    assert f"physics          {m['verdict']}: survived 100.0 %" in capsys.readouterr().out


def test_batch_summary_physics_columns():
    from qpretarget.dataset.batch import ClipResult, summary_rows

    rows = [
        ClipResult("a.bvh", "ok", physics={"verdict": "ok", "survived": 1.0}),
        ClipResult("b.bvh", "failed"),
    ]
    cols, table = summary_rows(rows)
    assert "physics/verdict" in cols and "physics/survived" in cols
    assert table[0]["physics/survived"] == 1.0 and math.isnan(table[1]["physics/survived"])


def test_batch_table_shows_the_verdict():
    from qpretarget.dataset.batch import ClipResult, format_table

    text = format_table([ClipResult("a.bvh", "ok", physics={"verdict": "falls", "survived": 0.3})])
    assert "physics" in text.splitlines()[0] and "falls 30%" in text


def test_batch_physics_end_to_end(tmp_path, static_cfg, mocap_dir):
    """One real clip through `qpretarget batch --physics`: per-clip JSON + figure, summary columns."""
    import csv

    cfg = static_cfg
    out = tmp_path / "out"
    clip = mocap_dir / "cmu_14_37_drink_soda.bvh"
    argv = ["batch", str(cfg), str(clip), "-o", str(out), "--physics", "--no-audit", "--quiet"]
    assert main([*argv, "--workers", "1"]) == 0
    assert (out / "cmu_14_37_drink_soda.physics.json").is_file()
    assert (out / "cmu_14_37_drink_soda.physics.png").is_file()
    (row,) = list(csv.DictReader((out / "summary.csv").open()))
    assert float(row["physics/survived"]) == 1.0
