# SPDX-License-Identifier: Apache-2.0
"""Output files: paths checked before any work, and written atomically.

:func:`check_output_file` refuses, in one sentence, an output that is a folder, lies under a
file or cannot be written, before a run spends minutes computing it. :func:`atomic_path` and
:func:`write_atomic` write through a temporary file beside the target, renamed over it when
complete: an interrupted command never leaves a half-written file under a final name (either the
old file, or none, or the complete new one is there).
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, Any

from .errors import ConfigError


def _umask() -> int:
    """The process's umask, read without changing it (``os.umask`` would, for every thread)."""
    with contextlib.suppress(OSError, ValueError), open("/proc/self/status") as f:
        for line in f:
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    return 0o022


@contextlib.contextmanager
def atomic_path(path: str | Path, suffix: str = "") -> Iterator[Path]:
    """Yield a temporary path in ``path``'s folder; rename it to ``path`` on success.

    Args:
        path: the final file.
        suffix: suffix of the temporary file (some writers pick the format from it).

    Raises:
        OSError: the folder cannot be written (the temporary file is removed).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix or ".part", dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        # mkstemp makes the file private (0600); give it the mode a plain open() would have.
        with contextlib.suppress(OSError):
            os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def write_atomic(path: str | Path, writer: Callable[[IO[Any]], object], *, binary: bool) -> Path:
    """Open a temporary file, let ``writer`` fill it, rename it to ``path``; return ``path``.

    ``writer``'s return value (e.g. ``f.write``'s count) is ignored.
    """
    path = Path(path)
    with (
        atomic_path(path) as tmp,
        open(tmp, "wb" if binary else "w", encoding=None if binary else "utf-8") as f,
    ):  # noqa: E501
        writer(f)
    return path


class OutputPathError(ConfigError):
    """An output path that cannot be written: a folder, under a file, or not writable."""


def check_output_file(path: str | Path, suffix: str) -> Path:
    """Validate an output file path before any work is done; return it with ``suffix``.

    Args:
        path: the file the user asked for (``-o``).
        suffix: the expected suffix (``.npz``); a path without one gets it.

    Raises:
        OutputPathError: ``path`` is a folder, lies under a file, or its folder is not
            writable — one sentence naming the problem and the fix.
    """
    p = Path(path)
    if p.is_dir():
        example = str(p / ("run" + suffix))
        raise OutputPathError(f"output {str(p)!r} is a folder; give a file such as {example!r}.")
    if p.suffix != suffix:
        p = p.with_suffix(suffix) if not p.suffix else p.with_name(p.name + suffix)
    parent = p.parent
    for anc in (parent, *parent.parents):
        if anc.exists():
            if not anc.is_dir():
                raise OutputPathError(
                    f"cannot write {str(p)!r}: {str(anc)!r} is a file, not a folder."
                )
            if not os.access(anc, os.W_OK | os.X_OK):
                raise OutputPathError(f"cannot write {str(p)!r}: {str(anc)!r} is not writable.")
            break
    return p


def load_npz(path: str | Path, error: type[Exception]) -> Any:
    """``numpy.load`` of an ``.npz`` file without pickles; ``error`` names the file if unreadable.

    Returns:
        The open ``NpzFile`` (a context manager).
    """
    import numpy as np

    try:
        return np.load(path, allow_pickle=False)
    except Exception as exc:  # noqa: BLE001 - any failure to read is the same user error
        raise error(f"{path}: not a readable .npz file ({exc}).") from None
