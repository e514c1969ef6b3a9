# SPDX-License-Identifier: Apache-2.0
"""Mocap readers under corrupted files: truncations, bit flips, NaN/inf, wrong counts, garbage."""

from __future__ import annotations

import numpy as np
import pytest

from qpretarget import Controller
from qpretarget.motion import load_motion
from qpretarget.retarget import Retargeter

from .conftest import MOCAP, REPO, cut_frames, outcome

BVH = cut_frames((MOCAP / "cmu_16_33_walk_stop.bvh").read_text(), 60)
AMC_LINES = (MOCAP / "cmu_16_15.amc").read_text().splitlines()
AMC = "\n".join(AMC_LINES[: 3 + 30 * 30]) + "\n"  # header + ~30 frames
ASF = (MOCAP / "cmu_16.asf").read_text()
C3D = (MOCAP / "opensim_walking2.c3d").read_bytes()


@pytest.fixture(scope="module")
def controller() -> Controller:
    return Controller.from_yaml(REPO / "configs" / "g1_whole_body.yaml")


def _write(tmp_path, name: str, data: bytes | str):
    path = tmp_path / name
    if isinstance(data, str):
        path.write_text(data)
    else:
        path.write_bytes(data)
    if name.endswith(".amc"):
        (tmp_path / "cmu_16.asf").write_text(ASF)
    return path


def _check(path, controller) -> str:
    """Load; if it loads, a short retarget gives finite q or a documented error."""
    kind, motion = outcome(lambda: load_motion(path, **({"asf": path.parent / "cmu_16.asf"}
                                                        if path.suffix == ".amc" else {})))  # fmt: skip
    if kind == "error":
        return kind
    pos = np.asarray(motion.positions)
    assert not np.isinf(pos).any(), "a reader returned inf positions (must be NaN or an error)"
    kind, run = outcome(lambda: Retargeter(controller).retarget(motion.slice(0.0, 0.3)))
    if kind == "ok":
        assert np.all(np.isfinite(run.q)), "NaN in the retargeted output"
    return kind


def _truncations(data, rng, n=6):
    cuts = sorted(rng.integers(1, len(data) - 1, size=n))
    return [data[:c] for c in cuts]


def _flips(data: bytes, rng, n=6, bits=8):
    out = []
    for _ in range(n):
        b = bytearray(data)
        for i in rng.integers(0, len(b), size=bits):
            b[i] ^= 1 << int(rng.integers(0, 8))
        out.append(bytes(b))
    return out


@pytest.mark.parametrize("fmt", ["bvh", "amc", "c3d"])
def test_truncated_files(tmp_path, rng, controller, fmt):
    data = {"bvh": BVH.encode(), "amc": AMC.encode(), "c3d": C3D}[fmt]
    for k, cut in enumerate(_truncations(data, rng)):
        _check(_write(tmp_path, f"t{k}.{fmt}", cut), controller)


@pytest.mark.parametrize("fmt", ["bvh", "amc", "c3d"])
def test_bit_flips(tmp_path, rng, controller, fmt):
    data = {"bvh": BVH.encode(), "amc": AMC.encode(), "c3d": C3D}[fmt]
    for k, flipped in enumerate(_flips(data, rng)):
        _check(_write(tmp_path, f"f{k}.{fmt}", flipped), controller)


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "1e300"])
def test_non_finite_channels(tmp_path, controller, value):
    lines = BVH.splitlines()
    i = next(k for k, s in enumerate(lines) if s.startswith("Frame Time")) + 10
    vals = lines[i].split()
    vals[5] = value
    lines[i] = " ".join(vals)
    _check(_write(tmp_path, "n.bvh", "\n".join(lines) + "\n"), controller)
    amc = AMC.replace("\nroot ", f"\nroot {value} ", 1)
    _check(_write(tmp_path, "n.amc", amc), controller)


