# SPDX-License-Identifier: Apache-2.0
"""The compiled kernel ``qpretarget._kernel`` (built from ``src/kernel`` at install): loading it.

The kernel runs a velocity-level tick's per-module computations in C++
(:mod:`qpretarget.control.compiled`) and calls DAQP's C entry point for the direct DAQP backend
(:mod:`qpretarget.solvers.daqp_`). It is optional: without it (no C++ compiler at install, a
pinocchio other than the one it was built against, or ``QPRETARGET_KERNEL=0``) every module runs
its Python code, with the same results.
"""

from __future__ import annotations

import contextlib
import importlib
import os
from collections.abc import Iterator
from types import ModuleType

_KERNEL: ModuleType | None = None
_WHY_NOT = ""


def _load() -> tuple[ModuleType | None, str]:
    """Import the compiled kernel if it was built and matches the running pinocchio."""
    if os.environ.get("QPRETARGET_KERNEL", "1").strip().lower() in ("0", "false", "no", "off"):
        return None, "turned off by QPRETARGET_KERNEL=0"
    try:
        import pinocchio as pin

        # The extension module built from src/kernel (absent without a C++ compiler).
        _kernel = importlib.import_module(f"{__package__}._kernel")
    except ImportError as exc:
        return None, (
            f"the compiled kernel is not installed ({exc}); reinstall with a C++ compiler "
            "(pip install -e . prints what is missing)"
        )
    running = getattr(pin, "__version__", "")
    if running != _kernel.PINOCCHIO_VERSION:
        return None, (
            f"the kernel was built against pinocchio {_kernel.PINOCCHIO_VERSION}, this is "
            f"{running}: reinstall qpretarget (pip install --no-build-isolation -e .)"
        )
    return _kernel, ""


_DAQP_OK: bool | None = None  # DAQP's C entry points loaded and checked (None: not tried)
_OFF = 0  # nesting depth of ``python_only()``


def kernel() -> ModuleType | None:
    """The compiled kernel module, or ``None`` (then :func:`why_not` says why)."""
    global _KERNEL, _WHY_NOT
    if _OFF:
        return None
    if _KERNEL is None and not _WHY_NOT:
        _KERNEL, _WHY_NOT = _load()
    return _KERNEL


def why_not() -> str:
    """Why the kernel is not in use ('' when it is)."""
    if _OFF:
        return "turned off by qpretarget.kernel.python_only()"
    kernel()
    return _WHY_NOT


@contextlib.contextmanager
def python_only() -> Iterator[None]:
    """Within this block, controllers built and DAQP solves run their Python code.

    For comparisons of the two paths (the golden runs were recorded in Python). A controller
    built inside the block keeps running in Python after it.
    """
    global _OFF
    _OFF += 1
    try:
        yield
    finally:
        _OFF -= 1


#: DAQP's settings defaults as its C library documents them (include/constants.h): the layout
#: check of the compiled DAQP call (a DAQP whose settings struct differs is not called from C).
_DAQP_DEFAULTS = (1e-6, 1e-12, 1e-11, 1e-8, 1e-14, 10.0, 10000.0, 1e30)


def daqp_kernel() -> ModuleType | None:
    """The kernel with DAQP's C entry points loaded, or ``None`` (Python's daqp is used)."""
    k = kernel()
    if k is None:
        return None
    global _DAQP_OK
    if _DAQP_OK is None:
        ok = False
        try:
            import daqp

            ok = bool(k.daqp_load(daqp.__file__))
            ok = ok and tuple(k.daqp_defaults()[: len(_DAQP_DEFAULTS)]) == _DAQP_DEFAULTS
        except (ImportError, AttributeError, RuntimeError):
            ok = False
        _DAQP_OK = ok
    return k if _DAQP_OK else None


def describe() -> str:
    """One line for ``--version``/bench reports: is the kernel in use, or why not."""
    k = kernel()
    if k is None:
        return f"compiled kernel: off ({why_not()})"
    daqp = "DAQP from C" if daqp_kernel() is not None else "DAQP through Python"
    return f"compiled kernel: on (pinocchio {k.PINOCCHIO_VERSION}, {daqp})"


__all__ = ["daqp_kernel", "describe", "kernel", "python_only", "why_not"]
