# SPDX-License-Identifier: Apache-2.0
r"""Does the point-cloud fit's objective prefer the person's trunk heading? (docs/point_clouds.md)

The fourteenth round of docs/point_clouds.md asks, at a clip's worst frames, whether the trunk
heading the fit ends with is the objective's choice or the search's. At each frame named by
``--at``, after the shipped fit of the frame, the frame is fitted again (the linear and
refinement stages, as a re-initialisation start, ``CloudRetargeter._trial``) from two starts:

* ``self``: the frame's own fit;
* ``person``: the fit with its floating base turned about the vertical by
  :math:`-\Delta\psi_{hip}` (its hip line then has the person's heading) and its waist
  (the first joint of ``em.reinit_yaw_reset``, else of ``em.reinit_at_limits``) twisted by
  :math:`-(\Delta\psi_{shoulder} - \Delta\psi_{hip})` (its shoulder line too),

where :math:`\Delta\psi` is the heading of the fit's line (left key-frame minus right, the
robot's ``keyframes``) minus the person's (the rendered human model's key-points). For each it
prints the start's and the refit's heading errors, the worst upper-arm error (the fit's own
shoulder-to-elbow key-frames against the person's) and the NLL of eq. 3 after the position
stages (each refit at its own sigma^2). A ``person`` refit that drifts back and ends with a
higher NLL than ``self`` is a heading the objective does not prefer: no start or yaw search
would keep it. Each probed frame is reached by a run of its own from the clip's start (the
refits change the QP solvers' warm starts, so a later frame of the same run would not be the
shipped run's).

    python scripts/cloud_heading.py                    # boxing, render and template seed 0
    python scripts/cloud_heading.py --at 58 60 80 82 --json heading.json
    python scripts/cloud_heading.py --clip reach --render-seed 1 --template-seed 1 --at 84 86
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from cloud_accuracy import CLIPS, ROOT, _config, _rendering  # noqa: E402

#: ``--at`` by default: boxing's worst frames (3 s, render seed 0, template seed 0).
BOXING_FRAMES = [48, 52, 54, 56, 58, 60, 62, 76, 78, 80, 82, 84]


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _heading(v: np.ndarray) -> float:
    return math.atan2(float(v[1]), float(v[0]))


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    c = float(a @ b) / max(float(np.linalg.norm(a) * np.linalg.norm(b)), 1e-12)
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))


class _Probe:
    """Heading and upper-arm errors of a fitted template pose against the rendered person."""

    def __init__(self, fitter: Any, poser: Any, human_q: np.ndarray) -> None:
        import pinocchio as pin

        self.pin, self.fitter, self.poser, self.human_q = pin, fitter, poser, human_q
        model = fitter.model
        keys = fitter.robot.keyframes
        names = ("shoulder", "elbow", "hip")
        self.frames = {
            f"{s}_{n}": model.getFrameId(keys[f"{s}_{n}"]) for s in ("left", "right") for n in names
        }
        self.data = model.createData()

    def errors(self, q: np.ndarray, frame: int) -> dict[str, float]:
        """Shoulder- and hip-line heading errors [rad] and the worst upper arm's [deg]."""
        self.pin.framesForwardKinematics(self.fitter.model, self.data, q)
        p = {k: self.data.oMf[f].translation.copy() for k, f in self.frames.items()}
        h = self.poser.model_keypoints(self.human_q[frame])

        def line(d: dict[str, np.ndarray], part: str) -> float:
            return _heading(d[f"left_{part}"] - d[f"right_{part}"])

        upper = max(
            _angle(p[f"{s}_elbow"] - p[f"{s}_shoulder"], h[f"{s}_elbow"] - h[f"{s}_shoulder"])
            for s in ("left", "right")
        )
        return {
            "shoulder": _wrap(line(p, "shoulder") - line(h, "shoulder")),
            "hip": _wrap(line(p, "hip") - line(h, "hip")),
            "upper_arm_deg": upper,
        }


def _turned(fitter: Any, q: np.ndarray, hip: float, twist: float, waist: int | None) -> np.ndarray:
    """``q`` with the base turned by ``-hip`` about the vertical and the waist by ``-twist``."""
    import pinocchio as pin

    out = q.copy()
    M = pin.XYZQUATToSE3(out[:7])
    c, s = math.cos(-hip), math.sin(-hip)
    Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    out[:7] = pin.SE3ToXYZQUAT(pin.SE3(Rz @ M.rotation, M.translation))
    if waist is not None:
        out[waist] = np.clip(out[waist] - twist, fitter.q_min[waist], fitter.q_max[waist])
    return out


