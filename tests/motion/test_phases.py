# SPDX-License-Identifier: Apache-2.0
"""Support phases on real clips and the Poubel 2014 Table I transition sequences."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from qpretarget.motion import Butterworth
from qpretarget.motion.keypoints import keypoint_positions
from qpretarget.motion.phases import (
    PhaseThresholds,
    SequencerSettings,
    SupportPhaseDetector,
    SupportSequencer,
    clamp_to_polygon,
    convex_hull,
    detect_support_phases,
    shrink_polygon,
)


def _phases(load_clip, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Phases of a clip with the pipeline's defaults: 7 Hz zero-phase Butterworth, then detection."""
    motion = load_clip(name)
    kp = keypoint_positions(motion, "cmu")
    bw = Butterworth(7.0, motion.rate)
    feet = {
        side: np.stack([bw.filtfilt(kp[f"{side}_ankle"]), bw.filtfilt(kp[f"{side}_toe"])], axis=1)
        for side in ("left", "right")
    }
    return motion.t, detect_support_phases(motion.t, feet["left"], feet["right"])


# Frames (1-based, as in the file) marked by hand from the foot heights and speeds of the clips:
# "left" = right foot in the air (standing on the left), mid-swing frames; "double" = one foot has
# landed (heel down, slowing under 0.3 m/s) and the other still has its toe on the ground.
WALK_16_15 = {
    31: "left", 97: "right", 163: "left", 235: "right", 301: "left", 379: "right", 451: "left",
    73: "double", 145: "double", 349: "double",
}  # fmt: skip
WALK_STOP_16_33 = {
    61: "right", 115: "left", 187: "right", 157: "double", 241: "double", 283: "double",
}  # fmt: skip


@pytest.mark.parametrize(
    ("clip", "marks"),
    [("cmu_16_15_walk.bvh", WALK_16_15), ("cmu_16_33_walk_stop.bvh", WALK_STOP_16_33)],
)
def test_walking_phases_match_hand_marks(load_clip, clip, marks):
    _, phases = _phases(load_clip, clip)
    found = {frame: str(phases[frame - 1]) for frame in marks}
    assert found == marks


def test_walk_alternates_single_supports_with_short_double_supports(load_clip):
    t, phases = _phases(load_clip, "cmu_16_15_walk.bvh")
    changes = [k for k in range(1, len(phases)) if phases[k] != phases[k - 1]]
    sequence = [str(phases[k]) for k in changes]
    # 3.9 s of walking at ~1.1 m/s: 7 single supports (3.5 strides), each after a double support.
    singles = [s for s in sequence if s != "double"]
    assert len(singles) == 7 and sequence[0] == "left"
    assert all(s == "double" for s in sequence[1::2])
    assert all(a != b for a, b in zip(singles, singles[1:], strict=False))  # alternating
    durations = np.diff([t[k] for k in changes] + [t[-1]])
    double = [d for d, s in zip(durations, sequence, strict=True) if s == "double"]
    assert all(0.05 < d < 0.25 for d in double)  # walking: ~0.1 s double support


@pytest.mark.parametrize("clip", ["cmu_02_06_bend_scoop_lift_arm.bvh", "cmu_14_37_drink_soda.bvh"])
def test_both_feet_down_all_along_gives_double_support_only(load_clip, clip):
    _, phases = _phases(load_clip, clip)
    assert set(phases.tolist()) == {"double"}


def test_one_leg_balance_is_left_support(load_clip):
    t, phases = _phases(load_clip, "cmu_49_18_one_leg_balance.bvh")
    # README: balances on the left leg with the right foot lifted (~0.35 m).
    assert np.mean(phases == "left") > 0.9
    assert phases[np.searchsorted(t, 5.0)] == "left"


