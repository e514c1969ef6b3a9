# SPDX-License-Identifier: Apache-2.0
"""`HumanMotion`, the container every reader returns, and the errors of the motion package.

Conventions (see ``docs/motion.md``): positions in [m], world z up and right-handed, time in [s]
starting at the first frame of the file, orientations as world rotation matrices of the joint
frames relative to the skeleton's rest pose.
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import QPRetargetError


class MotionError(QPRetargetError):
    """Base class of the errors raised by :mod:`qpretarget.motion`."""


class MotionFormatError(MotionError, ValueError):
    """A motion file does not follow its format.

    The message names the file, the line or frame, and what was expected versus found.

    Attributes:
        path: The file being read.
        line: 1-based line number, when the format is line-based.
        frame: Frame number as written in the file (AMC) or 1-based frame index, if relevant.
    """

    def __init__(
        self,
        path: str | Path,
        message: str,
        *,
        line: int | None = None,
        frame: int | None = None,
    ) -> None:
        where = str(path)
        if line is not None:
            where += f", line {line}"
        if frame is not None:
            where += f" (frame {frame})"
        super().__init__(f"{where}: {message}")
        self.path = str(path)
        self.line = line
        self.frame = frame


class UnknownMotionJointError(MotionError, KeyError):
    """A joint or marker name is not in the motion.

    Attributes:
        name: The name asked for.
        close_matches: Up to three similar names found in the motion.
    """

    def __init__(
        self, name: str, *, known: Sequence[str], source: str = "", detail: str = ""
    ) -> None:
        candidates = list(known) + [k.rsplit(":", 1)[1] for k in known if ":" in k]
        close = difflib.get_close_matches(name, candidates, n=3, cutoff=0.5)
        hint = f" Did you mean {', '.join(map(repr, close))}?" if close else ""
        where = f" of {source}" if source else ""
        if detail:
            self.message = f"joint {name!r}{where}: {detail}"
        else:
            self.message = (
                f"joint {name!r} is not in the {len(known)} joints{where}.{hint} "
                "List them with `motion.names`."
            )
        super().__init__(self.message)
        self.name = name
        self.close_matches = close

    def __str__(self) -> str:
        """Return the message without the quotes `KeyError` adds."""
        return self.message


def _readonly(array: np.ndarray) -> np.ndarray:
    view = array.view()
    view.flags.writeable = False
    return view


#: Frames at the start of a clip searched for a cut (:func:`leading_cut`).
CUT_SEARCH = 10
#: A jump counts as a cut when it is this many times the largest one after the searched frames.
CUT_RATIO = 3.0
#: ... and at least this long [m] (a still clip's jumps are all tiny).
CUT_MIN = 0.1


def leading_cut(positions: npt.ArrayLike) -> tuple[int, float, float]:
    r"""Frames at the start of a clip that are not part of its motion (a reference pose, a dropout).

    Some files begin with a pose that is not captured motion: BVH conversions of the CMU
    database (cgspeed's among them) put a T-pose in frame 0, and CMU 16_15's AMC file has the
    left arm snapped to its rest pose in frames 1-2. The skeleton then jumps between two of the
    first frames by far more than it moves between any two later ones. With
    :math:`d_k = \max_j \lVert p_j(k+1) - p_j(k) \rVert` (the largest point displacement
    from frame :math:`k` to :math:`k+1`, missing points ignored) and
    :math:`D = \max_{k \ge K} d_k` (:data:`CUT_SEARCH` :math:`= K`), the last
    :math:`k < K` with :math:`d_k > \max(` :data:`CUT_RATIO` :math:`D,` :data:`CUT_MIN`
    :math:`)` is a cut and frames :math:`0..k` are dropped. (On the shared clips: 0.69 m
    against at most 0.05 m later on the cgspeed clip, 0.93 m on the 16_15 AMC; no other clip
    comes within a factor 3 of its own later jumps.)

    Args:
        positions: ``(T, J, 3)`` positions [m] (NaN: missing).

    Returns:
        ``(n, jump, largest)``: the number of frames to drop (0: none), the cut's jump and
        :math:`D` [m]; ``(0, 0, 0)`` for clips shorter than :math:`2K`.
    """
    p = np.asarray(positions, dtype=float)
    if p.ndim != 3 or p.shape[0] < 2 * CUT_SEARCH:
        return 0, 0.0, 0.0
    step = np.linalg.norm(np.diff(p, axis=0), axis=2)  # (T-1, J)
    step = np.where(np.isfinite(step), step, -np.inf)
    d = step.max(axis=1)
    later = d[CUT_SEARCH:]
    later = later[np.isfinite(later)]
    if later.size == 0:
        return 0, 0.0, 0.0
    largest = float(later.max())
    cuts = np.nonzero(d[:CUT_SEARCH] > max(CUT_RATIO * largest, CUT_MIN))[0]
    if cuts.size == 0:
        return 0, 0.0, largest
    k = int(cuts[-1])
    return k + 1, float(d[k]), largest


@dataclass(frozen=True, eq=False)
class HumanMotion:
    r"""A captured human motion: named 3D points over time.

    Arrays are stored as read-only views; :meth:`slice` and indexing return new objects.

    Attributes:
        t: Timestamps in [s], shape ``(T,)``, strictly increasing.
        names: Joint (or marker, or key-point) names, ``J`` unique strings.
        positions: Positions in [m] in the z-up right-handed world, shape ``(T, J, 3)``; NaN marks
            a missing sample (C3D gaps).
        parents: Parent index of each joint, -1 for a root (every marker of a C3D file is a root).
        orientations: World rotation of each joint frame relative to the rest pose,
            shape ``(T, J, 3, 3)``, or ``None`` when the source has none (C3D).
        rate: Nominal frame rate in [Hz].
        source: Where the motion comes from (file path), used in messages.
        meta: Reader details: ``length_scale`` [m / file unit], ``up_axis``, ``frame_time`` as
            written, ``first_frame`` numbering of the file, and format-specific entries.
    """

    t: np.ndarray
    names: tuple[str, ...]
    positions: np.ndarray
    parents: tuple[int, ...]
    orientations: np.ndarray | None = None
    rate: float = 0.0
    source: str = ""
    meta: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        """Normalise types, validate shapes and freeze the arrays.

        Raises:
            ValueError: If shapes, names, parents or timestamps are inconsistent.
        """
        t = np.asarray(self.t, dtype=float)
        positions = np.asarray(self.positions, dtype=float)
        names = tuple(str(n) for n in self.names)
        parents = tuple(int(p) for p in self.parents)
        if t.ndim != 1:
            raise ValueError(f"t must have shape (T,), got {t.shape}")
        num_frames, num_joints = t.shape[0], len(names)
        if positions.shape != (num_frames, num_joints, 3):
            raise ValueError(
                f"positions must have shape (T, J, 3) = ({num_frames}, {num_joints}, 3) to match "
                f"t and names, got {positions.shape}"
            )
        if len(parents) != num_joints:
            raise ValueError(f"parents has {len(parents)} entries for {num_joints} names")
        if len(set(names)) != num_joints:
            dupes = sorted({n for n in names if names.count(n) > 1})
            raise ValueError(f"joint names must be unique; repeated: {dupes}")
        for j, p in enumerate(parents):
            if not -1 <= p < num_joints or p == j:
                raise ValueError(f"joint {names[j]!r} has invalid parent index {p}")
        if num_frames > 1 and not np.all(np.diff(t) > 0):
            raise ValueError("t must be strictly increasing")
        orientations = self.orientations
        if orientations is not None:
            orientations = np.asarray(orientations, dtype=float)
            if orientations.shape != (num_frames, num_joints, 3, 3):
                raise ValueError(
                    "orientations must have shape (T, J, 3, 3) = "
                    f"({num_frames}, {num_joints}, 3, 3), got {orientations.shape}"
                )
            orientations = _readonly(orientations)
        if not self.rate > 0:
            raise ValueError(f"rate must be positive [Hz], got {self.rate}")
        object.__setattr__(self, "t", _readonly(t))
        object.__setattr__(self, "positions", _readonly(positions))
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "parents", parents)
        object.__setattr__(self, "orientations", orientations)
        object.__setattr__(self, "rate", float(self.rate))
        object.__setattr__(self, "source", str(self.source))
        object.__setattr__(self, "meta", dict(self.meta))

    # ----------------------------------------------------------------------------- look-ups

    def __len__(self) -> int:
        """Number of frames."""
        return self.t.shape[0]

    def __repr__(self) -> str:
        """Short summary: source, frames, rate, joints."""
        return (
            f"HumanMotion(source={self.source!r}, frames={len(self)}, rate={self.rate:g} Hz, "
            f"duration={self.duration:.3f} s, joints={len(self.names)}, "
            f"orientations={'yes' if self.orientations is not None else 'no'})"
        )

    @property
    def duration(self) -> float:
        """Time between the first and the last frame in [s]."""
        return float(self.t[-1] - self.t[0]) if len(self) else 0.0

    def index(self, name: str) -> int:
        """Index of a joint in :attr:`names`.

        An exact match wins. Otherwise a name without a ``prefix:`` matches a prefixed label
        when exactly one label ends with ``:name`` (C3D subject prefixes such as ``Daphnee:``).

        Args:
            name: Joint, marker or key-point name.

        Returns:
            Index into :attr:`names`.

        Raises:
            UnknownMotionJointError: If no name matches, or if the unprefixed name is ambiguous.
        """
        try:
            return self.names.index(name)
        except ValueError:
            pass
        suffix = ":" + name
        hits = [i for i, n in enumerate(self.names) if n.endswith(suffix)]
        if len(hits) == 1:
            return hits[0]
        if len(hits) > 1:
            options = ", ".join(repr(self.names[i]) for i in hits)
            raise UnknownMotionJointError(
                name,
                known=self.names,
                source=self.source,
                detail=f"ambiguous, it matches {options}; use the full label",
            )
        raise UnknownMotionJointError(name, known=self.names, source=self.source)

    def joint(self, name: str) -> np.ndarray:
        """Positions of one joint in [m], shape ``(T, 3)`` (read-only view).

        Raises:
            UnknownMotionJointError: If the name is not in the motion (the message lists close
                matches).
        """
        return self.positions[:, self.index(name)]

    def joint_orientation(self, name: str) -> np.ndarray:
        """World rotations of one joint frame, shape ``(T, 3, 3)`` (read-only view).

        Raises:
            UnknownMotionJointError: If the name is not in the motion.
            ValueError: If the motion has no orientations (C3D markers).
        """
        index = self.index(name)
        if self.orientations is None:
            raise ValueError(
                f"{self.source or 'this motion'} has no orientations (marker data); "
                "use positions only"
            )
        return self.orientations[:, index]

    # ----------------------------------------------------------------------------- subsets

    def __getitem__(self, frames: slice) -> HumanMotion:
        """Frames ``motion[start:stop:step]`` as a new motion (timestamps unchanged).

        Raises:
            TypeError: If ``frames`` is not a slice (use :meth:`joint` for a joint).
        """
        if not isinstance(frames, slice):
            raise TypeError(
                "HumanMotion supports frame slices only, e.g. motion[10:20]; "
                "use motion.joint(name) for one joint"
            )
        step = frames.step or 1
        rate = self.rate / step
        return HumanMotion(
            t=self.t[frames].copy(),
            names=self.names,
            positions=self.positions[frames].copy(),
            parents=self.parents,
            orientations=None if self.orientations is None else self.orientations[frames].copy(),
            rate=rate,
            source=self.source,
            meta=self.meta,
        )

    def slice(self, start_s: float = 0.0, end_s: float | None = None) -> HumanMotion:
        """Frames with ``start_s <= t < end_s`` as a new motion; timestamps are kept, not shifted.

        Comparisons allow a millionth of a frame period, so ``slice(1.0, 2.0)`` of a 120 Hz
        clip holds exactly the 120 frames from ``t = 1`` [s].

        Args:
            start_s: First time in [s] (inclusive).
            end_s: Last time in [s] (exclusive); ``None`` for the end of the clip.

        Raises:
            ValueError: If the interval holds no frame.
        """
        eps = 1e-6 / self.rate
        mask = self.t >= start_s - eps
        if end_s is not None:
            mask &= self.t < end_s - eps
        (indices,) = np.nonzero(mask)
        if indices.size == 0:
            raise ValueError(
                f"no frame of {self.source or 'the motion'} in [{start_s}, {end_s}) s; "
                f"the clip spans [{self.t[0]:.4f}, {self.t[-1]:.4f}] s"
            )
        return self[indices[0] : indices[-1] + 1]

    # ----------------------------------------------------------------------------- measures

    def segment_length(self, a: str, b: str) -> float:
        """Median distance in [m] between two joints over the frames where both are present.

        Raises:
            UnknownMotionJointError: If a name is not in the motion.
            ValueError: If the two points are never present together.
        """
        d = np.linalg.norm(self.joint(a) - self.joint(b), axis=-1)
        d = d[np.isfinite(d)]
        if d.size == 0:
            raise ValueError(f"{a!r} and {b!r} are never both present in {self.source}")
        return float(np.median(d))

    def without_leading_cut(self) -> HumanMotion:
        """The motion without the frames before a cut at its start (:func:`leading_cut`).

        Returns ``self`` when there is none; otherwise the later frames (timestamps kept), with
        a sentence saying what was dropped appended to ``meta["notes"]`` and the count in
        ``meta["dropped_leading_frames"]``.
        """
        n, jump, largest = leading_cut(self.positions)
        if n == 0 or n >= len(self):
            return self
        out = self[n:]
        frames = "frame 0" if n == 1 else f"frames 0-{n - 1}"
        note = (
            f"{frames} of {Path(self.source).name or 'the motion'} dropped: not part of the "
            f"motion (a reference pose or a dropout: the skeleton jumps {jump:.2f} m in one "
            f"frame, at most {largest:.2f} m between any two later frames); "
            "load_motion(..., keep_leading_cut=True) keeps them"
        )
        meta = dict(self.meta)
        meta["notes"] = [*meta.get("notes", []), note]
        meta["dropped_leading_frames"] = n
        return HumanMotion(
            t=out.t, names=out.names, positions=out.positions, parents=out.parents,
            orientations=out.orientations, rate=out.rate, source=out.source, meta=meta,
        )  # fmt: skip

    def with_positions(
        self,
        names: Sequence[str],
        positions: npt.ArrayLike,
        *,
        meta: Mapping[str, Any] | None = None,
    ) -> HumanMotion:
        """A motion with the same timing and new points (parents -1, no orientations).

        Used to turn key-points into a motion of their own.

        Args:
            names: New point names, ``J'`` of them.
            positions: ``(T, J', 3)`` positions in [m].
            meta: Entries added to (or replacing those of) :attr:`meta`.
        """
        return HumanMotion(
            t=self.t,
            names=tuple(names),
            positions=np.asarray(positions, dtype=float),
            parents=(-1,) * len(names),
            orientations=None,
            rate=self.rate,
            source=self.source,
            meta={**self.meta, **(meta or {})},
        )
