# SPDX-License-Identifier: Apache-2.0
"""Subcommands of the ``qpretarget`` command, one module each.

Each module in this package defines ``register(subparsers) -> None`` that adds its parser with
``set_defaults(func=run)``, where ``run(args) -> int`` is the exit code. :func:`discover` imports
every module here, so adding a subcommand never touches ``cli.py``. A module whose optional
dependencies are missing should still register and say what to install when run.

:func:`add_command` adds a subcommand's parser (help line, description, examples) and the
``add_*`` helpers the arguments several commands share, with one wording each.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
from types import ModuleType


def discover() -> list[ModuleType]:
    """Import every subcommand module of this package, sorted by name."""
    mods = []
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        mods.append(importlib.import_module(f"{__name__}.{info.name}"))
    return mods


#: ``config`` of the commands that retarget a motion.
RETARGET_CONFIG_HELP = "controller YAML with a `retarget:` section"
#: ``motion`` of the commands that read a mocap file.
MOTION_HELP = "motion file: .bvh, .amc (with its .asf), .c3d"


def add_command(
    sub: argparse._SubParsersAction, name: str, *, help: str, description: str, examples: str
) -> argparse.ArgumentParser:
    """Add subcommand ``name``: one-line ``help``, ``description``, and ``examples`` as epilog.

    The epilog keeps its line breaks (the examples are laid out by hand).
    """
    return sub.add_parser(
        name,
        help=help,
        description=description,
        epilog=examples,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )


def add_config(p: argparse.ArgumentParser, help: str = RETARGET_CONFIG_HELP) -> None:
    """The positional ``config`` (controller YAML)."""
    p.add_argument("config", help=help)


def add_motion(p: argparse.ArgumentParser) -> None:
    """The positional ``motion`` (a mocap file)."""
    p.add_argument("motion", help=MOTION_HELP)


def add_output(p: argparse.ArgumentParser, help: str) -> None:
    """The required ``-o/--output``."""
    p.add_argument("-o", "--output", required=True, help=help)


def add_clip_range(p: argparse.ArgumentParser) -> None:
    """``--start`` / ``--end``: the part of the clip to use [s]."""
    p.add_argument("--start", type=float, default=None, help="first time of the clip [s]")
    p.add_argument("--end", type=float, default=None, help="end time of the clip [s] (excluded)")


def add_control_rate(p: argparse.ArgumentParser) -> None:
    """``--rate``: the control rate [Hz]."""
    p.add_argument("--rate", type=float, default=None, help="control rate [Hz] (default 1/dt)")


def add_quiet(p: argparse.ArgumentParser, help: str = "no progress bar") -> None:
    """``--quiet``: less output on stderr."""
    p.add_argument("--quiet", action="store_true", help=help)
