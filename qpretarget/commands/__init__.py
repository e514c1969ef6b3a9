# SPDX-License-Identifier: Apache-2.0
"""Subcommands of the ``qpretarget`` command, one module each.

Each module in this package defines ``register(subparsers) -> None`` that adds its parser with
``set_defaults(func=run)``, where ``run(args) -> int`` is the exit code. :func:`discover` imports
every module here, so adding a subcommand never touches ``cli.py``. A module whose optional
dependencies are missing should still register and say what to install when run.
"""

from __future__ import annotations

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
