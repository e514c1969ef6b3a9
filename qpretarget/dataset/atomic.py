# SPDX-License-Identifier: Apache-2.0
"""Atomic file writes: a temporary file beside the target, renamed over it when complete.

An interrupted batch therefore never leaves a half-written file under a final name: either the
old file (or none) or the complete new one is there.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, Any


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
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix or ".part", dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def write_atomic(path: str | Path, writer: Callable[[IO[Any]], None], *, binary: bool) -> Path:
    """Open a temporary file, let ``writer`` fill it, rename it to ``path``; return ``path``."""
    path = Path(path)
    with (
        atomic_path(path) as tmp,
        open(tmp, "wb" if binary else "w", encoding=None if binary else "utf-8") as f,
    ):  # noqa: E501
        writer(f)
    return path
