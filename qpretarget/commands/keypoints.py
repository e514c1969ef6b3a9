# SPDX-License-Identifier: Apache-2.0
"""``qpretarget keypoints``: a motion file's joints and the key-point map that fits them."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

from . import add_command, add_motion

if TYPE_CHECKING:
    from ..motion.keypoints import KeypointMap

SUMMARY = "list a motion file's joints and the key-point map that fits them"
DESCRIPTION = "Show the joints of a BVH, ASF/AMC or C3D file and the key-point map guess."

HELP = """examples:
  qpretarget keypoints ../shared/data/mocap/cmu_16_15_walk.bvh
  qpretarget keypoints my_capture.bvh --template > my_skeleton.yaml

Prints the joint (or marker) names of the file and the bundled key-point map picked for them
(cmu, cgspeed, lafan1, mixamo, mvn_bvh, biovision, ...), key-point by key-point, and what the
retargeter will correct in the skeleton (a waist at the hip joints, a rest pose that does not
face forward; docs/motion.md). When no bundled map fits, prints the closest one, the names
it misses, and a map template to fill in (docs/motion.md); pass the filled file with
`qpretarget retarget ... --keypoint-map my_skeleton.yaml`.
"""


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``keypoints`` subcommand."""
    p = add_command(sub, "keypoints", help=SUMMARY, description=DESCRIPTION, examples=HELP)
    add_motion(p)
    p.add_argument("--template", action="store_true", help="print only a YAML map template")
    p.set_defaults(func=run)


def _norm(name: str) -> str:
    return "".join(c for c in name.lower() if c.isalnum())


def suggest(names: list[str], kmap: KeypointMap) -> dict[str, str]:
    """Key-point -> a joint of ``names`` that looks like the map's source (suffix match).

    A file whose joints carry a prefix (``J_lhumerus``, ``Character1_LeftArm``) or another case
    still gets the map's choices; key-points without a look-alike are left out.
    """
    out: dict[str, str] = {}
    normed = [(_norm(n), n) for n in names]
    for kp, src in kmap.keypoints.items():
        picks = []
        for point in src.points:
            p = _norm(point.split(":")[-1])
            hit = next((n for nn, n in normed if nn == p), None) or next(
                (n for nn, n in normed if p and nn.endswith(p)), None
            )
            if hit is None:
                break
            picks.append(hit)
        else:
            out[kp] = picks[0] if len(picks) == 1 else "[" + ", ".join(picks) + "]"
    return out


def template(names: list[str], guess: dict[str, str]) -> str:
    """A key-point map YAML to fill in: every standard key-point, guesses filled, the rest ?."""
    from ..motion.keypoints import KEYPOINT_NAMES

    lines = [
        "# Key-point map template: check the guesses; for a commented key-point the file can",
        "# give, uncomment it and replace ? with a joint name (or a list [a, b]: their midpoint).",
        "# Format: docs/motion.md. Joints of the file:",
        *("#   " + ", ".join(names[i : i + 8]) for i in range(0, len(names), 8)),
        "name: my_skeleton",
        "kind: skeleton",
        "keypoints:",
    ]
    lines += [f"  {kp}: {guess[kp]}" if kp in guess else f"  # {kp}: ?" for kp in KEYPOINT_NAMES]
    return "\n".join(lines) + "\n"


def best_suggestion(names: list[str]) -> tuple[str, dict[str, str]]:
    """The bundled map whose names are most like the file's, and its suggestions."""
    from ..motion.keypoints import list_keypoint_maps, load_keypoint_map

    scored = [(m, suggest(names, load_keypoint_map(m))) for m in list_keypoint_maps()]
    return max(scored, key=lambda ms: len(ms[1]))


def conventions(motion: Any, kmap: KeypointMap) -> list[str]:
    """What the retargeter will correct in this skeleton, read on its first frame.

    The waist lift of a root at the hip joints and the re-referencing of a rest pose that does
    not stand upright facing +x (``KeypointStream.waist_lift`` / ``rest_fix``, the same
    functions the retargeter calls; docs/motion.md, *The waist key-point* and *Rest poses*).
    """
    import numpy as np

    from ..retarget.stream import KeypointStream, rotation_angle

    try:
        pts = {k: np.asarray(v, float)[0] for k, v in kmap.positions(motion).items()}
        rots = (
            {o: motion.joint_orientation(j)[0] for o, j in kmap.orientations.items()}
            if motion.orientations is not None
            else {}
        )
    except (KeyError, ValueError, IndexError):
        return []
    lift = KeypointStream.waist_lift(pts, rots.get("waist"))
    if lift:
        pts["waist"] = pts["waist"] + np.array([0.0, 0.0, lift])
    fixes = KeypointStream.rest_fix(pts, rots)
    out = []
    if lift:
        out.append(
            f"skeleton: the waist is rooted at (or near) the hip joints: raised by "
            f"{100 * lift:.1f} cm when retargeted (docs/motion.md, The waist key-point)"
        )
    if fixes:
        angles = {o: float(np.degrees(rotation_angle(C))) for o, C in fixes.items()}
        listed = ", ".join(f"{o} {a:.0f} deg" for o, a in sorted(angles.items()))
        out.append(
            f"skeleton: the rest pose is not upright facing +x ({listed} off the body frames): "
            "re-referenced when retargeted (docs/motion.md, Rest poses)"
        )
    return out or ["skeleton: waist and rest pose as the retargeter expects"]


def run(args: argparse.Namespace) -> int:
    """Print the joints and the guessed map (or a template to fill); 0 if a bundled map fits."""
    from ..motion import load_motion
    from ..motion.keypoints import KeypointMapError, guess_keypoint_map

    motion = load_motion(args.motion)
    names = list(motion.names)
    try:
        kmap: KeypointMap | None = guess_keypoint_map(motion)
    except KeypointMapError:
        kmap = None
    if kmap is not None:
        guess = {kp: ", ".join(src.points) for kp, src in kmap.keypoints.items()}
        if args.template:
            print(template(names, guess), end="")
            return 0
        print(f"{args.motion}: {len(names)} joints/markers, {motion.duration:.2f} s at "
              f"{motion.rate:g} Hz\n  " + ", ".join(names))  # fmt: skip
        print(f"key-point map: {kmap.name} ({' '.join(kmap.description.split())})")
        for kp, src in guess.items():
            print(f"  {kp:16s} <- {src}")
        for line in conventions(motion, kmap):
            print(line)
        return 0
    like, guess = best_suggestion(names)
    if args.template:
        print(template(names, guess), end="")
        return 0
    print(f"{args.motion}: {len(names)} joints/markers; no bundled key-point map fits. The names "
          f"look most like the {like!r} map ({len(guess)} key-points guessed below). Check the "
          "template, save it and pass it with --keypoint-map FILE.yaml:\n")  # fmt: skip
    print(template(names, guess), end="")
    return 1
