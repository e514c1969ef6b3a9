# SPDX-License-Identifier: Apache-2.0
"""What the sensor sees: template points in view, occlusions, the person's silhouette.

The angular-cell z-buffers of the point-cloud fit (:mod:`.em`): :func:`visible_from` (the
template's own occlusions, ``em.occlusion_cell``), :func:`behind_cloud` (occlusions the
frame's cloud confirms, ``em.occlusion_confirm``) and :class:`Silhouette` (template points
outside the person's outline and their pulls, ``em.silhouette_weight``). docs/point_clouds.md,
*The fit per frame*.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

#: A template point is outside the person's silhouette when the sensor saw past it by more
#: than this [m] (or saw nothing) around its ray (``em.silhouette_weight``).
SILHOUETTE_DEPTH = 0.15
#: Cloud points searched for the nearest one at or in front of such a point's depth.
SILHOUETTE_NEIGHBOURS = 16


def _angular_cells(
    points: np.ndarray, eye: np.ndarray, cell: float
) -> tuple[np.ndarray, np.ndarray]:
    r"""Distance from ``eye`` (n,) and angular cell index (n,) of each point.

    Directions are binned in cells of ``cell`` metres at the points' median distance (azimuth
    scaled by the cosine of the median elevation, so cells are about square). Azimuths are
    taken within half a turn of the points' mean direction (whole turns added or taken away):
    ``arctan2``'s seam at :math:`\pm\pi` would otherwise split the cell column it runs
    through, and points on its two sides would not hide one another (a person seen across the
    world's -x axis). The cells' edges stay where they are, so nothing else moves.
    """
    d = points - eye
    r = np.linalg.norm(d, axis=1)
    r_med = float(np.median(r))
    ang = cell / max(r_med, 1e-6)
    az = np.arctan2(d[:, 1], d[:, 0])
    mean = d.sum(axis=0)
    if np.hypot(mean[0], mean[1]) > 0.0:
        ref = float(np.arctan2(mean[1], mean[0]))
        turn = 2.0 * np.pi
        az = np.where(az < ref - np.pi, az + turn, np.where(az >= ref + np.pi, az - turn, az))
    el = np.arcsin(np.clip(d[:, 2] / np.maximum(r, 1e-12), -1.0, 1.0))
    cu = np.floor(az * np.cos(np.median(el)) / ang).astype(np.int64)
    cv = np.floor(el / ang).astype(np.int64)
    key = (cu - cu.min()) * (cv.max() - cv.min() + 1) + (cv - cv.min())
    _, inv = np.unique(key, return_inverse=True)
    return r, inv


def visible_from(
    points: np.ndarray, eye: np.ndarray, cell: float, depth_tolerance: float | None = None
) -> np.ndarray:
    """Points not hidden behind others as seen from ``eye``: a point z-buffer on angular cells.

    Directions are binned in cells of ``cell`` metres at the points' median distance; in each
    cell, points deeper than the nearest one by more than ``depth_tolerance`` (default
    ``2 cell``) are hidden.
    """
    r, inv = _angular_cells(points, eye, cell)
    front = np.full(int(inv.max()) + 1, np.inf)
    np.minimum.at(front, inv, r)
    tol = 2.0 * cell if depth_tolerance is None else depth_tolerance
    return r <= front[inv] + tol


def behind_cloud(
    points: np.ndarray,
    cloud: np.ndarray,
    eye: np.ndarray,
    cell: float,
    depth_tolerance: float | None = None,
) -> np.ndarray:
    r"""Points the ``cloud`` shows a surface in front of, as seen from ``eye``.

    Points and cloud are binned together in the angular cells of :func:`visible_from`; a point
    is behind the cloud when a cloud point of its cell is nearer to ``eye`` by more than
    ``depth_tolerance`` (default ``2 cell``): :math:`r_m > \min_{n \in c(m)} r_n + \tau`.
    A point whose cell holds no cloud point (the sensor saw past it) is not behind.
    """
    m = len(points)
    r, inv = _angular_cells(np.vstack([points, cloud]), eye, cell)
    front = np.full(int(inv.max()) + 1, np.inf)
    np.minimum.at(front, inv[m:], r[m:])
    tol = 2.0 * cell if depth_tolerance is None else depth_tolerance
    return r[:m] > front[inv[:m]] + tol


@dataclass
class SilhouettePulls:
    r"""Pulls on the template points outside the person's silhouette (:class:`Silhouette`).

    :math:`\lambda_s \sum_{m \in O} \|v_m - t_m\|^2` over the points O outside (indices
    ``idx`` into the posed points) towards their targets ``targets`` (|O|, 3), in the units
    of the M-step's bracket (:meth:`EStep.bracket`: a pulled point weighs as ``weight`` cloud
    points all assigned to it).
    """

    idx: np.ndarray
    targets: np.ndarray
    weight: float

    def bracket(self, v: np.ndarray) -> float:
        r""":math:`\lambda_s \sum_{m \in O} \|v_m - t_m\|^2` at the posed points ``v``."""
        if not len(self.idx):
            return 0.0
        d = v[self.idx] - self.targets
        return float(self.weight * np.einsum("ma,ma->", d, d))

    def add_to(self, P1: np.ndarray, E: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        r"""``P1`` and ``E`` of :meth:`Template.normal_equations` with the pulls added.

        :math:`P_m \mathrel{+}= \lambda_s`, :math:`e_m \mathrel{+}= \lambda_s (t_m - v_m)`.
        """
        if not len(self.idx):
            return P1, E
        P1, E = P1.copy(), E.copy()
        P1[self.idx] += self.weight
        E[self.idx] += self.weight * (self.targets - v[self.idx])
        return P1, E


class Silhouette:
    r"""The person's silhouette as the sensor saw it in one frame's cloud.

    Wang 2017's mixture (eq. 1) has the template points as its centres: a centre no cloud point
    is near costs nothing, so a template part that sticks out of the person's outline (a trunk
    turned wider than the person's, an arm put where the sensor saw past) is not pulled back.
    Depth trackers add a free-space term for that (Ganapathi et al., ECCV 2012; Schmidt et
    al., DART, RSS 2014); this is its outline half. A template point that takes part is
    *outside* when no cloud point of its angular cell or the 8 around it lies nearer than
    :math:`r_m + d_s` (``SILHOUETTE_DEPTH``, 15 cm) from the sensor: there the sensor saw
    nothing, or saw well past the point. It is pulled across the image, at its own distance
    :math:`r_m`, onto the ray of the nearest cloud point (in the image) that lies at or in
    front of its depth (:math:`r_n \le r_m + 2\,\mathrm{cell}`; among the
    ``SILHOUETTE_NEIGHBOURS`` nearest, else the nearest):
    :math:`t_m = e + r_m (s_n - e) / \|s_n - e\|`.

    The other half, pushing a point that lies in front of a surface the sensor saw just behind
    it back onto that surface, was measured and is left out (docs/point_clouds.md, *Eleventh
    round*). Cells are ``cell`` metres at the cloud's median distance from ``eye`` (as
    :func:`visible_from`, azimuths taken about the cloud's mean direction); template points
    below ``floor`` (where the crop cut the floor, and the person's soles with it) are not
    pulled.
    """

    def __init__(self, cloud: np.ndarray, eye: np.ndarray, cell: float, floor: float) -> None:
        self.eye = np.asarray(eye, float)
        self.cell = float(cell)
        self.floor = float(floor)
        self.cloud = np.asarray(cloud, float)
        d = self.cloud - self.eye
        r = np.linalg.norm(d, axis=1)
        self.r_med = float(np.median(r))
        mean = d.mean(axis=0)
        self.az0 = math.atan2(float(mean[1]), float(mean[0]))  # azimuths about it (no seam)
        el = np.arcsin(np.clip(d[:, 2] / np.maximum(r, 1e-12), -1.0, 1.0))
        self.cos_el = math.cos(float(np.median(el)))
        uv = self.image(d, r)
        ij = np.floor(uv / self.cell).astype(np.int64)
        self.lo = ij.min(axis=0) - 1
        shape = tuple(int(x) for x in ij.max(axis=0) - self.lo + 2)
        front = np.full(shape, np.inf)
        np.minimum.at(front, (ij[:, 0] - self.lo[0], ij[:, 1] - self.lo[1]), r)
        # The nearest surface over each cell and the 8 around it.
        pad = np.pad(front, 1, constant_values=np.inf)
        near = pad[1:-1, 1:-1].copy()
        for a in (0, 1, 2):
            for b in (0, 1, 2):
                np.minimum(near, pad[a : a + shape[0], b : b + shape[1]], out=near)
        self.front = near
        self._uv = uv
        self._r = r
        self._tree: Any = None

    def image(self, d: np.ndarray, r: np.ndarray) -> np.ndarray:
        """(n, 2) image coordinates [m at the median distance] of directions ``d`` (n, 3)."""
        az = _wrap(np.arctan2(d[:, 1], d[:, 0]) - self.az0)
        el = np.arcsin(np.clip(d[:, 2] / np.maximum(r, 1e-12), -1.0, 1.0))
        return np.stack([az * self.cos_el * self.r_med, el * self.r_med], axis=1)

    def outside(self, v: np.ndarray) -> np.ndarray:
        """(n,) whether each point of ``v`` (n, 3) is outside the silhouette (floor excepted)."""
        d = v - self.eye
        r = np.linalg.norm(d, axis=1)
        ij = np.floor(self.image(d, r) / self.cell).astype(np.int64) - self.lo
        inside = np.all((ij >= 0) & (ij < np.array(self.front.shape)), axis=1)
        front = np.full(len(r), np.inf)
        front[inside] = self.front[ij[inside, 0], ij[inside, 1]]
        return (front > r + SILHOUETTE_DEPTH) & (v[:, 2] > self.floor)

    def pulls(self, v: np.ndarray, points: np.ndarray, weight: float) -> SilhouettePulls:
        """The pulls on the template ``points`` (indices into ``v``, the (M, 3) posed points)."""
        idx = points[self.outside(v[points])]
        if not len(idx):
            return SilhouettePulls(idx, np.empty((0, 3)), weight)
        if self._tree is None:
            from scipy.spatial import cKDTree

            self._tree = cKDTree(self._uv)
        d = v[idx] - self.eye
        r = np.linalg.norm(d, axis=1)
        k = min(SILHOUETTE_NEIGHBOURS, len(self._uv))
        _, j = self._tree.query(self.image(d, r), k=k)
        j = j.reshape(len(idx), k)
        ok = self._r[j] <= (r + 2.0 * self.cell)[:, None]
        first = np.where(ok.any(axis=1), ok.argmax(axis=1), 0)
        ray = self.cloud[j[np.arange(len(idx)), first]] - self.eye
        ray /= np.linalg.norm(ray, axis=1)[:, None]
        return SilhouettePulls(idx, self.eye + ray * r[:, None], weight)


def _wrap(x: np.ndarray) -> np.ndarray:
    """Angles [rad] moved by whole turns into [-pi, pi]."""
    return x - 2.0 * math.pi * np.round(x / (2.0 * math.pi))


__all__ = [
    "SILHOUETTE_DEPTH",
    "SILHOUETTE_NEIGHBOURS",
    "Silhouette",
    "SilhouettePulls",
    "behind_cloud",
    "visible_from",
]
