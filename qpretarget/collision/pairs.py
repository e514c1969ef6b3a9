# SPDX-License-Identifier: Apache-2.0
r"""Which body pairs can collide: ``pairs: auto`` and the rules that leave a pair out.

Candidate pairs are every pair of bodies with collision geometry (DESIGN.md "Self-collision"),
minus the pairs that can never be separated or never matter:

* **same joint** — two links rigidly attached to one joint keep their relative pose;
* **adjacent** — one body's joint is the *geometric parent* of the other's: the nearest ancestor
  joint that carries collision geometry (links without geometry are skipped, as MoveIt's setup
  assistant does), so the hulls of two links around one joint are not asked to separate;
* **both static** — neither body moves;
* **in contact in the reference pose** — their simplified shapes are closer than
  ``contact_margin`` in the robot's reference posture (they touch by design, e.g. a thigh cover
  and the hip);
* **disabled by the SRDF** — ``<disable_collisions link1=... link2=... reason=.../>`` of the
  robot's SRDF, when example-robot-data ships one.

Then the config's ``include:`` pairs are added back (whatever the rules said) and its
``exclude:`` pairs are left out. :func:`select_pairs` returns the pairs and, for each left-out
pair, the reason; ``qpretarget info CONFIG`` prints both.
"""

from __future__ import annotations

import itertools
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import ConfigError, UnknownNameError
from ..robot import RobotModel, RobotState
from .model import CollisionModel
from .shapes import LinkShape

Pair = tuple[str, str]


def adjacent_links(robot: RobotModel, a: str, b: str, shapes: Mapping[str, LinkShape]) -> bool:
    """``True`` when links ``a`` and ``b`` are on the same joint or on a parent/child joint pair."""
    ja, jb = shapes[a].joint, shapes[b].joint
    parents = robot.model.parents
    return ja == jb or parents[ja] == jb or parents[jb] == ja


@dataclass(frozen=True)
class PairSelection:
    """The outcome of :func:`select_pairs`.

    Attributes:
        pairs: the selected pairs, in a deterministic order (body order of the URDF).
        excluded: left-out pair -> the reason, in words.
        n_bodies: bodies with collision geometry.
    """

    pairs: list[Pair]
    excluded: dict[Pair, str] = field(default_factory=dict)
    n_bodies: int = 0

    def reasons(self) -> dict[str, int]:
        """Number of left-out pairs per reason (the text before any parenthesis)."""
        out: dict[str, int] = {}
        for why in self.excluded.values():
            key = why.split(" (")[0]
            out[key] = out.get(key, 0) + 1
        return out


def srdf_disabled_pairs(srdf: str | Path | None) -> dict[Pair, str]:
    """``disable_collisions`` entries of an SRDF file: pair (sorted) -> SRDF reason.

    Raises:
        ConfigError: the file is not well-formed XML.
    """
    if srdf is None:
        return {}
    try:
        root = ET.parse(str(srdf)).getroot()
    except (ET.ParseError, OSError) as exc:
        raise ConfigError(f"cannot read the SRDF {str(srdf)!r}: {exc}") from None
    out: dict[Pair, str] = {}
    for el in root.iter("disable_collisions"):
        a, b = el.get("link1"), el.get("link2")
        if a and b:
            out[_key(a, b)] = el.get("reason") or "listed"
    return out


def _key(a: str, b: str) -> Pair:
    return (a, b) if a <= b else (b, a)


def _geometric_parent(model_parents: Sequence[int], joint: int, carriers: set[int]) -> int:
    """Nearest ancestor of ``joint`` that carries collision geometry (0: the universe)."""
    j = model_parents[joint]
    while j != 0 and j not in carriers:
        j = model_parents[j]
    return j


def _chain_neighbours(
    a: LinkShape, b: LinkShape, parents: Sequence[int], carriers: set[int]
) -> bool:
    """One body's joint is the other's geometric grandparent (two joints apart in one chain)."""
    for x, y in ((a, b), (b, a)):
        gp = _geometric_parent(parents, x.joint, carriers)
        if gp != 0 and _geometric_parent(parents, gp, carriers) == y.joint:
            return True
    return False


def _structural_reason(
    a: LinkShape, b: LinkShape, parents: Sequence[int], carriers: set[int]
) -> str | None:
    if a.joint == b.joint:
        return "same joint"
    if a.joint == 0 and b.joint == 0:
        return "both static"
    if _geometric_parent(parents, a.joint, carriers) == b.joint:
        return "adjacent in the kinematic tree"
    if _geometric_parent(parents, b.joint, carriers) == a.joint:
        return "adjacent in the kinematic tree"
    return None


