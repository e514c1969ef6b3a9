#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""Throughput of ``qpretarget batch`` on the shared clips: pool with 1 and 2 workers, and Ray.

Usage:
    python scripts/bench_batch.py                       # every clip of ../shared/data/mocap
    python scripts/bench_batch.py --engines pool --workers 1 2 --formats csv,pkl,npz --fps 30

Each run retargets every clip (``--force``) into a fresh temporary folder and reports wall time,
clips per minute and control ticks per second; a failed clip is listed. Ray's overhead is its wall
time minus the pool's at the same worker count (Ray starts a local instance inside the run).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from qpretarget.dataset.batch import make_jobs, run_batch
from qpretarget.dataset.exports import parse_formats

REPO = Path(__file__).resolve().parents[1]
MOCAP = REPO.parent / "shared" / "data" / "mocap"


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--config", default=str(REPO / "configs" / "g1_whole_body.yaml"))
    ap.add_argument("--inputs", nargs="+", default=[str(MOCAP)])
    ap.add_argument("--engines", nargs="+", default=["pool", "ray"])
    ap.add_argument("--workers", nargs="+", type=int, default=[1, 2])
    ap.add_argument("--formats", default="csv,pkl,npz")
    ap.add_argument("--fps", type=float, default=30.0)
    args = ap.parse_args()
    formats = parse_formats(args.formats)
    print("| engine | workers | clips | failed | wall s | clips/min | ticks/s |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for engine in args.engines:
        for workers in args.workers:
            with tempfile.TemporaryDirectory() as out:
                jobs = make_jobs(args.config, args.inputs, out, formats=formats, fps=args.fps,
                                 force=True)  # fmt: skip
                t0 = time.perf_counter()
                rows = run_batch(jobs, engine=engine, workers=workers)
                wall = time.perf_counter() - t0
            ok = [r for r in rows if r.status == "ok"]
            ticks = sum(r.frames for r in ok)
            print(f"| {engine} | {workers} | {len(rows)} | {len(rows) - len(ok)} | {wall:.1f} | "
                  f"{60 * len(rows) / wall:.1f} | {ticks / wall:.0f} |", flush=True)  # fmt: skip
            for r in rows:
                if r.status != "ok":
                    print(f"  failed: {r.clip}: {r.error}")


if __name__ == "__main__":
    main()
