# SPDX-License-Identifier: Apache-2.0
"""Registry of live sources: ``--source NAME[:ARG]`` -> a :class:`~qpretarget.sources.base.Source`.

A source module registers its class with ``@SOURCES.register("name")`` (the registry of
:mod:`qpretarget.registry`) and is listed in :data:`SOURCE_MODULES`; adding a source is one file
and one line here.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from typing import Any

from ..errors import ConfigError
from ..registry import Registry
from .base import Source

#: Registered live sources, by ``--source`` name.
SOURCES = Registry("source")

#: Modules that register a source (imported on first use).
SOURCE_MODULES = ("qpretarget.sources.xsens", "qpretarget.sources.file")


def load_sources() -> Registry:
    """Import every source module and return :data:`SOURCES`."""
    for mod in SOURCE_MODULES:
        importlib.import_module(mod)
    return SOURCES


def open_source(spec: str, options: Mapping[str, Any] | None = None) -> Source:
    """Build the source named by ``spec`` (``xsens``, ``xsens:9763``, ``file:clip.bvh``).

    Args:
        spec: ``NAME`` or ``NAME:ARG``.
        options: Options passed to the source (``host``, ``capture_rate``, ``units``...).

    Raises:
        ConfigError: Unknown source name (with the known ones) or a bad argument.
    """
    if not isinstance(spec, str) or not spec:
        raise ConfigError("--source needs a source such as `xsens` or `xsens:9763`.")
    name, _, arg = spec.partition(":")
    cls = load_sources().lookup(name, path="--source")
    if not issubclass(cls, Source):
        raise ConfigError(f"{name!r} is not a live source.", path="--source")
    return cls.from_spec(arg, dict(options or {}))
