# SPDX-License-Identifier: Apache-2.0
"""The compiled point-cloud kernel ``qpretarget._cloud`` (built from ``src/kernel/cloud.cpp``).

It runs the point-cloud fit's inner loops in C++: the exact k-nearest-neighbour searches
(:func:`.neighbours.knn`), the k-d tree E-step's posteriors and weighted sums
(:func:`.estep.e_step`) and the cloud normals' scatter matrices (:func:`.io.estimate_normals`), in
the numpy code's order of operations, so that the fit is the same to the bit with or without it
(``tests/cloud/test_compiled.py``). Optional: without it (no C++ compiler at install, or
``QPRETARGET_CLOUD_KERNEL=0``) the numpy code runs.

``QPRETARGET_CLOUD_THREADS`` (default 1) sets the threads of the
k-nearest-neighbour searches and of the E-step's posteriors (each cloud point's are
independent, and the sums over them are taken in one order: the same results with any number
of threads). A helper thread that gets no core (a loaded machine) is not waited for: its
share is done by the fit's own thread.
A frame's cloud normals are computed on a second thread while the fit's first stages run
(:func:`overlap`; ``QPRETARGET_CLOUD_OVERLAP=0`` turns that off).
"""

from __future__ import annotations

import contextlib
import importlib
import os
from collections.abc import Iterator
from types import ModuleType

_MODULE: ModuleType | None = None
_WHY_NOT = ""
_OFF = 0  # nesting depth of python_only()
#: The interface version this Python code expects of the compiled module.
ABI = 1


def _off(variable: str) -> bool:
    return os.environ.get(variable, "1").strip().lower() in ("0", "false", "no", "off")


def _load() -> tuple[ModuleType | None, str]:
    if _off("QPRETARGET_CLOUD_KERNEL"):
        return None, "turned off by QPRETARGET_CLOUD_KERNEL=0"
    try:
        mod = importlib.import_module("qpretarget._cloud")
    except ImportError as exc:
        return None, (
            f"the compiled point-cloud kernel is not installed ({exc}); reinstall with a C++ "
            "compiler (pip install -e . prints what is missing)"
        )
    if getattr(mod, "ABI", None) != ABI:
        return None, "the compiled point-cloud kernel is out of date: reinstall qpretarget"
    return mod, ""


def cloud_kernel() -> ModuleType | None:
    """The compiled point-cloud module, or ``None`` (then :func:`why_not` says why)."""
    global _MODULE, _WHY_NOT
    if _OFF:
        return None
    if _MODULE is None and not _WHY_NOT:
        _MODULE, _WHY_NOT = _load()
    return _MODULE


def why_not() -> str:
    """Why the compiled point-cloud kernel is not in use ('' when it is)."""
    if _OFF:
        return "turned off by qpretarget.cloud.compiled.python_only()"
    cloud_kernel()
    return _WHY_NOT


def threads() -> int:
    """Threads of the compiled searches and E-steps (``QPRETARGET_CLOUD_THREADS``, default 1).

    On the 2-core AMD EPYC VM 2 threads saved about 1 ms a frame idle and cost 2-3 ms while
    another job held the other core (docs/point_clouds.md), hence 1.
    """
    default = 1
    try:
        return max(1, int(os.environ.get("QPRETARGET_CLOUD_THREADS", str(default))))
    except ValueError:
        return default


def overlap() -> bool:
    """Whether a frame's cloud normals are computed while its first stages run.

    On a second thread (:func:`.io.normals_in_background`; needs the compiled kernel; the same
    normals). On by default; ``QPRETARGET_CLOUD_OVERLAP=0`` turns it off.
    """
    if _off("QPRETARGET_CLOUD_OVERLAP"):
        return False
    return cloud_kernel() is not None


def describe() -> str:
    """One line for bench reports: is the compiled point-cloud kernel in use, or why not."""
    if cloud_kernel() is None:
        return f"off ({why_not()})"
    n = threads()
    overlapped = "yes" if overlap() else "no"
    return f"on ({n} thread{'s' if n > 1 else ''}, normals overlapped: {overlapped})"


@contextlib.contextmanager
def python_only() -> Iterator[None]:
    """Within this block the point-cloud fit runs its numpy code (for comparisons)."""
    global _OFF
    _OFF += 1
    try:
        yield
    finally:
        _OFF -= 1


__all__ = ["cloud_kernel", "describe", "overlap", "python_only", "threads", "why_not"]
