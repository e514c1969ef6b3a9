# SPDX-License-Identifier: Apache-2.0
r"""Point-cloud input: sequences from files and depth images, cropping, voxel subsampling, normals.

Every reader returns a :class:`CloudSequence` in the *world* frame: z up, floor at z = 0, metres.
A depth image is back-projected with pinhole intrinsics,
:math:`x = (u - c_x) z / f_x,\ y = (v - c_y) z / f_y`, and moved to the world by the camera pose
(camera-to-world, OpenCV axes: x right, y down, z forward).

Accepted inputs (``docs/point_clouds.md``):

* ``.npz`` with ``points`` (T, N, 3) padded with NaN rows, or ``points`` (sum N, 3) with
  ``counts`` (T,); optional ``normals`` in the same layout. Or ``depth`` (T, H, W) [m] with
  ``intrinsics`` ``[fx, fy, cx, cy]``, optional ``depth_scale`` [m per unit] and ``camera_pose``
  (4, 4). Optional ``t`` (T,) [s] or ``rate`` [Hz], ``sensor_position`` (3,).
* ``.npy``: one (N, 3) cloud or a (T, N, 3) stack (NaN rows are padding).
* ``.ply``: one cloud (ASCII or binary little-endian; ``x y z`` and optional ``nx ny nz``).
* a directory of ``.ply``, ``.npy`` or 16-bit ``.png`` depth images (sorted by name); PNG needs
  ``intrinsics`` (and usually ``camera_pose``, ``depth_scale``) from the config.

The paper fits 2,500 cloud points per frame (Wang 2017 V.B): :func:`prepare_cloud` crops to a box,
averages the points of each voxel and draws a fixed-size random subset.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, overload

import numpy as np

from ..errors import ConfigError, QPRetargetError, missing_dependency
from ..fileio import load_npz, write_atomic


class CloudFormatError(QPRetargetError, ValueError):
    """A point-cloud file is unreadable or misses what the reader needs."""


@dataclass(frozen=True)
class PinholeIntrinsics:
    """Pinhole camera intrinsics [px] and image size.

    Attributes:
        fx, fy: focal lengths [px]; cx, cy: principal point [px]; width, height: image size [px].
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    @classmethod
    def from_any(
        cls, spec: Any, shape: tuple[int, int] | None = None, *, path: str = "input.intrinsics"
    ) -> PinholeIntrinsics:
        """Build from ``[fx, fy, cx, cy]`` (+ image ``shape`` (H, W)), a mapping, or an instance."""
        if isinstance(spec, PinholeIntrinsics):
            return spec
        try:
            if isinstance(spec, dict):
                vals = [float(spec[k]) for k in ("fx", "fy", "cx", "cy")]
                w, h = spec.get("width"), spec.get("height")
            else:
                vals = [float(x) for x in np.asarray(spec, float).reshape(-1)[:4]]
                if len(vals) != 4:
                    raise ValueError
                w = h = None
        except (KeyError, TypeError, ValueError):
            raise ConfigError(
                "intrinsics must be [fx, fy, cx, cy] or {fx, fy, cx, cy, width, height} [px], "
                f"got {spec!r}.",
                path=path,
            ) from None
        if shape is not None:
            h, w = shape
        if w is None or h is None:
            raise ConfigError("intrinsics need the image width and height.", path=path)
        if vals[0] <= 0 or vals[1] <= 0:
            raise ConfigError(
                f"focal lengths must be positive, got fx={vals[0]}, fy={vals[1]}.", path=path
            )
        fx, fy, cx, cy = vals
        return cls(fx, fy, cx, cy, width=int(w), height=int(h))


@dataclass
class CloudFrame:
    """One sensor frame: world points (N, 3), optional unit normals (N, 3), time [s]."""

    points: np.ndarray
    normals: np.ndarray | None = None
    t: float = 0.0


