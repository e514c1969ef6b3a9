# SPDX-License-Identifier: Apache-2.0
"""Planar geometry shared by the support polygon, the metrics and the support phases."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt


def convex_hull_2d(points: npt.ArrayLike) -> np.ndarray:
    """Counter-clockwise convex hull of 2-D points (Andrew's monotone chain), ``(h, 2)``.

    Orientation tests use points rounded to 1e-9 m and collinear points are dropped, so noise on
    coincident sole corners (corners 1e-12 m apart) never drops a true corner or makes a
    degenerate edge. Fewer than 3 distinct points are returned as they are.
    """
    original: dict[tuple[float, float], np.ndarray] = {}
    for p in np.asarray(points, float).reshape(-1, 2):
        original.setdefault((round(float(p[0]), 9), round(float(p[1]), 9)), p)
    pts = sorted(original)  # decisions on the rounded points, the input points are returned
    if len(pts) <= 2:
        return np.array([original[k] for k in pts], dtype=float).reshape(-1, 2)

    def half(seq: list[tuple[float, float]]) -> list[tuple[float, float]]:
        out: list[tuple[float, float]] = []
        for p in seq:
            while len(out) >= 2:
                (ax, ay), (bx, by) = out[-2], out[-1]
                if (bx - ax) * (p[1] - ay) - (by - ay) * (p[0] - ax) > 1e-12:
                    break
                out.pop()
            out.append(p)
        return out

    lower, upper = half(pts), half(pts[::-1])
    return np.array([original[k] for k in lower[:-1] + upper[:-1]], dtype=float)