def test_hysteresis_and_min_duration_stop_chatter():
    # Heights alone first (speed thresholds out of reach).
    th = PhaseThresholds(height_on=0.03, height_off=0.05, speed_on=50.0, speed_off=100.0,
                         min_duration=0.03)  # fmt: skip
    det = SupportPhaseDetector(th)
    dt = 0.01
    ground = np.zeros((1, 3))

    def right(h, x=0.0):
        return np.array([[x, 0.0, h]])

    assert det.update(0.0, ground, ground) == "double"
    # The right foot hovers between the two height thresholds: no change (hysteresis).
    for k in range(1, 20):
        assert det.update(k * dt, ground, right(0.04 + 0.009 * np.sin(k))) == "double"
    # A 20 ms excursion above height_off is shorter than min_duration: no change.
    det.update(0.20, ground, right(0.06))
    det.update(0.21, ground, right(0.06))
    assert det.update(0.22, ground, right(0.04)) == "double"
    # Lifted for good: single support on the left once min_duration has passed.
    phases = [det.update(0.23 + k * dt, ground, right(0.08)) for k in range(6)]
    assert phases[:3] == ["double"] * 3 and phases[-1] == "left"
    # Back between the thresholds: still lifted (hysteresis); below height_on: down again.
    assert det.update(0.30, ground, right(0.04)) == "left"
    phases = [det.update(0.31 + k * dt, ground, right(0.02)) for k in range(6)]
    assert phases[0] == "left" and phases[-1] == "double"

    # Speeds: a foot sliding in at 1 m/s, 1 cm above the ground, is not in support yet.
    det = SupportPhaseDetector(PhaseThresholds(min_duration=0.0))
    det.update(0.0, ground, ground)
    det.update(0.01, ground, right(0.08))  # lifted
    p = [det.update(0.01 + k * dt, ground, right(0.01, x=0.01 * k)) for k in range(1, 5)]
    assert p == ["left"] * 4  # 1 m/s > speed_on = 0.5 m/s
    assert det.update(0.06, ground, right(0.01, x=0.04)) == "double"  # stopped


def test_thresholds_are_validated():
    with pytest.raises(ValueError, match="hysteresis"):
        PhaseThresholds(height_on=0.05, height_off=0.03)
    with pytest.raises(ValueError, match="positive"):
        SequencerSettings(com_speed=0.0)


def test_polygon_helpers():
    square = convex_hull(np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5]]))
    assert len(square) == 4
    half = shrink_polygon(square, 0.1)
    assert np.allclose(clamp_to_polygon(np.array([0.5, 0.5]), half), [0.5, 0.5])
    assert np.allclose(clamp_to_polygon(np.array([2.0, 0.5]), half), [0.9, 0.5], atol=1e-9)
    assert np.allclose(clamp_to_polygon(np.array([-1.0, -1.0]), half), [0.1, 0.1], atol=1e-6)


# ------------------------------------------------------------------------------- sequences
SOLE = (-0.05, 0.12, -0.03, 0.03)  # G1 sole rectangle [m]


class _PerfectRobot:
    """Follows the sequencer's targets exactly (feet and CoM), to test the sequences alone."""

    def __init__(self) -> None:
        self.soles = {
            "left": pin.SE3(np.eye(3), np.array([0.0, 0.12, 0.0])),
            "right": pin.SE3(np.eye(3), np.array([0.0, -0.12, 0.0])),
        }
        self.com = np.array([0.035, 0.0])

    def apply(self, cmd) -> None:
        for side, pose in cmd.feet.items():
            self.soles[side] = pose.copy()
        self.com = cmd.com.copy()


def _run(phases_by_time, swing_right, *, t_end=3.0, dt=0.01):
    seq = SupportSequencer({"left": SOLE, "right": SOLE}, SequencerSettings(), dt=dt)
    robot = _PerfectRobot()
    seq.reset(0.0, robot.soles, robot.com)
    log = []
    for k in range(1, int(t_end / dt) + 1):
        t = k * dt
        phase = phases_by_time(t)
        swing = {"left": robot.soles["left"], "right": swing_right(t)}
        cmd = seq.update(t, phase, robot.soles, robot.com, swing)
        log.append((t, cmd))
        robot.apply(cmd)
    return seq, log, robot


