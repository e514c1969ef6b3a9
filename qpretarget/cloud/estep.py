# SPDX-License-Identifier: Apache-2.0
r"""E-step of the EM point-cloud fit (:mod:`.em`): posteriors, the NLL and their sums.

The mixture is the one of :mod:`.em` (Wang 2017, HUMROB, eq. 1-3): the template points
:math:`v_m` (M of them) as centroids, the cloud points :math:`s_n` (N of them), a uniform outlier
term of weight :math:`\mu`.

**E-step** (eq. 4, 20): posteriors
:math:`p_{mn} = e^{-\|s_n - v_m\|^2 / 2\sigma^2} / (\sum_i e^{-\|s_n - v_i\|^2/2\sigma^2} + c)`
with :math:`c = (2\pi\sigma^2)^{3/2} \frac{\mu}{1-\mu} \frac{M}{N}`. (Eq. 4 as printed has
:math:`(1-\mu)/\mu`; the value consistent with eq. 1 and 3, and with Myronenko and Song's CPD that
the paper follows, is :math:`\mu/(1-\mu)`, used here.) ``estep: kdtree`` keeps, for each cloud
point, its ``neighbors`` nearest template points (:func:`.neighbours.knn`) and drops the other
terms of the sum, which are below :math:`e^{-d^2/2\sigma^2}` for a distance d beyond the k-th
neighbour; the truncated likelihood is the one reported and made monotone (:mod:`.em`,
*Monotonicity*).

With normals (the refinement, eq. 21) the same posteriors are taken in 6-D
(:func:`search_coordinates`). The M-step needs only the posteriors' sums (:class:`EStep`);
:class:`_Neighbours` reuses an EM loop's kd-tree pairs until they are stale.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from ..errors import ConfigError
from .compiled import cloud_kernel, threads
from .config import CloudConfig
from .neighbours import knn
from .template import PosedTemplate
from .visibility import SilhouettePulls

LOG_2PI = math.log(2.0 * math.pi)


@dataclass
class EStep:
    r"""Result of an E-step: the NLL at the current parameters and the posterior statistics.

    Attributes:
        nll: negative log-likelihood (eq. 3; eq. 21's 6-D mixture when normals are used).
        P1: (M,) :math:`\sum_n p_{mn}` per template point (0 for inactive points).
        Px: (M, 3) :math:`\sum_n p_{mn} s_n`.
        Pn: (M, 3) :math:`\sum_n p_{mn} s^\perp_n` (normal stage) or None.
        wS2: :math:`\sum_{n,m} p_{mn} \|s_n\|^2`; wN2: the same for normals.
        Np: :math:`N_P = \sum_{n,m} p_{mn}`.
        dim: 3 (positions) or 6 (positions and normals).
        normal_weight: :math:`\lambda_\perp` of the normal stage (0 otherwise).
        silhouette: the pulls of the points outside the silhouette in a refinement iteration
            (``em.silhouette_weight``): in :meth:`bracket`, so in Q and the acceptance rule,
            but not in the :math:`\sigma^2` update.
    """

    nll: float
    P1: np.ndarray
    Px: np.ndarray
    Pn: np.ndarray | None
    wS2: float
    wN2: float
    Np: float
    dim: int
    normal_weight: float
    normal_scale: float = 1.0
    pairs: np.ndarray | None = None
    silhouette: SilhouettePulls | None = None

    def bracket(self, posed: PosedTemplate, *, silhouette: bool = True) -> float:
        r"""Weighted squared residuals at the template ``posed`` (sufficient statistics).

        :math:`\sum_{n,m} p_{mn} (\|s_n - v_m\|^2 + \lambda_\perp \|s^\perp_n - v^\perp_m\|^2)`.
        """
        v = posed.points
        out = (
            self.wS2
            - 2.0 * np.einsum("ma,ma->", v, self.Px)
            + np.einsum("m,ma,ma->", self.P1, v, v)
        )
        if self.Pn is not None:
            n = self.normal_scale * posed.normals
            out += self.normal_weight * (
                self.wN2
                - 2.0 * np.einsum("ma,ma->", n, self.Pn)
                + np.einsum("m,ma,ma->", self.P1, n, n)
            )
        if silhouette and self.silhouette is not None:
            out += self.silhouette.bracket(v)
        return float(out)

    def q_value(self, posed: PosedTemplate, sigma2: float) -> float:
        """Complete-data objective (eq. 5 / 13 + 15) with these posteriors, up to a constant."""
        return self.bracket(posed) / (2.0 * sigma2) + 0.5 * self.dim * self.Np * math.log(sigma2)

    def sigma2_update(self, posed: PosedTemplate) -> float:
        r"""Minimiser of :meth:`q_value` over :math:`\sigma^2` at ``posed``."""
        return self.bracket(posed, silhouette=False) / (self.dim * max(self.Np, 1e-300))


def e_step(
    S: np.ndarray,
    V: np.ndarray,
    active: np.ndarray,
    sigma2: float,
    mu: float,
    *,
    mode: str = "kdtree",
    neighbors: int = 12,
    Sn: np.ndarray | None = None,
    Vn: np.ndarray | None = None,
    normal_weight: float = 0.0,
    normal_scale: float = 1.0,
    pairs: np.ndarray | None = None,
    chunk: int = 512,
) -> EStep:
    r"""E-step of Wang 2017 eq. 4/20 (or eq. 21 with normals) and the NLL of eq. 3.

    Args:
        S: (N, 3) cloud points.
        V: (M, 3) posed template points.
        active: (M,) booleans, template points taking part (the others get no mass).
        sigma2: variance [m^2].
        mu: outlier weight in [0, 1).
        mode: ``dense`` (all pairs) or ``kdtree`` (``neighbors`` nearest template points).
        neighbors: template points per cloud point in ``kdtree`` mode.
        Sn: (N, 3) unit normals of the cloud for the 6-D normal stage.
        Vn: (M, 3) unit normals of the template for the 6-D normal stage.
        normal_weight: :math:`\lambda_\perp` (> 0 with normals).
        normal_scale: length :math:`\ell` [m] the unit normals are multiplied by.
        pairs: (N, k) template indices to use instead of a new neighbour search (``kdtree``
            mode); the result's ``pairs`` are the ones used. Any fixed set gives an upper bound
            of the truncated NLL, so reusing pairs between searches keeps EM monotone.
        chunk: cloud points per block of the dense E-step.
    """
    idx_act = np.flatnonzero(active)
    M = len(idx_act)
    N = len(S)
    Mtot = len(V)
    use_n = Sn is not None and Vn is not None and normal_weight > 0
    if M == 0 or N == 0:
        raise ValueError("empty template or cloud")
    B, Afull = search_coordinates(S, V, Sn, Vn, normal_weight, normal_scale)
    # Scaled normals (zeros when the normal stage is off, so the arrays are always arrays).
    Sn = _scaled_normals(Sn, normal_scale) if use_n else np.zeros((N, 3))
    if use_n:
        dim = 6
        lognorm = -3.0 * (LOG_2PI + math.log(sigma2)) + 1.5 * math.log(normal_weight)
    else:
        dim = 3
        lognorm = -1.5 * (LOG_2PI + math.log(sigma2))
    A = Afull[idx_act]
    log_in = math.log1p(-mu) - math.log(M) + lognorm
    log_out = math.log(mu / N) if mu > 0 else -np.inf
    if mode == "dense":
        sums = _dense_sums(S, Sn, B, A, idx_act, Mtot, sigma2, (log_in, log_out), use_n, chunk)
    elif mode == "kdtree":
        sums, pairs = _kdtree_sums(
            S, Sn, B, A, Afull, idx_act, Mtot, sigma2, (log_in, log_out), use_n, neighbors, pairs
        )
    else:
        raise ConfigError(f"estep must be 'kdtree' or 'dense', got {mode!r}.", path="em.estep")
    return EStep(*sums, dim, normal_weight if use_n else 0.0, normal_scale, pairs)


def search_coordinates(
    S: np.ndarray,
    V: np.ndarray,
    Sn: np.ndarray | None,
    Vn: np.ndarray | None,
    normal_weight: float,
    normal_scale: float,
) -> tuple[np.ndarray, np.ndarray]:
    r"""The spaces the E-step's distances are taken in: cloud (N, d) and template (M, d).

    Positions (d = 3), or with normals (``normal_weight`` :math:`\lambda_\perp` > 0) the 6-D
    :math:`(s, \sqrt{\lambda_\perp}\, \ell\, s^\perp)` of eq. 21, :math:`\ell` =
    ``normal_scale``: the squared distance is then the exponent of eq. 21 times
    :math:`2\sigma^2`.
    """
    if Sn is None or Vn is None or not normal_weight > 0:
        return S, V
    sq = math.sqrt(normal_weight)
    return (
        np.hstack([S, sq * (normal_scale * np.asarray(Sn, float))]),
        np.hstack([V, sq * (normal_scale * np.asarray(Vn, float))]),
    )


#: What an E-step sums over the posteriors: nll, P1, Px, Pn, wS2, wN2, Np (see :class:`EStep`).
_Sums = tuple[float, np.ndarray, np.ndarray, np.ndarray | None, float, float, float]


def _log_posteriors(
    a: np.ndarray, log_in: float, log_out: float, axis: int = 1
) -> tuple[np.ndarray, np.ndarray]:
    r"""Per cloud point :math:`\log p(s_n)` (n,) and posteriors (n, k), or (k, n) with axis 0.

    From the exponents :math:`a_{nk} = -d_{nk}^2 / 2\sigma^2`, by log-sum-exp (no underflow).
    The k-d tree E-step passes its few neighbours per point as rows (``axis=0``): numpy
    reduces along contiguous rows 10-30 times faster than across many short ones.
    """
    amax = a.max(axis=axis)
    amx = amax[:, None] if axis == 1 else amax
    post = np.exp(a - amx)
    lse = amax + np.log(post.sum(axis=axis))
    logp = np.logaddexp(log_in + lse, log_out)
    scale = np.exp(log_in + amax - logp)
    post *= scale[:, None] if axis == 1 else scale  # one exp of the (n, k) block
    return logp, post


def _dense_sums(
    S: np.ndarray,
    Sn: np.ndarray,
    B: np.ndarray,
    A: np.ndarray,
    idx_act: np.ndarray,
    Mtot: int,
    sigma2: float,
    log_in_out: tuple[float, float],
    use_n: bool,
    chunk: int,
) -> _Sums:
    """E-step over all (cloud point, active template point) pairs, ``chunk`` cloud points a time."""
    N, M = len(B), len(A)
    P1: np.ndarray = np.zeros(Mtot)
    Px: np.ndarray = np.zeros((Mtot, 3))
    Pn: np.ndarray = np.zeros((Mtot, 3))
    nll = 0.0
    wS2 = wN2 = Np = 0.0
    s2 = np.einsum("na,na->n", S, S)
    n2 = np.einsum("na,na->n", Sn, Sn)
    for lo in range(0, N, chunk):
        Bc = B[lo : lo + chunk]
        # Squared distances coordinate by coordinate (no BLAS product, exact, >= 0).
        D = np.zeros((len(Bc), M))
        for c in range(A.shape[1]):
            diff = Bc[:, c, None] - A[None, :, c]
            D += diff * diff
        logp, post = _log_posteriors(D * (-0.5 / sigma2), *log_in_out)
        nll -= float(logp.sum())
        w = post.sum(axis=1)
        P1[idx_act] += post.sum(axis=0)
        Px[idx_act] += np.einsum("nm,na->ma", post, S[lo : lo + chunk])
        wS2 += float(w @ s2[lo : lo + chunk])
        if use_n:
            Pn[idx_act] += np.einsum("nm,na->ma", post, Sn[lo : lo + chunk])
            wN2 += float(w @ n2[lo : lo + chunk])
        Np += float(w.sum())
    return nll, P1, Px, Pn if use_n else None, wS2, wN2, Np


def _kdtree_sums(
    S: np.ndarray,
    Sn: np.ndarray,
    B: np.ndarray,
    A: np.ndarray,
    Afull: np.ndarray,
    idx_act: np.ndarray,
    Mtot: int,
    sigma2: float,
    log_in_out: tuple[float, float],
    use_n: bool,
    neighbors: int,
    pairs: np.ndarray | None,
) -> tuple[_Sums, np.ndarray]:
    """E-step over each cloud point's ``neighbors`` nearest active template points or ``pairs``.

    With the compiled point-cloud kernel (:mod:`.compiled`) the posteriors and the sums run in
    C++ in this code's order of operations: the same results to the bit.
    """
    ck = cloud_kernel()
    if ck is not None:
        if pairs is None:
            d2c, nb = knn(A, B, min(neighbors, len(A)))
            pairs = idx_act[nb]
        else:
            d2c = np.zeros((0, pairs.shape[1]))
            pairs = np.ascontiguousarray(pairs, dtype=np.int64)
        cols, s2, n2 = _cloud_terms(S, Sn if use_n else None)
        logp, w, R = ck.estep(
            np.ascontiguousarray(B, dtype=float),
            np.ascontiguousarray(Afull, dtype=float),
            pairs,
            d2c,
            sigma2,
            *log_in_out,
            cols,
            Mtot,
            threads(),
        )
        return _sums_from(logp, w, R, s2, n2, use_n), pairs
    # (k, N) layout below: the reductions over each point's k pairs run along rows.
    d2: np.ndarray | None = None
    if pairs is None:
        dist2, nb = knn(A, B, min(neighbors, len(A)))
        pairs = idx_act[nb]
        d2 = np.ascontiguousarray(dist2.T)
    if d2 is None:
        # Coordinate by coordinate on contiguous rows (a (N, k, 3) gather is slow).
        pairs_t = np.ascontiguousarray(pairs.T)
        d2 = np.zeros(pairs_t.shape)
        diff = np.empty(pairs_t.shape)
        AT, BT = np.ascontiguousarray(Afull.T), np.ascontiguousarray(B.T)
        for c in range(B.shape[1]):
            np.take(AT[c], pairs_t, out=diff)
            np.subtract(BT[c], diff, out=diff)
            diff *= diff
            d2 += diff
    d2 *= -0.5 / sigma2
    logp, post_t = _log_posteriors(d2, *log_in_out, axis=0)
    w = post_t.sum(axis=0)
    post = np.ascontiguousarray(post_t.T)
    # P1, Px (and Pn) in one sparse product: P^T [1 S Sn] with P the (N, Mtot) posteriors.
    P = _posterior_matrix(pairs, post, Mtot)
    cols, s2, n2 = _cloud_terms(S, Sn if use_n else None)
    R = np.asarray(P.T @ cols)
    return _sums_from(logp, w, R, s2, n2, use_n), pairs


def _sums_from(
    logp: np.ndarray,
    w: np.ndarray,
    R: np.ndarray,
    s2: np.ndarray,
    n2: np.ndarray | None,
    use_n: bool,
) -> _Sums:
    """The E-step's sums (:data:`_Sums`) from its per-point and per-template-point parts.

    ``logp``: log p(s_n) (N,); ``w``: each cloud point's posterior mass (N,); ``R``:
    P^T [1 S Sn] (Mtot, 4 or 7).
    """
    nll = -float(logp.sum())
    P1, Px = R[:, 0], R[:, 1:4]
    Pn = R[:, 4:7] if use_n else None
    wN2 = float(w @ n2) if n2 is not None else 0.0
    return nll, P1, Px, Pn, float(w @ s2), wN2, float(w.sum())


_CLOUD_TERMS: list[Any] = []
_POSTERIOR_MATRIX: list[Any] = []


def _posterior_matrix(pairs: np.ndarray, post: np.ndarray, Mtot: int) -> Any:
    """(N, Mtot) CSR matrix of the posteriors ``post`` (N, k) at columns ``pairs`` (N, k).

    Kept pairs come back from one E-step to the next: the matrix's structure is then reused
    and only its values replaced (scipy's constructor checks cost 50-70 us; comparing the
    pairs with a copy of the last ones, 15 us, also catches pairs changed in place).
    """
    from scipy.sparse import csr_matrix

    c = _POSTERIOR_MATRIX
    if c and c[1] == Mtot and c[0].shape == pairs.shape and np.array_equal(c[0], pairs):
        P = c[2]
        P.data[:] = post.reshape(-1)
        return P
    N, k = pairs.shape
    P = csr_matrix((post.reshape(-1), pairs.reshape(-1), np.arange(0, N * k + 1, k)), (N, Mtot))
    c[:] = [pairs.copy(), Mtot, P]
    return P


_SCALED_NORMALS: list[Any] = []


def _scaled_normals(Sn: Any, scale: float) -> np.ndarray:
    """``scale * Sn``, the same array while the same normals (compared by value) come back."""
    c = _SCALED_NORMALS
    if not (c and c[1] == scale and _same_array(c[0], Sn)):
        c[:] = [np.array(Sn, float), scale, scale * np.asarray(Sn, float)]
    out: np.ndarray = c[2]
    return out


def _cloud_terms(
    S: np.ndarray, Sn: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Columns ``[1 S Sn]`` and squared norms of a cloud, kept while the same arrays come back.

    A frame's E-steps share its cloud (and its scaled normals, :class:`_Neighbours`).
    """
    c = _CLOUD_TERMS
    if c and _same_array(c[0], S) and _same_array(c[1], Sn):
        return c[2], c[3], c[4]
    cols = np.hstack([np.ones((len(S), 1)), S] + ([Sn] if Sn is not None else []))
    s2 = np.einsum("na,na->n", S, S)
    n2 = np.einsum("na,na->n", Sn, Sn) if Sn is not None else None
    c[:] = [S.copy(), None if Sn is None else Sn.copy(), cols, s2, n2]
    return cols, s2, n2


def _same_array(kept: np.ndarray | None, a: Any) -> bool:
    """Whether ``a`` equals the ``kept`` copy (shape and values; both None counts)."""
    if kept is None or a is None:
        return kept is None and a is None
    a = np.asarray(a)
    return bool(kept.shape == a.shape and np.array_equal(kept, a))


def _max_abs_rows(D: np.ndarray) -> np.ndarray:
    """Largest absolute entry of each row of a (n, d) array, column by column (fast)."""
    out = np.abs(D[:, 0])
    for c in range(1, D.shape[1]):
        np.maximum(out, np.abs(D[:, c]), out=out)
    return out


class _Fit(Protocol):
    """What :class:`_Neighbours` uses of the fitter, :class:`.em.CloudRetargeter`.

    A protocol rather than the class itself: this module stays below :mod:`.em`, which imports
    it (no import cycle, even for typing).
    """

    config: CloudConfig

    def _e_step(
        self, S: np.ndarray, posed: PosedTemplate, active: np.ndarray, sigma2: float, **extra: Any
    ) -> EStep: ...


class _Neighbours:
    """The E-steps of one EM loop, reusing the kd-tree pairs until they are stale.

    Pairs are searched again once an active template point has moved more than
    ``em.neighbor_refresh`` sigma (in any coordinate) from where they were searched.
    """

    def __init__(self, fit: _Fit) -> None:
        self.fit = fit
        self.pairs: np.ndarray | None = None
        self.ref: np.ndarray | None = None  # (K, d) active points where last searched
        self.searches = 0  # neighbour searches (for the benchmark)

    def e_step(
        self, S: np.ndarray, posed: PosedTemplate, active: np.ndarray, sigma2: float, **extra: Any
    ) -> EStep:
        """:meth:`CloudRetargeter._e_step` with the kept pairs."""
        fit = self.fit
        em = fit.config.em
        if em.estep != "kdtree":
            return fit._e_step(S, posed, active, sigma2, **extra)
        A = posed.points[active]
        pairs = self.pairs
        if (
            pairs is None
            or self.ref is None
            or self.ref.shape != A.shape
            or float(_max_abs_rows(A - self.ref).max()) > em.neighbor_refresh * math.sqrt(sigma2)
        ):
            pairs = None
        est = fit._e_step(S, posed, active, sigma2, pairs=pairs, **extra)
        if pairs is None:
            self.ref = A
            self.searches += 1
        self.pairs = est.pairs
        return est


__all__ = ["EStep", "e_step", "search_coordinates"]
