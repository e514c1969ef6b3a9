# SPDX-License-Identifier: Apache-2.0
"""The fit's k-nearest-neighbour search equals a brute-force search, with every backend."""

from __future__ import annotations

import numpy as np
import pytest

import qpretarget.cloud.neighbours as nn
from qpretarget.cloud.compiled import cloud_kernel, python_only


@pytest.mark.parametrize("backend", ["scipy", "pykdtree", "compiled"])
@pytest.mark.parametrize(("dim", "k"), [(3, 8), (6, 8), (3, 1)])
def test_knn_is_exact(monkeypatch: pytest.MonkeyPatch, backend: str, dim: int, k: int) -> None:
    if backend == "pykdtree":
        pytest.importorskip("pykdtree")
    if backend == "compiled" and cloud_kernel() is None:
        pytest.skip("compiled point-cloud kernel not built")
    rng = np.random.default_rng(3)
    data = rng.normal(size=(700, dim))
    query = rng.normal(size=(300, dim))
    if backend == "compiled":
        d2, idx = nn.knn(data, query, k)
    else:
        monkeypatch.setattr(nn, "BACKEND", backend)
        with python_only():
            d2, idx = nn.knn(data, query, k)
    full = ((query[:, None, :] - data[None, :, :]) ** 2).sum(axis=2)
    expected = np.sort(full, axis=1)[:, :k]
    assert idx.shape == (300, k) and idx.dtype == np.intp
    # Same neighbours: random data have no ties; distances to round-off (1e-12 relative).
    np.testing.assert_array_equal(idx, np.argsort(full, axis=1)[:, :k])
    np.testing.assert_allclose(d2, expected, rtol=1e-12, atol=1e-14)


def test_knn_rejects_too_many_neighbours() -> None:
    with pytest.raises(ValueError, match="neighbours asked of 5 points"):
        nn.knn(np.zeros((5, 3)), np.zeros((2, 3)), 6)
