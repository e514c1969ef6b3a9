# SPDX-License-Identifier: Apache-2.0
"""Atomic file writing (qpretarget/fileio.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from qpretarget.fileio import _umask, atomic_path, write_atomic


def test_atomic_files_get_the_usual_mode(tmp_path: Path) -> None:
    """Files written atomically are readable like any other (mkstemp alone leaves 0600)."""
    out = write_atomic(tmp_path / "x.json", lambda f: f.write("{}"), binary=False)
    assert out.read_text() == "{}"
    assert (out.stat().st_mode & 0o777) == (0o666 & ~_umask())


def test_a_failed_write_leaves_neither_the_file_nor_a_temporary(tmp_path: Path) -> None:
    target = tmp_path / "y.bin"
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        tmp.write_bytes(b"partial")
        raise RuntimeError("writer failed")
    assert not target.exists() and list(tmp_path.iterdir()) == []