def _check_names(pairs: Sequence[Sequence[str]], known: Sequence[str], path: str) -> list[Pair]:
    out: list[Pair] = []
    for k, pair in enumerate(pairs):
        if isinstance(pair, str) or len(pair) != 2:
            raise ConfigError(
                f"a pair must be [body_a, body_b], got {pair!r}.", path=f"{path}[{k}]"
            )
        for i, body in enumerate(pair):
            if body not in known:
                raise UnknownNameError(
                    "collision body", str(body), list(known), path=f"{path}[{k}][{i}]",
                    fix="Bodies are links with collision geometry (`qpretarget info CONFIG` "
                    "lists them).",
                )  # fmt: skip
        out.append((str(pair[0]), str(pair[1])))
    return out


def select_pairs(
    robot: RobotModel,
    shapes: Mapping[str, LinkShape],
    *,
    contact_margin: float = 0.0,
    include: Sequence[Sequence[str]] = (),
    exclude: Sequence[Sequence[str]] = (),
    use_srdf: bool = True,
    geometry: str = "convex_hull",
    neighbour_distance: float = 0.0,
    links: Sequence[str] | None = None,
    path: str = "pairs",
) -> PairSelection:
    r"""Every pair of bodies that can collide (``pairs: auto``), with the reasons for the rest.

    Args:
        robot: the robot (its reference posture and SRDF).
        shapes: body name -> simplified shape (:func:`~qpretarget.collision.link_shapes`), in the
            URDF's order; the contact test uses these shapes, as the controller does.
        contact_margin: pairs closer than this in the reference posture are in contact [m].
        include: pairs added whatever the rules say.
        exclude: pairs left out whatever the rules say.
        use_srdf: honour the SRDF's ``disable_collisions``.
        geometry: kind of the shapes (``convex_hull`` or ``capsule``).
        neighbour_distance: chain neighbours (two joints apart in one limb) closer than this in
            the reference posture are left out [m]: their hulls sit close by construction, and
            a damper on them would lock the joint between them (``0``: keep them all).
        links: restrict the candidates to pairs of these bodies (adjacency is still judged
            on every body with geometry).
        path: YAML path for error messages.

    Returns:
        The :class:`PairSelection`.

    Raises:
        UnknownNameError: an ``include``/``exclude`` pair names an unknown body (close names).
    """
    names = list(shapes) if links is None else [n for n in shapes if n in set(links)]
    inc = {_key(*p) for p in _check_names(include, names, f"{path}.include")}
    exc = {_key(*p) for p in _check_names(exclude, names, f"{path}.exclude")}
    parents = list(robot.model.parents)
    carriers = {s.joint for s in shapes.values() if s.joint != 0}
    srdf = srdf_disabled_pairs(robot.srdf_path) if use_srdf else {}
    excluded: dict[Pair, str] = {}
    candidates: list[Pair] = []
    for a, b in itertools.combinations(names, 2):
        key = _key(a, b)
        why = _structural_reason(shapes[a], shapes[b], parents, carriers)
        if why is None and key in srdf:
            why = f"disabled by the SRDF ({srdf[key]})"
        if why is None and key in exc:
            why = "excluded by the config"
        if why is not None and key not in inc:
            excluded[(a, b)] = why
        else:
            candidates.append((a, b))
    movable = [p for p in candidates if not (shapes[p[0]].joint == 0 and shapes[p[1]].joint == 0)]
    d = _reference_distances(robot, movable, geometry)
    pairs: list[Pair] = []
    for (a, b), dist in zip(movable, d, strict=True):
        if _key(a, b) in inc:
            pairs.append((a, b))
        elif dist <= contact_margin:
            excluded[(a, b)] = f"in contact in the reference pose ({dist * 1e3:.1f} mm)"
        elif dist < neighbour_distance and _chain_neighbours(
            shapes[a], shapes[b], parents, carriers
        ):
            excluded[(a, b)] = f"chain neighbours close at rest ({dist * 1e3:.1f} mm)"
        else:
            pairs.append((a, b))
    return PairSelection(pairs, excluded, len(names))


def _reference_distances(robot: RobotModel, pairs: Sequence[Pair], geometry: str) -> np.ndarray:
    if not pairs:
        return np.zeros(0)
    model = CollisionModel(robot, pairs, geometry=geometry, broad_phase=False)
    state = RobotState(robot)
    state.update(robot.q_reference)
    return model.compute_all(state)[0]
