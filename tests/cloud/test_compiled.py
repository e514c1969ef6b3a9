# SPDX-License-Identifier: Apache-2.0
"""The compiled point-cloud kernel (``qpretarget._cloud``) gives the numpy code's results.

Its searches, E-step sums and normals' scatter matrices follow the numpy code's order of
operations (src/kernel/cloud.cpp): the searches and the normals are compared for exact
equality; the E-step's sums to 1e-12 relative and a whole fit to 1e-9 (rad, m), because numpy's
own results move in the last bits with the memory alignment of its arrays (two numpy runs of
the same fit in one process differed by 2e-12 rad; the compiled runs are reproducible to the
bit). Without the module (no compiler at install) or with ``QPRETARGET_CLOUD_KERNEL=0`` the
numpy code runs.
"""

from __future__ import annotations

import importlib
import math

import numpy as np
import pytest

import qpretarget.cloud.compiled as compiled
import qpretarget.cloud.neighbours as nn
from qpretarget.cloud.em import CloudRetargeter, e_step
from qpretarget.cloud.io import estimate_normals, normals_in_background


@pytest.fixture()
def ck():
    mod = compiled.cloud_kernel()
    if mod is None:
        pytest.skip(f"compiled point-cloud kernel not built: {compiled.why_not()}")
    return mod


def _surface(rng: np.random.Generator, n: int, noise: float = 0.003) -> np.ndarray:
    """Points on a body-sized cylinder (a surface, like the fit's clouds and templates)."""
    a, z = rng.uniform(0, 2 * np.pi, n), rng.uniform(0.0, 1.7, n)
    r = 0.15 + 0.05 * np.sin(3 * z)
    return np.stack([r * np.cos(a), r * np.sin(a), z], 1) + rng.normal(scale=noise, size=(n, 3))


@pytest.mark.parametrize(("dim", "k"), [(3, 8), (6, 8), (3, 10), (3, 1)])
@pytest.mark.parametrize("threads", [1, 2])
def test_compiled_knn_equals_the_python_searches(ck, dim: int, k: int, threads: int) -> None:
    rng = np.random.default_rng(4)
    data, query = _surface(rng, 2000), _surface(rng, 2500)
    if dim == 6:
        data = np.hstack([data, 0.035 * rng.normal(size=(2000, 3))])
        query = np.hstack([query, 0.035 * rng.normal(size=(2500, 3))])
    query[:100] += rng.normal(scale=0.5, size=(100, dim))  # outliers far from the data
    d2, idx = ck.knn(data, query, k, threads)
    with compiled.python_only():
        e2, jdx = nn.knn(data, query, k)
    np.testing.assert_array_equal(idx, jdx)
    np.testing.assert_array_equal(d2, e2)  # the same squared distances to the bit
    assert idx.dtype == np.int64 and d2.shape == (2500, k)


@pytest.mark.parametrize("normals", [False, True])
@pytest.mark.parametrize("mu", [0.1, 0.0])
def test_compiled_e_step_equals_numpy(ck, normals: bool, mu: float) -> None:
    rng = np.random.default_rng(5)
    S, V = _surface(rng, 2500), _surface(rng, 3000)
    Sn = rng.normal(size=S.shape)
    Sn /= np.linalg.norm(Sn, axis=1, keepdims=True)
    Vn = rng.normal(size=V.shape)
    Vn /= np.linalg.norm(Vn, axis=1, keepdims=True)
    active = rng.uniform(size=len(V)) < 0.6
    kw = {"Sn": Sn, "Vn": Vn, "normal_weight": 0.5, "normal_scale": 0.05} if normals else {}
    fresh = e_step(S, V, active, 1.2e-4, mu, neighbors=8, **kw)
    with compiled.python_only():
        ref = e_step(S, V, active, 1.2e-4, mu, neighbors=8, **kw)
    # Kept pairs (the distances computed from the pairs, not by the search), template moved.
    V2 = V + rng.normal(scale=0.002, size=V.shape)
    kept = e_step(S, V2, active, 1.0e-4, mu, neighbors=8, pairs=fresh.pairs, **kw)
    with compiled.python_only():
        kept_ref = e_step(S, V2, active, 1.0e-4, mu, neighbors=8, pairs=ref.pairs, **kw)
    tol = {"rtol": 1e-12, "atol": 1e-15}
    for a, b in ((fresh, ref), (kept, kept_ref)):
        np.testing.assert_allclose([a.nll, a.Np, a.wS2, a.wN2], [b.nll, b.Np, b.wS2, b.wN2], **tol)
        np.testing.assert_array_equal(a.pairs, b.pairs)
        np.testing.assert_allclose(a.P1, b.P1, **tol)
        np.testing.assert_allclose(a.Px, b.Px, **tol)
        if normals:
            np.testing.assert_allclose(a.Pn, b.Pn, **tol)
        else:
            assert a.Pn is None and b.Pn is None
        assert math.isfinite(a.nll)