@dataclass
class CloudSequence:
    """A sequence of world-frame clouds.

    Attributes:
        frames: the frames, in time order.
        sensor_position: optical centre in the world (3,) (orients estimated normals), or None.
        source: file or directory it came from.
        meta: free information (intrinsics, camera pose, ...).
    """

    frames: list[CloudFrame]
    sensor_position: np.ndarray | None = None
    source: str = ""
    meta: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.frames)

    def __iter__(self) -> Iterator[CloudFrame]:
        return iter(self.frames)

    @property
    def t(self) -> np.ndarray:
        """Frame times (T,) [s]."""
        return np.array([f.t for f in self.frames])

    def save(self, path: str | Path) -> Path:
        """Write the ragged ``.npz`` layout (``points``, ``counts``, ``t``, ...), atomically."""
        path = Path(path)
        arrays: dict[str, Any] = {
            "points": np.concatenate([f.points for f in self.frames])
            if self.frames
            else np.zeros((0, 3)),
            "counts": np.array([len(f.points) for f in self.frames], dtype=np.int64),
            "t": self.t,
        }
        if self.frames and all(f.normals is not None for f in self.frames):
            arrays["normals"] = np.concatenate([f.normals for f in self.frames])
        if self.sensor_position is not None:
            arrays["sensor_position"] = np.asarray(self.sensor_position, float)
        for k, v in self.meta.items():
            if isinstance(v, np.ndarray):
                arrays[f"meta/{k}"] = v
        from ..fileio import atomic_path

        with atomic_path(path, suffix=".npz") as tmp:  # no half-written file on failure
            np.savez_compressed(tmp, **arrays)
        return path


# ------------------------------------------------------------------------------ depth images
@overload
def depth_to_points(
    depth: np.ndarray,
    intrinsics: PinholeIntrinsics,
    camera_pose: np.ndarray | None = None,
    *,
    return_pixels: Literal[False] = False,
) -> np.ndarray: ...


@overload
def depth_to_points(
    depth: np.ndarray,
    intrinsics: PinholeIntrinsics,
    camera_pose: np.ndarray | None = None,
    *,
    return_pixels: Literal[True],
) -> tuple[np.ndarray, np.ndarray]: ...