def test_table_one_sequence_for_a_step_of_the_right_foot():
    """DS -> LS -> DS (Poubel 2014 Table I, mirrored): CoM to the left foot, lift the right
    foot flat, follow the person, lower it flat, CoM back between the feet."""

    def phase(t):
        return "left" if 0.5 <= t < 1.5 else "double"

    def swing(t):  # where the scaled person's right sole is: 10 cm forward at landing
        return pin.SE3(np.eye(3), np.array([0.1 * min(max(t - 0.5, 0) / 1.0, 1), -0.14, 0.05]))

    seq, log, robot = _run(phase, swing)
    states = [s for _, s in seq.log]
    assert states[:7] == ["double", "com_to_left", "lift_right", "left", "lower_right",
                          "com_to_middle", "double"]  # fmt: skip
    by_state = {}
    for t, cmd in log:
        by_state.setdefault(cmd.state, []).append((t, cmd))
    # 1. CoM to the support foot while both feet are down; the foot lifts only once it is there.
    assert all(c.contacts == ("left", "right") for _, c in by_state["com_to_left"])
    first_lift = by_state["lift_right"][0][1]
    assert first_lift.contacts == ("left",) and first_lift.switched
    left_center = np.array([0.035, 0.12])
    assert np.linalg.norm(by_state["com_to_left"][-1][1].com - left_center) < 1e-3
    # 2. The foot is lifted flat, straight up, to lift_height.
    lift = [c.feet["right"] for _, c in by_state["lift_right"]]
    assert all(np.allclose(p.rotation, np.eye(3)) for p in lift)
    assert all(abs(p.translation[0]) < 1e-12 for p in lift)
    assert by_state["left"][0][1].feet["right"].translation[2] >= 0.03 - 1e-9
    # 3. Lowered flat to the ground where the person put the foot (10 cm forward).
    landing = seq._foot.end  # the planned landing pose
    assert np.allclose(landing.rotation, np.eye(3))
    assert landing.translation[2] == 0.0
    assert landing.translation[0] == pytest.approx(0.1, abs=1e-6)
    assert all(np.allclose(c.feet["right"].rotation, np.eye(3)) for _, c in by_state["lower_right"])
    # The contact engages within land_tolerance of the ground and of the landing spot.
    assert 0.0 <= robot.soles["right"].translation[2] <= SequencerSettings().land_tolerance
    assert robot.soles["right"].translation[0] == pytest.approx(0.1, abs=1e-3)
    # 4. Contact again, then the CoM goes back to the middle of the new stance.
    assert by_state["com_to_middle"][0][1].contacts == ("left", "right")
    right_center = robot.soles["right"].translation[:2] + [0.035, 0.0]
    middle = 0.5 * (left_center + right_center)
    assert np.linalg.norm(log[-1][1].com - middle) < 1e-9


def test_an_abandoned_transfer_goes_back_to_the_middle():
    def phase(t):
        return "left" if 0.5 <= t < 0.6 else "double"  # lifted for 0.1 s only

    seq, log, _ = _run(phase, lambda t: pin.SE3(np.eye(3), np.array([0.0, -0.12, 0.05])))
    states = [s for _, s in seq.log]
    assert states == ["double", "com_to_left", "com_to_middle", "double"]
    assert all(cmd.contacts == ("left", "right") for _, cmd in log)  # never lifted


def test_landing_spot_is_kept_in_the_reachable_area():
    seq = SupportSequencer({"left": SOLE, "right": SOLE},
                           SequencerSettings(min_width=0.2, max_width=0.3, max_stride=0.15))  # fmt: skip
    seq.reset(0.0, {"left": pin.SE3(np.eye(3), np.array([0.0, 0.12, 0.0])),
                    "right": pin.SE3(np.eye(3), np.array([0.0, -0.12, 0.0]))}, [0, 0])  # fmt: skip
    for wanted, expected in [
        ([0.05, 0.05, 0.0], [0.05, -0.08, 0.0]),  # crossing the support foot: pushed out
        ([0.5, -0.12, 0.0], [0.15, -0.12, 0.0]),  # too far forward: shortened
        ([0.0, -0.6, 0.0], [0.0, -0.18, 0.0]),  # too wide
    ]:
        out = seq.clamp_swing("left", pin.SE3(np.eye(3), np.array(wanted)), clearance=0.0)
        assert np.allclose(out.translation, expected, atol=1e-12)
    twisted = pin.SE3(pin.exp3(np.array([0.3, 0.0, 1.5])), np.array([0.0, -0.12, -0.1]))
    out = seq.clamp_swing("left", twisted, clearance=0.03)
    assert np.allclose(out.rotation[:, 2], [0, 0, 1])  # flat
    assert out.translation[2] == pytest.approx(0.03)  # above the ground by the clearance
    yaw = np.arctan2(out.rotation[1, 0], out.rotation[0, 0])
    assert yaw == pytest.approx(SequencerSettings().max_yaw)
