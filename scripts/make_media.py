#!/usr/bin/env python3
# SPDX-License-Identifier: Apache-2.0
"""Make the README's media from a real clip: G1 retargeting CMU 29_03 (teapot arm gestures).

Writes docs/media/g1_teapot.gif (qpretarget render), docs/media/viewer.png (the browser viewer in
headless Chromium) and docs/media/viewer_config.png (`qpretarget view configs/g1_whole_body.yaml`).

    python scripts/make_media.py [--seconds 6]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from qpretarget.cli import main as cli

REPO = Path(__file__).resolve().parents[1]
CLIP = REPO.parent / "shared" / "data" / "mocap" / "cmu_29_03_teapot_arm_gestures.bvh"
OUT = REPO / "docs" / "media"


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--seconds", type=float, default=6.0)
    args = ap.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    run = OUT / "g1_teapot.npz"
    cfg = REPO / "configs" / "g1_whole_body.yaml"
    cli(["retarget", str(cfg), str(CLIP), "--end", str(args.seconds), "-o", str(run), "--quiet"])
    cli(["render", str(run), "-o", str(OUT / "g1_teapot.gif"), "--fps", "12", "--size", "480x360"])
    from qpretarget.commands.view import build_viewer
    from qpretarget.viz.screenshot import screenshot

    for src, name in ((run, "viewer.png"), (cfg, "viewer_config.png")):
        viewer = build_viewer(src, host="127.0.0.1", port=0)
        try:
            wait = ("Play / pause",) if src == run else ("constraints",)
            screenshot(viewer.url, OUT / name, wait_for=wait, settle=6.0, width=1100, height=700)
        finally:
            viewer.close()
    run.unlink()  # the run file is regenerated on demand; only images are kept
    print(f"wrote {sorted(p.name for p in OUT.iterdir())}")


if __name__ == "__main__":
    main()