def probe(
    clip: str, frames: int, render_seed: int, template_seed: int, config: Path, at: list[int],
    cache: Path, sets: list[str] | None = None,
) -> list[dict[str, Any]]:  # fmt: skip
    """Run the shipped fit of ``clip`` and refit the frames ``at`` from ``self`` and ``person``."""
    import qpretarget as qp
    from qpretarget.cloud.config import CloudConfig
    from qpretarget.cloud.em import CloudRetargeter
    from qpretarget.cloud.io import read_cloud_sequence
    from qpretarget.cloud.poser import HumanPoser

    seq = read_cloud_sequence(_rendering(clip, frames, render_seed, cache))
    bad = [k for k in at if not 0 < k < len(seq.frames)]
    if bad:
        raise SystemExit(f"--at {bad}: frames must lie in 1..{len(seq.frames) - 1}.")
    cfg = CloudConfig.from_dict(_config(config, sets or [], template_seed))
    robot = qp.load_robot(cfg.robot)
    poser, human_q = HumanPoser(), seq.meta["human_q"]
    rows: list[dict[str, Any]] = []
    for k in sorted(set(at)):
        # A fresh fitter per probed frame, run up to it: the refits change the QP solvers'
        # warm starts, so the frames after a probed one would not be the shipped run's.
        fitter = CloudRetargeter(cfg, robot=robot)
        fitter.fit = _probing(fitter, k, _Probe(fitter, poser, human_q), rows)  # type: ignore[method-assign]
        try:
            fitter.run(seq)
        except _Done:
            pass
    return rows


class _Done(Exception):
    """Raised after the probed frame: the run goes no further."""


def _probing(fitter: Any, k: int, probe_: _Probe, rows: list[dict[str, Any]]) -> Any:
    """``fitter.fit``, refitting frame ``k`` from ``self`` and ``person`` after its fit."""
    cfg, fit_frame = fitter.config, fitter.fit
    waist_names = list(cfg.em.reinit_yaw_reset) or list(cfg.em.reinit_at_limits)
    waist = None
    if waist_names:
        waist = fitter.model.joints[fitter.model.getJointId(waist_names[0])].idx_q

    def fit(frame: Any, *, index: int = 0) -> Any:
        res = fit_frame(frame, index=index)
        if index != k:
            return res
        S, Sn = fitter._frame_cloud, fitter._frame_normals
        e = probe_.errors(res.q_fit, index)
        row: dict[str, Any] = {"frame": index, "fit": _degrees(e), "fit_nll": res.nll}
        starts = {
            "self": res.q_fit,
            "person": _turned(fitter, res.q_fit, e["hip"], e["shoulder"] - e["hip"], waist),
        }
        for name, q0 in starts.items():
            q_start, q_prev = fitter._reinit_start(q0)
            q, _, nll = fitter._trial(S, Sn, q_start, q_prev, [], f"probe-{name}-")
            row[name] = {
                "start": _degrees(probe_.errors(q_start, index)),
                "end": _degrees(probe_.errors(q, index)),
                "nll": nll,
            }
        rows.append(row)
        _print(row)
        raise _Done

    return fit


def _degrees(e: dict[str, float]) -> dict[str, float]:
    return {
        "shoulder_deg": math.degrees(e["shoulder"]),
        "hip_deg": math.degrees(e["hip"]),
        "upper_arm_deg": e["upper_arm_deg"],
    }


def _print(row: dict[str, Any]) -> None:
    def txt(e: dict[str, float]) -> str:
        return f"shoulder {e['shoulder_deg']:+6.1f} hip {e['hip_deg']:+6.1f}"

    f = row["fit"]
    print(f"frame {row['frame']:3d}  fit: {txt(f)} upper arm {f['upper_arm_deg']:5.1f} deg")
    for name in ("self", "person"):
        r = row[name]
        print(
            f"  from {name:6s} {txt(r['start'])} -> {txt(r['end'])}, upper arm "
            f"{r['end']['upper_arm_deg']:5.1f} deg, NLL {r['nll']:10.1f}"
        )
    d = row["person"]["nll"] - row["self"]["nll"]
    note = "  (the fit's heading preferred)" if d > 0 else ""
    print(f"  NLL(person) - NLL(self) = {d:+.1f} nats{note}")


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--clip", default="boxing", help=f"short name ({', '.join(CLIPS)}) or path")
    ap.add_argument("--frames", type=int, default=90, help="clip frames at 30 Hz (default 90)")
    ap.add_argument("--render-seed", type=int, default=0)
    ap.add_argument("--template-seed", type=int, default=0)
    ap.add_argument("--config", type=Path, default=ROOT / "configs" / "cloud_g1.yaml")
    ap.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                    help="override a config key (dotted path, YAML value); repeatable")  # fmt: skip
    ap.add_argument("--at", type=int, nargs="+", default=BOXING_FRAMES,
                    help="frames to refit (default: boxing's worst)")  # fmt: skip
    ap.add_argument("--cache", type=Path, default=Path.home() / ".cache" / "qpretarget" / "clouds",
                    help="renderings shared with scripts/cloud_accuracy.py")  # fmt: skip
    ap.add_argument("--json", type=Path, help="write the rows here")
    args = ap.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)
    rows = probe(
        args.clip, args.frames, args.render_seed, args.template_seed, args.config, args.at,
        args.cache, args.sets,
    )  # fmt: skip
    if args.json:
        from qpretarget.fileio import write_atomic

        text = json.dumps({"clip": args.clip, "rows": rows}, indent=1)
        write_atomic(args.json, lambda f: f.write(text), binary=False)
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
