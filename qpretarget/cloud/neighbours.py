# SPDX-License-Identifier: Apache-2.0
"""Exact k-nearest-neighbour searches of the point-cloud fit (E-step pairs, cloud normals).

One function, :func:`knn`, used by every search of :mod:`qpretarget.cloud`. It uses the
compiled point-cloud kernel's kd-tree (:mod:`.compiled`, ``src/kernel/cloud.cpp``) when it is
built, else ``pykdtree`` (a kd-tree in C) when that package is installed, else scipy's
``cKDTree``; all are exact, so they return the same neighbours (up to ties between equal
distances), and the compiled one and pykdtree the same squared distances to the bit. On the
fit's searches (2,500 cloud points, k = 8-10 of about 2,000 template points, 3-D and 6-D)
pykdtree built and searched in about 0.7 of cKDTree's time, the compiled one in about 0.9 of
pykdtree's on one thread and 0.6 on two (``scripts/bench_cloud.py --stages``;
docs/point_clouds.md).
"""

from __future__ import annotations

import importlib
import os
from typing import Any

import numpy as np

from .compiled import cloud_kernel, threads

_PyKDTree: Any
try:  # optional: a faster exact kd-tree (imported by name: type-checks with or without it)
    _PyKDTree = importlib.import_module("pykdtree.kdtree").KDTree
except ImportError:  # pragma: no cover - depends on the environment
    _PyKDTree = None

_FORCED = os.environ.get("QPRETARGET_KNN", "").strip().lower()
#: Search backend without the compiled kernel: ``pykdtree`` when installed, else ``scipy``.
#: The environment variable ``QPRETARGET_KNN=scipy`` (or ``pykdtree``) forces that one, also
#: over the compiled kernel (for comparisons).
BACKEND = "pykdtree" if _PyKDTree is not None and _FORCED != "scipy" else "scipy"


def backend() -> str:
    """The search in use: ``compiled``, ``pykdtree`` or ``scipy``."""
    if _FORCED not in ("scipy", "pykdtree") and cloud_kernel() is not None:
        return "compiled"
    return BACKEND


def knn(data: np.ndarray, query: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    r"""The ``k`` nearest ``data`` points of every ``query`` point, exactly (Euclidean).

    Args:
        data: (M, d) points searched in.
        query: (N, d) points searched for, same d.
        k: neighbours per query point, 1 <= k <= M.

    Returns:
        ``(d2, idx)``: squared distances :math:`\|q_n - x_{idx_{nj}}\|^2` (N, k), ascending
        along each row, and the indices (N, k) into ``data`` (``np.intp``).
    """
    data = np.ascontiguousarray(data, dtype=float)
    query = np.ascontiguousarray(query, dtype=float)
    k = int(k)
    if not 1 <= k <= len(data):
        raise ValueError(f"k = {k} neighbours asked of {len(data)} points")
    ck = cloud_kernel() if _FORCED not in ("scipy", "pykdtree") else None
    if ck is not None:
        d2c, idxc = ck.knn(data, query, k, threads())
        return d2c, idxc
    if BACKEND == "pykdtree":
        d2, idx = _PyKDTree(data).query(query, k=k, sqr_dists=True)
        idx = idx.astype(np.intp, copy=False)
    else:
        from scipy.spatial import cKDTree

        # Sliding-midpoint splits (balanced_tree=False): 5-20 % faster here than median
        # splits, same neighbours.
        dist, idx = cKDTree(data, balanced_tree=False).query(query, k=k)
        d2 = dist * dist
    if k == 1:
        d2, idx = d2.reshape(-1, 1), idx.reshape(-1, 1)
    return np.asarray(d2, float), np.asarray(idx, np.intp)


__all__ = ["BACKEND", "backend", "knn"]
