#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""Bar chart of the per-tick cost of every library in one anchors run (docs/benchmarks.md).

Reads the "Per-tick cost and tracking" table of a RESULTS-anchors.md written by
``../shared/bench/run_anchors.sh`` (Pink, mink, PlaCo and qpretarget in one run) and draws the
median µs per tick (bar) and p95 (tick mark) of each library / solver, one panel per variant.

Usage:
    python scripts/plot_benchmarks.py RESULTS-anchors.md -o docs/figures/benchmarks.png
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def read_table(path: Path) -> list[dict[str, str]]:
    """Rows of the first markdown table whose header starts with ``| variant |``."""
    rows: list[dict[str, str]] = []
    header: list[str] | None = None
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("| variant |") and header is None:
            header = [c.strip() for c in line.strip("|").split("|")]
            continue
        if header is not None:
            if not line.startswith("|"):
                if rows:
                    break
                continue
            cells = [c.strip() for c in line.strip("|").split("|")]
            if set(cells[0]) <= {"-", ":"}:
                continue
            rows.append(dict(zip(header, cells, strict=False)))
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("results", help="RESULTS-anchors.md of one run")
    ap.add_argument("-o", "--output", required=True, help="PNG to write")
    args = ap.parse_args(argv)
    rows = read_table(Path(args.results))
    if not rows:
        print(f"no '| variant |' table in {args.results}", file=sys.stderr)
        return 1
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from qpretarget.fileio import atomic_path

    variants = list(dict.fromkeys(r["variant"] for r in rows))
    fig, axes = plt.subplots(1, len(variants), figsize=(5.2 * len(variants), 4.8), squeeze=False)
    for ax, v in zip(axes[0], variants, strict=True):
        sel = [r for r in rows if r["variant"] == v]
        labels = [r["library / QP solver"].replace(" / ", "\n") for r in sel]
        med = [float(r["median µs"]) for r in sel]
        p95 = [float(r["p95 µs"]) for r in sel]
        colors = [
            "tab:green" if "qpretarget" in lab else "tab:orange" if "placo" in lab else "tab:gray"
            for lab in labels
        ]
        y = range(len(sel))
        ax.barh(list(y), med, color=colors)
        ax.scatter(p95, list(y), marker="|", color="black", s=120, label="p95")
        ax.set_yticks(list(y), labels, fontsize=7)
        ax.invert_yaxis()
        ax.set_xscale("log")
        ax.set_xlim(left=20)
        ax.set_xlabel("µs per tick (median bar, p95 mark; log scale)")
        ax.set_title(f"workload {v}")
        ax.grid(axis="x", alpha=0.3)
    axes[0][0].legend(loc="lower right", fontsize=8)
    fig.suptitle("G1 retargeting tick, one anchors run (../shared/bench): lower is faster")
    fig.tight_layout()
    with atomic_path(args.output, ".png") as tmp:
        fig.savefig(tmp, dpi=110)
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