def depth_to_points(
    depth: np.ndarray,
    intrinsics: PinholeIntrinsics,
    camera_pose: np.ndarray | None = None,
    *,
    return_pixels: bool = False,
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Back-project a depth image [m] to points (world frame if ``camera_pose`` is given).

    Pixels with a non-finite or non-positive depth are skipped.

    Args:
        depth: (H, W) depth along the optical axis [m].
        intrinsics: pinhole intrinsics.
        camera_pose: (4, 4) camera-to-world transform, or None for camera coordinates.
        return_pixels: also return the flat pixel index of each point.
    """
    depth = np.asarray(depth, float)
    H, W = depth.shape
    flat = depth.reshape(-1)
    pix = np.flatnonzero(np.isfinite(flat) & (flat > 0))
    v, u = np.divmod(pix, W)
    z = flat[pix]
    pts = np.stack(
        [(u - intrinsics.cx) * z / intrinsics.fx, (v - intrinsics.cy) * z / intrinsics.fy, z],
        axis=1,
    )
    if camera_pose is not None:
        T = np.asarray(camera_pose, float)
        pts = pts @ T[:3, :3].T + T[:3, 3]
    return (pts, pix) if return_pixels else pts


def depth_normals(
    depth: np.ndarray, intrinsics: PinholeIntrinsics, camera_pose: np.ndarray | None = None
) -> np.ndarray:
    """Unit normals (H, W, 3) from neighbouring pixels' points (cross product), facing the camera.

    Pixels without a valid neighbour get NaN.
    """
    H, W = depth.shape
    z = np.where(np.isfinite(depth) & (depth > 0), depth, np.nan)
    v, u = np.mgrid[0:H, 0:W]
    P = np.stack(
        [(u - intrinsics.cx) * z / intrinsics.fx, (v - intrinsics.cy) * z / intrinsics.fy, z], -1
    )
    du = np.full_like(P, np.nan)
    dv = np.full_like(P, np.nan)
    du[:, 1:-1] = P[:, 2:] - P[:, :-2]
    dv[1:-1] = P[2:] - P[:-2]
    n = np.cross(du, dv)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    flip = np.einsum("hwa,hwa->hw", n, P) > 0  # must face the camera (at the origin)
    n[flip] *= -1
    if camera_pose is not None:
        n = n @ np.asarray(camera_pose, float)[:3, :3].T
    return n


# ------------------------------------------------------------------------------ preprocessing
def crop(points: np.ndarray, box_min: Sequence[float], box_max: Sequence[float]) -> np.ndarray:
    """Boolean mask (N,) of the points inside the axis-aligned box ``[box_min, box_max]``."""
    lo, hi = np.asarray(box_min, float), np.asarray(box_max, float)
    out = np.ones(len(points), bool)
    for a in range(points.shape[1]):  # column by column: fast on many short rows
        c = points[:, a]
        out &= (c >= lo[a]) & (c <= hi[a])
    return out


def crop_hint(points: np.ndarray, box: Mapping[str, Sequence[float]] | None) -> str:
    """Where a frame's points are, when a crop box left too few of them: a sentence.

    Names the median of the finite points and a box of the crop's own size centred on it
    horizontally (its heights kept), to paste into ``input.crop``; empty when the frame has
    too few points anyway (then the crop is not the cause).
    """
    pts = np.asarray(points, float).reshape(-1, 3)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if len(pts) < 10 or not box:
        return ""
    lo, hi = np.asarray(box["min"], float), np.asarray(box["max"], float)
    med = np.median(pts, axis=0)
    half = 0.5 * (hi[:2] - lo[:2])
    new_lo = [round(float(med[0] - half[0]), 2), round(float(med[1] - half[1]), 2), float(lo[2])]
    new_hi = [round(float(med[0] + half[0]), 2), round(float(med[1] + half[1]), 2), float(hi[2])]
    return (
        f" The frame's {len(pts)} points have their median at "
        f"({med[0]:.2f}, {med[1]:.2f}, {med[2]:.2f}) m, and the crop keeps "
        f"{[float(x) for x in lo]} - {[float(x) for x in hi]}: if that is the person, centre "
        f"the box on them, e.g. crop: {{min: {new_lo}, max: {new_hi}}}."
    )


def voxel_downsample(
    points: np.ndarray, voxel: float, normals: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray | None]:
    """Average the points (and normals, re-normalised) in each cubic voxel of edge ``voxel``."""
    if voxel <= 0 or len(points) == 0:
        return points, normals
    key = np.floor(points / voxel).astype(np.int64)
    key -= key.min(axis=0)
    dims = key.max(axis=0) + 1
    lin = (key[:, 0] * dims[1] + key[:, 1]) * dims[2] + key[:, 2]
    _, inv, cnt = np.unique(lin, return_inverse=True, return_counts=True)
    out = (
        np.stack([np.bincount(inv, weights=points[:, a]) for a in range(3)], axis=1) / cnt[:, None]
    )
    nout = None
    if normals is not None:
        nout = np.stack([np.bincount(inv, weights=normals[:, a]) for a in range(3)], axis=1)
        nn = np.linalg.norm(nout, axis=1, keepdims=True)
        nout = np.divide(nout, nn, out=np.zeros_like(nout), where=nn > 1e-12)
    return out, nout


def estimate_normals(points: np.ndarray, viewpoint: np.ndarray | None, k: int = 10) -> np.ndarray:
    """Unit normals (N, 3) by PCA of each point's ``k`` nearest neighbours, facing ``viewpoint``.

    Without a viewpoint the normals face away from the cloud's centroid.
    """
    from .compiled import cloud_kernel
    from .neighbours import knn

    n = len(points)
    if n < 3:
        return np.tile([0.0, 0.0, 1.0], (n, 1))
    k = int(min(k, n))
    _, idx = knn(points, points, k)
    ck = cloud_kernel()
    if ck is not None:  # the same sums in C++, in the order of the numpy code below
        C = ck.scatter(np.ascontiguousarray(points, dtype=float), idx.astype(np.int64, copy=False))
        return _facing(smallest_eigenvectors(C), points, viewpoint)
    # Scatter matrices entry by entry on (k, n) coordinate arrays, reduced along contiguous
    # rows (a (n, k, 3) gather, batched 3x3 products and reductions over many short rows are
    # slow in numpy).
    idx_t = np.ascontiguousarray(idx.reshape(n, k).T)
    cs = [np.take(np.ascontiguousarray(points[:, a]), idx_t) for a in range(3)]
    cs = [c - c.mean(axis=0) for c in cs]
    C = np.empty((n, 3, 3))
    for a in range(3):
        for b in range(a, 3):
            C[:, a, b] = C[:, b, a] = (cs[a] * cs[b]).sum(axis=0)
    return _facing(smallest_eigenvectors(C), points, viewpoint)


def normals_in_background(
    points: np.ndarray, viewpoint: np.ndarray | None, k: int = 10
) -> Callable[[], np.ndarray]:
    """:func:`estimate_normals` started on another thread; call the result to get them.

    The search and the scatter matrices run in the compiled point-cloud kernel, which lets
    Python's other threads run meanwhile (the fit's first stage does not need the normals), so
    on a machine with a free core they cost the fit only the eigenvectors. The same normals to
    the bit; without the compiled kernel (or with fewer than 3 points) they are computed now.
    """
    from .compiled import cloud_kernel

    ck = cloud_kernel()
    n = len(points)
    if ck is None or n < 3:
        out = estimate_normals(points, viewpoint, k)
        return lambda: out
    k = int(min(k, n))
    pts = np.ascontiguousarray(points, dtype=float)
    box: list[Any] = []

    def work() -> None:
        try:
            _, idx = ck.knn(pts, pts, k, 1)  # .neighbours.knn's search, on this thread alone
            box.append(ck.scatter(pts, idx.astype(np.int64, copy=False)))
        except BaseException as exc:  # re-raised by the caller
            box.append(exc)

    th = threading.Thread(target=work, name="qpretarget-normals", daemon=True)
    th.start()

    def get() -> np.ndarray:
        th.join()
        C = box[0]
        if isinstance(C, BaseException):
            raise C
        return _facing(smallest_eigenvectors(C), pts, viewpoint)

    return get


def _facing(nrm: np.ndarray, points: np.ndarray, viewpoint: np.ndarray | None) -> np.ndarray:
    """The normals ``nrm`` turned towards ``viewpoint`` (or away from the centroid)."""
    ref = (viewpoint - points) if viewpoint is not None else (points - points.mean(axis=0))
    nrm[np.einsum("na,na->n", nrm, ref) < 0] *= -1
    return nrm


def smallest_eigenvectors(A: np.ndarray) -> np.ndarray:
    r"""Unit eigenvectors (N, 3) of the smallest eigenvalue of symmetric 3x3 matrices (N, 3, 3).

    Closed form, vectorised (a fifth of ``numpy.linalg.eigh``'s time on 2,500 matrices): with
    :math:`q = \operatorname{tr} A / 3`, :math:`p = \sqrt{\|A - qI\|_F^2 / 6}` and
    :math:`r = \det((A - qI)/p) / 2`, the smallest eigenvalue is
    :math:`\lambda = q + 2p\cos(\arccos(r)/3 + 2\pi/3)`; the eigenvector is the largest
    cross product of two rows of :math:`A - \lambda I` (they span its orthogonal complement).
    An isotropic matrix (every vector an eigenvector) gets :math:`e_z`.
    """
    A = np.asarray(A, float)
    # Component arrays (N,): numpy is slow on many tiny 3x3 blocks.
    a, b, c = A[:, 0, 0], A[:, 0, 1], A[:, 0, 2]
    d, e, f = A[:, 1, 1], A[:, 1, 2], A[:, 2, 2]
    q = (a + d + f) / 3.0
    a, d, f = a - q, d - q, f - q
    p = np.sqrt((a * a + d * d + f * f + 2.0 * (b * b + c * c + e * e)) / 6.0)
    ok = p > 1e-12 * np.maximum(np.abs(q), 1e-300)
    ps = np.where(ok, p, 1.0)
    det = a * (d * f - e * e) - b * (b * f - e * c) + c * (b * e - d * c)
    r = np.clip(det / (2.0 * ps**3), -1.0, 1.0)
    shift = 2.0 * ps * np.cos(np.arccos(r) / 3.0 + 2.0 * np.pi / 3.0)  # lambda - q
    a, d, f = a - shift, d - shift, f - shift
    # Rows (a b c), (b d e), (c e f) of A - lambda I; their cross products.
    c01 = np.stack([b * e - c * d, c * b - a * e, a * d - b * b], 1)
    c02 = np.stack([b * f - c * e, c * c - a * f, a * e - b * c], 1)
    c12 = np.stack([d * f - e * e, e * c - b * f, b * e - d * c], 1)
    cands = np.stack([c01, c02, c12], 1)
    norms = np.einsum("nca,nca->nc", cands, cands)
    best = norms.argmax(axis=1)
    rows = np.arange(len(A))
    v = cands[rows, best]
    nv = np.sqrt(norms[rows, best])
    good = ok & (nv > 0)
    out = np.tile([0.0, 0.0, 1.0], (len(A), 1))
    out[good] = v[good] / nv[good, None]
    return out


def prepare_cloud(
    points: np.ndarray,
    normals: np.ndarray | None = None,
    *,
    box_min: Sequence[float] | None = None,
    box_max: Sequence[float] | None = None,
    voxel: float = 0.0,
    max_points: int = 2500,
    rng: np.random.Generator | None = None,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Crop, voxel-average and randomly subsample a cloud to at most ``max_points`` points.

    NaN rows (padding) are dropped first.
    """
    points = np.asarray(points, float)
    ok = np.isfinite(points[:, 0]) & np.isfinite(points[:, 1]) & np.isfinite(points[:, 2])
    if box_min is not None and box_max is not None:
        ok &= crop(points, box_min, box_max)
    points = points[ok]
    normals = None if normals is None else np.asarray(normals, float)[ok]
    points, normals = voxel_downsample(points, voxel, normals)
    if max_points and len(points) > max_points:
        rng = rng if rng is not None else np.random.default_rng(0)
        sel = np.sort(rng.choice(len(points), size=max_points, replace=False))
        points = points[sel]
        normals = None if normals is None else normals[sel]
    return points, normals


# ------------------------------------------------------------------------------ readers
def read_ply(path: str | Path) -> tuple[np.ndarray, np.ndarray | None]:
    """Vertices (N, 3) and optional normals (N, 3) of a PLY file (ASCII or binary little-endian).

    Raises:
        CloudFormatError: not a PLY file, unsupported encoding, or no ``x y z`` properties.
    """
    path = Path(path)
    raw = path.read_bytes()
    if not raw.startswith(b"ply"):
        raise CloudFormatError(f"{path}: not a PLY file (no 'ply' magic line).")
    end = raw.find(b"end_header")
    if end < 0:
        raise CloudFormatError(f"{path}: PLY header has no end_header.")
    header = raw[:end].decode("ascii", errors="replace").splitlines()
    body = raw[raw.index(b"\n", end) + 1 :]
    fmt, n_vertex, props, in_vertex = "", 0, [], False
    types = {
        "char": "i1",
        "uchar": "u1",
        "short": "i2",
        "ushort": "u2",
        "int": "i4",
        "uint": "u4",
        "float": "f4",
        "double": "f8",
        "int8": "i1",
        "uint8": "u1",
        "int16": "i2",
        "uint16": "u2",
        "int32": "i4",
        "uint32": "u4",
        "float32": "f4",
        "float64": "f8",
    }
    for line in header:
        w = line.split()
        if not w:
            continue
        if w[0] == "format":
            fmt = w[1]
        elif w[0] == "element":
            in_vertex = w[1] == "vertex"
            if in_vertex:
                n_vertex = int(w[2])
        elif w[0] == "property" and in_vertex:
            if w[1] == "list":
                raise CloudFormatError(f"{path}: list properties on vertices are not supported.")
            props.append((w[2], types.get(w[1], "f4")))
    names = [p[0] for p in props]
    if not {"x", "y", "z"} <= set(names):
        raise CloudFormatError(f"{path}: the vertex element has no x, y, z properties.")
    if fmt == "ascii":
        rows = body.decode("ascii", errors="replace").split("\n")[:n_vertex]
        arr = np.array([[float(x) for x in r.split()[: len(names)]] for r in rows if r.strip()])
        col = {n: arr[:, i] for i, n in enumerate(names)}
    elif fmt == "binary_little_endian":
        dt = np.dtype([(n, "<" + t) for n, t in props])
        rec = np.frombuffer(body, dtype=dt, count=n_vertex)
        col = {n: rec[n].astype(float) for n in names}
    else:
        raise CloudFormatError(
            f"{path}: PLY format {fmt!r} is not supported (ascii, binary_little_endian)."
        )
    pts = np.stack([col["x"], col["y"], col["z"]], axis=1)
    nrm = (
        np.stack([col["nx"], col["ny"], col["nz"]], axis=1)
        if {"nx", "ny", "nz"} <= set(col)
        else None
    )
    return pts, nrm


def write_ply(path: str | Path, points: np.ndarray, normals: np.ndarray | None = None) -> Path:
    """Write a binary little-endian PLY file with ``x y z`` (and ``nx ny nz``)."""
    path = Path(path)
    cols = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if normals is not None:
        cols += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")]
    rec = np.empty(len(points), dtype=cols)
    for i, a in enumerate("xyz"):
        rec[a] = points[:, i]
        if normals is not None:
            rec["n" + a] = normals[:, i]
    head = "ply\nformat binary_little_endian 1.0\n" + f"element vertex {len(points)}\n"
    head += "".join(f"property float {c}\n" for c, _ in cols) + "end_header\n"
    data = head.encode("ascii") + rec.tobytes()
    return write_atomic(path, lambda f: f.write(data), binary=True)


def _frames_from_stack(
    points: np.ndarray, normals: np.ndarray | None, t: np.ndarray
) -> list[CloudFrame]:
    frames = []
    for i in range(len(points)):
        ok = np.all(np.isfinite(points[i]), axis=1)
        frames.append(
            CloudFrame(points[i][ok], None if normals is None else normals[i][ok], float(t[i]))
        )
    return frames


def _times(n: int, t: np.ndarray | None, rate: float | None, source: str) -> np.ndarray:
    if t is not None:
        t = np.asarray(t, float).reshape(-1)
        if len(t) != n:
            raise CloudFormatError(f"{source}: {len(t)} times for {n} frames.")
        return t - t[0] if n else t
    if n <= 1:
        return np.zeros(n)
    if rate is None or rate <= 0:
        raise CloudFormatError(
            f"{source}: the frame rate is unknown; give `input.rate:` in the config or --rate on "
            "the command line."
        )
    return np.arange(n) / float(rate)


def read_cloud_sequence(
    path: str | Path,
    *,
    rate: float | None = None,
    intrinsics: Any = None,
    camera_pose: np.ndarray | None = None,
    depth_scale: float | None = None,
) -> CloudSequence:
    """Read a point-cloud sequence (see the module docstring for the layouts).

    Args:
        path: file or directory.
        rate: frame rate [Hz] when the input has no times.
        intrinsics: ``[fx, fy, cx, cy]`` for depth images without their own intrinsics.
        camera_pose: (4, 4) camera-to-world transform for depth images (default: the file's, else
            identity, i.e. points stay in the camera frame).
        depth_scale: metres per depth unit for integer depth images (default 0.001 for PNG).

    Raises:
        CloudFormatError: unreadable or incomplete input, with the fix.
    """
    path = Path(path)
    src = str(path)
    if not path.exists():
        raise CloudFormatError(f"input {src!r} does not exist.")
    if path.is_dir():
        return _read_directory(path, rate, intrinsics, camera_pose, depth_scale)
    suffix = path.suffix.lower()
    if suffix == ".ply":
        p, n = read_ply(path)
        return CloudSequence([CloudFrame(p, n, 0.0)], source=src)
    if suffix == ".npy":
        try:
            arr = np.load(path, allow_pickle=False)
        except Exception as exc:
            raise CloudFormatError(f"{src}: not a readable .npy file ({exc}).") from None
        if arr.ndim == 2 and arr.shape[1] == 3:
            return CloudSequence([CloudFrame(arr.astype(float), None, 0.0)], source=src)
        if arr.ndim == 3 and arr.shape[2] == 3:
            return CloudSequence(
                _frames_from_stack(arr.astype(float), None, _times(len(arr), None, rate, src)),
                source=src,
            )
        raise CloudFormatError(
            f"{src}: expected an (N, 3) or (T, N, 3) array, got shape {arr.shape}."
        )
    if suffix == ".npz":
        return _read_npz(path, rate, intrinsics, camera_pose, depth_scale)
    raise CloudFormatError(
        f"{src}: unsupported input type {suffix!r}; use .npz, .npy, .ply or a directory."
    )


def _read_npz(path: Path, rate, intrinsics, camera_pose, depth_scale) -> CloudSequence:  # noqa: ANN001
    src = str(path)
    with load_npz(path, CloudFormatError) as data:
        keys = set(data.files)
        if "rate" in keys and rate is None:
            rate = float(data["rate"])
        t = data["t"] if "t" in keys else None
        sensor = data["sensor_position"].astype(float) if "sensor_position" in keys else None
        pose = (
            np.asarray(camera_pose, float)
            if camera_pose is not None
            else (data["camera_pose"].astype(float) if "camera_pose" in keys else None)
        )
        if sensor is None and pose is not None:
            sensor = pose[:3, 3].copy()
        meta = {k[5:]: data[k] for k in keys if k.startswith("meta/")}
        if "points" in keys:
            P = data["points"].astype(float)
            N = data["normals"].astype(float) if "normals" in keys else None
            if "counts" in keys:
                counts = data["counts"].astype(int)
                if counts.sum() != len(P):
                    raise CloudFormatError(
                        f"{src}: counts sum to {counts.sum()} but there are {len(P)} points."
                    )
                times = _times(len(counts), t, rate, src)
                edges = np.concatenate([[0], np.cumsum(counts)])
                frames = [
                    CloudFrame(P[a:b], None if N is None else N[a:b], float(times[i]))
                    for i, (a, b) in enumerate(zip(edges[:-1], edges[1:], strict=True))
                ]
            elif P.ndim == 3:
                frames = _frames_from_stack(P, N, _times(len(P), t, rate, src))
            elif P.ndim == 2:
                frames = [CloudFrame(P, N, 0.0)]
            else:
                raise CloudFormatError(
                    f"{src}: `points` must be (T, N, 3) or (sum N, 3) with `counts`."
                )
            return CloudSequence(frames, sensor_position=sensor, source=src, meta=meta)
        if "depth" in keys:
            D = data["depth"]
            if D.ndim == 2:
                D = D[None]
            scale = (
                depth_scale
                if depth_scale is not None
                else (float(data["depth_scale"]) if "depth_scale" in keys else 1.0)
            )
            intr_spec = data["intrinsics"] if "intrinsics" in keys else intrinsics
            if intr_spec is None:
                raise CloudFormatError(
                    f"{src}: depth images need `intrinsics` [fx, fy, cx, cy] (in the file or "
                    "the config)."
                )
            intr = PinholeIntrinsics.from_any(intr_spec, D.shape[1:])
            times = _times(len(D), t, rate, src)
            frames = []
            for i in range(len(D)):
                d = D[i].astype(float) * scale
                frames.append(CloudFrame(depth_to_points(d, intr, pose), None, float(times[i])))
            return CloudSequence(
                frames, sensor_position=sensor, source=src, meta={"intrinsics": intr, **meta}
            )
    raise CloudFormatError(
        f"{src}: the .npz has neither `points` nor `depth` (keys: {sorted(keys)})."
    )


def _read_directory(path: Path, rate, intrinsics, camera_pose, depth_scale) -> CloudSequence:  # noqa: ANN001
    src = str(path)
    for suffix in (".ply", ".npy", ".png"):
        files = sorted(p for p in path.iterdir() if p.suffix.lower() == suffix)
        if files:
            break
    else:
        raise CloudFormatError(f"{src}: the directory has no .ply, .npy or .png files.")
    times = _times(len(files), None, rate, src)
    frames: list[CloudFrame] = []
    sensor = None
    pose = None if camera_pose is None else np.asarray(camera_pose, float)
    if pose is not None:
        sensor = pose[:3, 3].copy()
    for i, f in enumerate(files):
        if suffix == ".ply":
            p, n = read_ply(f)
        elif suffix == ".npy":
            p, n = np.load(f).astype(float).reshape(-1, 3), None
        else:
            try:
                from PIL import Image
            except ImportError:
                raise missing_dependency("plot", "reading PNG depth images (Pillow)") from None
            if intrinsics is None:
                raise CloudFormatError(
                    f"{src}: PNG depth images need `input.intrinsics: [fx, fy, cx, cy]` in the "
                    "config."
                )
            img = np.asarray(Image.open(f)).astype(float)
            intr = PinholeIntrinsics.from_any(intrinsics, img.shape[:2])
            p, n = (
                depth_to_points(
                    img * (depth_scale if depth_scale is not None else 1e-3), intr, pose
                ),
                None,
            )
        frames.append(CloudFrame(p, n, float(times[i])))
    return CloudSequence(frames, sensor_position=sensor, source=src)


__all__ = [
    "CloudFormatError",
    "CloudFrame",
    "CloudSequence",
    "PinholeIntrinsics",
    "crop",
    "depth_normals",
    "depth_to_points",
    "estimate_normals",
    "prepare_cloud",
    "read_cloud_sequence",
    "read_ply",
    "voxel_downsample",
    "write_ply",
]
