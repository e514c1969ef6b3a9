# SPDX-License-Identifier: Apache-2.0
"""``qpretarget batch``: retarget a dataset (files, folders, globs) to trainer formats."""

from __future__ import annotations

import argparse
import os
import sys

from . import add_command, add_config, add_output, add_quiet

SUMMARY = "retarget every clip of a dataset; export csv/pkl/npz; summary table"
DESCRIPTION = "Retarget files, folders (recursive) or globs of BVH, ASF/AMC and C3D clips."

HELP = """examples:
  qpretarget batch configs/g1_whole_body.yaml ../shared/data/mocap -o out \
      --format csv,pkl,npz --fps 30
  qpretarget batch configs/g1_whole_body.yaml 'mocap/**/*.bvh' -o out --workers 2
  qpretarget batch configs/g1_whole_body.yaml mocap/ -o out --engine ray            local Ray
  qpretarget batch configs/g1_whole_body.yaml mocap/ -o out --engine ray --address auto   cluster
  qpretarget batch configs/g1_whole_body.yaml mocap/ -o out --physics   + MuJoCo replay per clip

One output per clip (folders mirrored under OUT_DIR), summary.csv and summary.json in OUT_DIR.
A clip whose outputs are current (same config, options and version) is skipped; --force redoes
it. A clip that fails is listed with its reason; the exit status is 1 if any failed.
Formats (docs/formats.md): csv (Unitree LAFAN1 / BeyondMimic layout + JSON sidecar), pkl (GMR),
npz (qpretarget run). See docs/datasets.md.
"""


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``batch`` subcommand."""
    p = add_command(sub, "batch", help=SUMMARY, description=DESCRIPTION, examples=HELP)
    add_config(p)
    p.add_argument("inputs", nargs="+", help="motion files, folders or glob patterns")
    add_output(p, "output folder")
    p.add_argument("--format", default="npz", help="comma-separated: csv, pkl, npz (default npz)")
    p.add_argument("--fps", type=float, default=None, help="output rate [Hz] (default: control)")
    p.add_argument("--workers", type=int, default=None, help="parallel clips (default: cores)")
    p.add_argument("--engine", choices=("pool", "ray"), default="pool", help="where clips run")
    p.add_argument("--address", default=None, help="Ray cluster address (default: start one)")
    p.add_argument("--force", action="store_true", help="redo clips whose outputs are current")
    p.add_argument("--no-audit", action="store_true", help="skip the all-pairs collision audit")
    p.add_argument(
        "--physics",
        action="store_true",
        help="replay each clip in MuJoCo (physics extra): <clip>.physics.json/.png, physics/* "
        "summary columns",
    )
    add_quiet(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the batch, print and write the summary; 1 if a clip failed."""
    from ..dataset.batch import format_table, make_jobs, run_batch, write_summary
    from ..dataset.exports import parse_formats
    from ..errors import ConfigError

    formats = parse_formats(args.format)
    if args.physics:  # a missing mujoco is said once, before any clip
        from ..physics.model import import_mujoco

        import_mujoco()
    if args.workers is not None and args.workers < 1:
        raise ConfigError(f"--workers must be at least 1, got {args.workers}.")
    if os.path.exists(args.output) and not os.path.isdir(args.output):
        raise ConfigError(f"output folder {args.output!r} is a file; give a folder with -o.")
    try:
        os.makedirs(args.output, exist_ok=True)
    except OSError as exc:
        raise ConfigError(
            f"cannot create the output folder {args.output!r}: {exc.strerror}."
        ) from None
    if not os.access(args.output, os.W_OK):
        raise ConfigError(f"the output folder {args.output!r} is not writable.")
    jobs = make_jobs(
        args.config, args.inputs, args.output, formats=formats, fps=args.fps,
        force=args.force, audit=not args.no_audit, physics=args.physics,
    )  # fmt: skip
    results = run_batch(
        jobs, engine=args.engine, workers=args.workers, address=args.address,
        progress=not args.quiet and sys.stderr.isatty(),
    )  # fmt: skip
    print(format_table(results))
    csv_path, json_path = write_summary(results, args.output)
    failed = [r for r in results if r.status == "failed"]
    done = sum(r.status == "ok" for r in results)
    skipped = sum(r.status == "skipped" for r in results)
    print(f"{done} retargeted, {skipped} skipped (current), {len(failed)} failed; "
          f"summary: {csv_path} and {json_path}")  # fmt: skip
    return 1 if failed else 0
