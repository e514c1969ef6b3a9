# SPDX-License-Identifier: Apache-2.0
"""Small validators turning user values into checked floats and arrays with clear messages."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from .errors import ConfigError, close_matches_hint


def positive_float(value: Any, name: str, *, allow_zero: bool = False) -> float:
    """Return ``value`` as a float > 0 (or >= 0), else raise :class:`ConfigError`."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise ConfigError(f"{name} must be a number, got {value!r}.")
    v = float(value)
    if not np.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ConfigError(f"{name} must be a finite number {bound}, got {value!r}.")
    return v


def weight_vector(value: npt.ArrayLike, dim: int, name: str) -> np.ndarray:
    """Return a (dim,) non-negative weight vector from a scalar or a sequence."""
    is_bool = isinstance(value, (bool, np.bool_)) or (
        isinstance(value, (list, tuple)) and any(isinstance(x, (bool, np.bool_)) for x in value)
    )
    arr = np.asarray(value, dtype=float) if not isinstance(value, str) and not is_bool else None
    if arr is None or arr.ndim > 1 or (arr.ndim == 1 and arr.shape[0] != dim):
        raise ConfigError(f"{name} must be a number or a list of {dim} numbers, got {value!r}.")
    if np.any(~np.isfinite(arr)) or np.any(arr < 0):
        raise ConfigError(f"{name} must be finite and >= 0, got {value!r}.")
    return np.broadcast_to(arr, (dim,)).astype(float).copy()


def check_keys(
    spec: Any, allowed: Any, path: str, *, what: str = "key", listed: str = "Allowed"
) -> None:
    """Refuse a YAML mapping key not in ``allowed``: one message with close names and the path.

    Raises:
        ConfigError: ``unknown {what} 'k'. Did you mean ...? {listed}: a, b.`` at ``path.k``.
    """
    names = [str(a) for a in allowed]
    for key in spec:
        if key not in allowed:
            raise ConfigError(
                f"unknown {what} {key!r}.{close_matches_hint(str(key), names)} "
                f"{listed}: {', '.join(names)}.",
                path=f"{path}.{key}",
            )


def check_bool(value: Any, name: str) -> bool:
    """Return ``value`` if it is a YAML boolean, else raise :class:`ConfigError` naming ``name``."""
    if not isinstance(value, bool):
        raise ConfigError(f"{name} must be true or false, got {value!r}.")
    return value