def test_compiled_e_step_does_not_depend_on_the_threads(ck) -> None:
    rng = np.random.default_rng(9)
    S, V = _surface(rng, 2500), _surface(rng, 2000)
    d2, nb = ck.knn(V, S, 8, 1)
    cols = np.hstack([np.ones((len(S), 1)), S])
    args = (1.1e-4, -7.2, -10.1, cols, len(V))
    one = ck.estep(S, V, nb, d2, *args, 1)
    # 2 and 3 threads; and the distances from the pairs (kept pairs) instead of the search's.
    for other in (
        ck.estep(S, V, nb, d2, *args, 2),
        ck.estep(S, V, nb, d2, *args, 3),
        ck.estep(S, V, nb, np.zeros((0, 8)), *args, 2),
    ):
        for a, b in zip(one, other, strict=True):
            np.testing.assert_array_equal(a, b)


def test_compiled_normals_equal_numpy(ck) -> None:
    pts = _surface(np.random.default_rng(6), 2500)
    eye = np.array([2.0, 0.3, 1.1])
    n = estimate_normals(pts, eye, 10)
    with compiled.python_only():
        m = estimate_normals(pts, eye, 10)
    np.testing.assert_array_equal(n, m)


def test_normals_in_the_background_equal_the_normals(ck) -> None:
    """The overlapped normals (their search and scatter on another thread) are the same."""
    pts = _surface(np.random.default_rng(8), 2500)
    eye = np.array([2.0, 0.3, 1.1])
    np.testing.assert_array_equal(
        normals_in_background(pts, eye, 10)(), estimate_normals(pts, eye, 10)
    )
    with compiled.python_only():  # no compiled kernel: computed at once, the numpy way
        np.testing.assert_array_equal(
            normals_in_background(pts, eye, 10)(), estimate_normals(pts, eye, 10)
        )


def test_a_fit_is_the_same_with_and_without_the_compiled_kernel(ck, g1, g1_template, g1_sequence):
    """Three frames of the G1 sequence (calibration off): the same poses (to 1e-9)."""
    cfg = {"robot": "g1", "stability": {"mode": "qp"}, "calibration": {"enabled": False}}
    seq = g1_sequence.sequence
    seq = type(seq)(frames=seq.frames[:3], sensor_position=seq.sensor_position)
    _, fast = CloudRetargeter(cfg, robot=g1, template=g1_template).run(seq)
    with compiled.python_only():
        _, slow = CloudRetargeter(cfg, robot=g1, template=g1_template).run(seq)
    for a, b in zip(fast, slow, strict=True):
        np.testing.assert_allclose(a.q_fit, b.q_fit, rtol=0, atol=1e-9)
        assert a.sigma2 == pytest.approx(b.sigma2, rel=1e-9) and a.iterations == b.iterations


def test_the_numpy_code_runs_without_the_module(monkeypatch: pytest.MonkeyPatch) -> None:
    """No compiled module (no compiler at install) or QPRETARGET_CLOUD_KERNEL=0: numpy."""
    real = importlib.import_module

    def no_cloud(name: str, *a, **k):
        if name == "qpretarget._cloud":
            raise ImportError("No module named 'qpretarget._cloud'")
        return real(name, *a, **k)

    monkeypatch.delenv("QPRETARGET_CLOUD_KERNEL", raising=False)
    monkeypatch.setattr(compiled, "_MODULE", None)
    monkeypatch.setattr(compiled, "_WHY_NOT", "")
    monkeypatch.setattr(importlib, "import_module", no_cloud)
    assert compiled.cloud_kernel() is None
    assert "not installed" in compiled.why_not()
    assert nn.backend() in ("pykdtree", "scipy")
    rng = np.random.default_rng(7)
    S, V = _surface(rng, 300), _surface(rng, 400)
    est = e_step(S, V, np.ones(len(V), bool), 1e-4, 0.1, neighbors=8)
    assert est.pairs is not None and est.pairs.shape == (300, 8) and math.isfinite(est.nll)
    monkeypatch.setattr(compiled, "_MODULE", None)
    monkeypatch.setattr(compiled, "_WHY_NOT", "")
    monkeypatch.setattr(importlib, "import_module", real)
    monkeypatch.setenv("QPRETARGET_CLOUD_KERNEL", "0")
    assert compiled.cloud_kernel() is None
    assert "QPRETARGET_CLOUD_KERNEL=0" in compiled.why_not()