def test_wrong_channel_counts_zero_frames_huge_frame_time(tmp_path, controller):
    lines = BVH.splitlines()
    i = next(k for k, s in enumerate(lines) if s.startswith("Frame Time"))
    short = lines[: i + 1] + [" ".join(lines[i + 1].split()[:-3])] + lines[i + 2 :]
    assert _check(_write(tmp_path, "short.bvh", "\n".join(short)), controller) == "error"
    long = lines[: i + 1] + [lines[i + 1] + " 0 0 0"] + lines[i + 2 :]
    assert _check(_write(tmp_path, "long.bvh", "\n".join(long)), controller) == "error"
    assert _check(_write(tmp_path, "zero.bvh", cut_frames(BVH, 0)), controller) == "error"
    for t in ("1e30", "1e300", "inf", "nan"):
        huge = BVH.replace(lines[i], f"Frame Time: {t}")
        assert _check(_write(tmp_path, "huge.bvh", huge), controller) == "error", t
    neg = BVH.replace(lines[i], "Frame Time: -0.01")
    assert _check(_write(tmp_path, "neg.bvh", neg), controller) == "error"


def test_amc_wrong_counts_and_zero_frames(tmp_path, controller):
    """An AMC bone line with a value too few or too many, a header without frames, a frame number
    out of order: errors that name the line."""
    lines = AMC.splitlines()
    i = next(k for k, s in enumerate(lines) if s.startswith("root "))
    short = lines.copy()
    short[i] = " ".join(lines[i].split()[:-1])
    assert _check(_write(tmp_path, "short.amc", "\n".join(short) + "\n"), controller) == "error"
    long = lines.copy()
    long[i] = lines[i] + " 0.5"
    assert _check(_write(tmp_path, "long.amc", "\n".join(long) + "\n"), controller) == "error"
    header = "\n".join(lines[: i - 1]) + "\n"
    assert _check(_write(tmp_path, "zero.amc", header), controller) == "error"
    j = next(k for k in range(i + 1, len(lines)) if lines[k].strip().isdigit())
    order = lines.copy()
    order[j] = "7"
    assert _check(_write(tmp_path, "order.amc", "\n".join(order) + "\n"), controller) == "error"


def test_asf_truncated_and_flipped(tmp_path, rng, controller):
    """The skeleton file of an AMC clip, cut at random offsets and with random bit flips."""
    data = ASF.encode()
    amc = _write(tmp_path, "clip.amc", AMC)
    for k, bad in enumerate(_truncations(data, rng, n=4) + _flips(data, rng, n=4)):
        (tmp_path / "cmu_16.asf").write_bytes(bad)
        kind, motion = outcome(lambda: load_motion(amc, asf=tmp_path / "cmu_16.asf"))
        if kind == "ok":
            assert not np.isinf(np.asarray(motion.positions)).any(), k


@pytest.mark.parametrize("value", ["nan", "inf", "1e300"])
def test_non_finite_bvh_offsets(tmp_path, controller, value):
    """A NaN, inf or absurd bone offset in the hierarchy: an error or finite output, never NaN q."""
    i = BVH.index("OFFSET", BVH.index("OFFSET") + 1)
    j = BVH.index("\n", i)
    bad = BVH[:i] + f"OFFSET {value} 0 0" + BVH[j:]
    _check(_write(tmp_path, "off.bvh", bad), controller)


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf, 1e30])
def test_non_finite_c3d_points(tmp_path, rng, controller, value):
    """Float C3D (negative scale, Intel order): 200 random point coordinates of the data section
    overwritten with NaN, inf or 1e30; missing data or an error, never NaN/inf q."""
    import struct

    data = bytearray(C3D)
    assert struct.unpack("<f", data[12:16])[0] < 0  # float points
    start = (struct.unpack("<H", data[16:18])[0] - 1) * 512
    words = rng.integers(0, (len(data) - start) // 4, size=200)
    for w in words:
        data[start + 4 * w : start + 4 * w + 4] = struct.pack("<f", value)
    _check(_write(tmp_path, "nan.c3d", bytes(data)), controller)


@pytest.mark.parametrize("fmt", ["bvh", "amc", "c3d"])
def test_binary_garbage(tmp_path, rng, controller, fmt):
    garbage = rng.integers(0, 256, size=4096, dtype=np.uint8).tobytes()
    assert _check(_write(tmp_path, f"g.{fmt}", garbage), controller) == "error"
    assert _check(_write(tmp_path, f"e.{fmt}", b""), controller) == "error"
