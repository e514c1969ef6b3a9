# SPDX-License-Identifier: Apache-2.0
"""Exceptions of qpretarget: one base class and one subclass per failure a user handles differently.

Every exception also derives from the builtin it refines (``ValueError``, ``RuntimeError``), so
``except ValueError`` keeps working. Messages name the problem and the fix.
"""

from __future__ import annotations

import difflib
from collections.abc import Sequence
from pathlib import Path


def close_matches_hint(name: str, known: Sequence[str], n: int = 3) -> str:
    """Return ``" Did you mean 'a', 'b'?"`` for the names of ``known`` close to ``name`` (or "")."""
    close = difflib.get_close_matches(name, list(known), n=n, cutoff=0.5)
    if not close:
        lowered = name.lower()
        close = [k for k in known if lowered in k.lower() or k.lower() in lowered][:n]
    return f" Did you mean {', '.join(map(repr, close))}?" if close else ""


class QPRetargetError(Exception):
    """Base class of every error raised by qpretarget."""


class ConfigError(QPRetargetError, ValueError):
    """A controller description (YAML or dict) is invalid.

    Attributes:
        path: YAML path of the problem, e.g. ``tasks[2].frame``.
    """

    def __init__(self, message: str, *, path: str = "") -> None:
        self.path = path
        self.bare_message = message
        super().__init__(f"{path}: {message}" if path else message)


class UnknownNameError(ConfigError):
    """A frame, joint, robot, task type or solver name is not known; lists the closest names."""

    def __init__(
        self, kind: str, name: str, known: Sequence[str], *, path: str = "", fix: str = ""
    ) -> None:
        self.kind, self.name = kind, name
        self.close_matches = difflib.get_close_matches(name, list(known), n=3, cutoff=0.5)
        hint = close_matches_hint(name, known)
        msg = f"{kind} {name!r} is not known.{hint}"
        if fix:
            msg += f" {fix}"
        elif len(known) <= 12:
            msg += f" Known: {', '.join(sorted(known))}."
        super().__init__(msg, path=path)


class UnknownFrameError(UnknownNameError):
    """A frame name is not in the robot model."""

    def __init__(self, frame: str, known: Sequence[str], *, path: str = "") -> None:
        super().__init__(
            "frame",
            frame,
            known,
            path=path,
            fix="List the frames with `qpretarget info CONFIG --frames`.",
        )
        self.frame = frame


class UnknownJointError(UnknownNameError):
    """A joint name is not in the robot model."""

    def __init__(self, joint: str, known: Sequence[str], *, path: str = "") -> None:
        super().__init__(
            "joint",
            joint,
            known,
            path=path,
            fix="List the joints with `qpretarget info CONFIG`.",
        )
        self.joint = joint


class TargetError(QPRetargetError, ValueError):
    """A target given to :meth:`Controller.step` is malformed (shape, type, NaN) or names no task.

    Attributes:
        task: task name.
        tick: controller tick at which it happened (``None`` outside the loop).
    """

    def __init__(self, message: str, *, task: str | None = None, tick: int | None = None):
        self.task, self.tick = task, tick
        where = []
        if task is not None:
            where.append(f"task {task!r}")
        if tick is not None:
            where.append(f"tick {tick}")
        prefix = (", ".join(where) + ": ") if where else ""
        super().__init__(prefix + message)


class SolverError(QPRetargetError, RuntimeError):
    """A QP solver is unknown, not installed, or failed in a way the controller cannot absorb."""


class SolverNotInstalledError(SolverError, ImportError):
    """A QP solver backend is known to qpretarget but its package is not installed."""


class MissingDependencyError(QPRetargetError, ImportError):
    """An optional dependency (a ``pip`` extra of qpretarget) is not installed.

    Attributes:
        extra: the extra that installs it, e.g. ``"plot"``.
    """

    def __init__(self, message: str, *, extra: str = "") -> None:
        super().__init__(message)
        self.extra = extra


def source_checkout() -> Path | None:
    """The checkout qpretarget runs from (editable or in-place install), or ``None``.

    A source checkout is recognised by a ``pyproject.toml`` beside the package directory; an
    install from a wheel (site-packages) has none.
    """
    root = Path(__file__).resolve().parent.parent
    return root if (root / "pyproject.toml").is_file() else None


def install_hint(extra: str, what: str) -> str:
    """One sentence telling how to install the optional ``extra`` needed for ``what``.

    Args:
        extra: name of the extra in ``pyproject.toml`` (``plot``, ``viz``, ``mocap``, ...).
        what: what needs it, e.g. ``"drawing figures"`` (the sentence starts with it).

    Returns:
        ``'{what} needs the `{extra}` extra: pip install -e "/path/to/checkout[extra]"'`` when
        qpretarget runs from a source checkout (the package is on no index), else
        ``'... pip install "qpretarget[extra]"'``.
    """
    root = source_checkout()
    target = f"{root}[{extra}]" if root is not None else f"qpretarget[{extra}]"
    cmd = f'pip install -e "{target}"' if root is not None else f'pip install "{target}"'
    return f"{what} needs the `{extra}` extra: {cmd}"


def missing_dependency(extra: str, what: str) -> MissingDependencyError:
    """A :class:`MissingDependencyError` whose message is :func:`install_hint` (raise it)."""
    return MissingDependencyError(install_hint(extra, what), extra=extra)
