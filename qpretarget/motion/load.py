# SPDX-License-Identifier: Apache-2.0
"""`load_motion`: pick the reader from the file extension."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from .asf_amc import read_asf_amc
from .bvh import read_bvh
from .c3d_ import read_c3d
from .human_motion import HumanMotion
from .positions import read_positions

#: Extensions :func:`load_motion` understands (``.npz``/``.csv``: key-point files).
MOTION_EXTENSIONS = (".bvh", ".amc", ".c3d", ".npz", ".csv")

#: Endings a folder scan (``qpretarget batch DIR``) picks up: key-point files only under these
#: double endings, so a folder holding runs or CSV exports is not read as key-points.
SCANNED_ENDINGS = (".bvh", ".amc", ".c3d", ".keypoints.npz", ".keypoints.csv")


def is_scanned_motion_file(path: str | Path) -> bool:
    """Whether a folder scan takes ``path`` as a motion file (:data:`SCANNED_ENDINGS`)."""
    return str(path).lower().endswith(SCANNED_ENDINGS)


def find_asf(amc_path: str | Path) -> Path:
    """The skeleton file of an AMC motion, found next to it.

    Tries ``<stem>.asf``, then the stem without its trailing ``_<part>`` pieces (CMU names
    ``SS_TT.amc`` with ``SS.asf``: ``cmu_16_15.amc`` -> ``cmu_16.asf``), then the only ``.asf``
    file of the folder.

    Raises:
        FileNotFoundError: No candidate exists, or several ``.asf`` files could match; the
            message lists what was tried and asks for ``asf=``.
    """
    amc_path = Path(amc_path)
    folder, stem = amc_path.parent, amc_path.stem
    tried = []
    while True:
        candidate = folder / f"{stem}.asf"
        tried.append(candidate.name)
        if candidate.is_file():
            return candidate
        if "_" not in stem:
            break
        stem = stem.rsplit("_", 1)[0]
    others = sorted(folder.glob("*.asf"))
    if len(others) == 1:
        return others[0]
    raise FileNotFoundError(
        f"no skeleton found for {amc_path}: tried {tried}"
        + (f"; the folder holds {[p.name for p in others]}" if others else "")
        + "; pass asf=<path to the .asf file>"
    )


def load_motion(path: str | Path, *, keep_leading_cut: bool = False, **options: Any) -> HumanMotion:
    """Read a motion file with the reader its extension calls for.

    Frames before a cut at the start of the clip (a reference T-pose in frame 0, a dropout:
    :func:`~qpretarget.motion.human_motion.leading_cut`) are dropped, and
    ``meta["notes"]`` says so, unless ``keep_leading_cut``.

    * ``.bvh`` -> :func:`~qpretarget.motion.bvh.read_bvh`
    * ``.amc`` -> :func:`~qpretarget.motion.asf_amc.read_asf_amc`, skeleton from ``asf=`` or
      :func:`find_asf`
    * ``.c3d`` -> :func:`~qpretarget.motion.c3d_.read_c3d`
    * ``.npz``, ``.csv`` -> :func:`~qpretarget.motion.positions.read_positions` (key-point files)

    Args:
        path: The motion file.
        keep_leading_cut: Keep the frames before a cut at the start (as the file has them).
        **options: Keyword arguments of the reader (``length_scale``, ``up_axis``, ``rate``,
            ``asf``, ``marker_map``).

    Raises:
        FileNotFoundError: The file (or the AMC's skeleton) does not exist.
        ValueError: Unsupported extension (``.asf`` included: pass the ``.amc``).
        MotionFormatError: The reader found the file malformed.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".asf":
        raise ValueError(
            f"{path} is an ASF skeleton; load the AMC motion instead: "
            "load_motion('trial.amc', asf='skeleton.asf')"
        )
    if suffix not in MOTION_EXTENSIONS:
        raise ValueError(
            f"cannot read {path}: unsupported extension {path.suffix!r}; "
            f"supported: {', '.join(MOTION_EXTENSIONS)}"
        )
    if not path.is_file():
        raise FileNotFoundError(f"motion file {path} does not exist")
    motion = _read(path, suffix, options)
    return motion if keep_leading_cut else motion.without_leading_cut()


def _read(path: Path, suffix: str, options: dict[str, Any]) -> HumanMotion:
    if suffix == ".bvh":
        return read_bvh(path, **options)
    if suffix == ".c3d":
        return read_c3d(path, **options)
    if suffix in (".npz", ".csv"):
        return read_positions(path)
    asf = options.pop("asf", None)
    return read_asf_amc(find_asf(path) if asf is None else asf, path, **options)
