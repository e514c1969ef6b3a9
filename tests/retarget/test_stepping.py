# SPDX-License-Identifier: Apache-2.0
"""Kinematic stepping (retarget/stepping.py) and the shipped G1 whole-body config on real clips.

The clip tests run configs/g1_whole_body.yaml (kinematic balance mode) on the shared CMU clips and
assert the figures of issue 15 that it reaches, measured by analysis/human_metrics.py (the same
numbers as ``qpretarget evaluate``); docs/retargeting.md has the table of every figure.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yaml

from qpretarget import Controller
from qpretarget.analysis.human_metrics import human_metrics
from qpretarget.motion import load_motion
from qpretarget.motion.human_motion import HumanMotion
from qpretarget.retarget import Retargeter
from qpretarget.retarget.stepping import KinematicStepper, StepSettings

REPO = Path(__file__).resolve().parents[2]
MOCAP = REPO.parent / "shared" / "data" / "mocap"
CONFIG = REPO / "configs" / "g1_whole_body.yaml"


def _flat(x: float, y: float, z: float, yaw: float = 0.0) -> pin.SE3:
    c, s = math.cos(yaw), math.sin(yaw)
    return pin.SE3(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), np.array([x, y, z]))


# ------------------------------------------------------------------------------ unit (synthetic)
def test_a_lifted_human_foot_releases_its_contact_and_lands_where_the_person_did():
    st = KinematicStepper(StepSettings(), dt=0.01)
    soles = {"left": _flat(0, 0.1, 0), "right": _flat(0, -0.1, 0)}
    up = {"left": True, "right": False}
    desired = {"left": soles["left"], "right": _flat(0.2, -0.1, 0.08)}
    cmd = st.update(0.0, {"left": True, "right": True}, soles, desired, {})
    assert cmd.contacts == ("left", "right")
    cmd = st.update(0.1, up, soles, desired, {})
    assert cmd.switched and cmd.contacts == ("left",) and cmd.states["right"] == "swing"
    # The swing target starts where the sole left the ground (lift blend) ...
    assert np.allclose(cmd.feet["right"].translation, [0, -0.1, 0.0])
    cmd = st.update(0.25, up, soles, desired, {})
    assert np.allclose(cmd.feet["right"].translation, [0.2, -0.1, 0.08])  # ... then follows
    # The person puts the foot down: the sole goes down over the spot, contact once on the floor.
    soles["right"] = _flat(0.2, -0.1, 0.08)
    cmd = st.update(0.3, {"left": True, "right": True}, soles, desired, {})
    assert cmd.states["right"] == "landing" and cmd.contacts == ("left",)
    assert cmd.feet["right"].translation[2] < 0.08  # descending at most land_speed
    soles["right"] = _flat(0.2, -0.1, 0.001)
    cmd = st.update(0.4, {"left": True, "right": True}, soles, desired, {})
    assert cmd.switched and cmd.contacts == ("left", "right")
    assert cmd.anchors["right"].translation[2] == 0.0  # anchored flat on the ground


def test_a_foot_waits_for_the_other_to_stand_and_flight_releases_both():
    st = KinematicStepper(StepSettings(), dt=0.01)
    soles = {"left": _flat(0, 0.1, 0), "right": _flat(0, -0.1, 0.05)}
    st.update(0.0, {"left": True, "right": True}, soles, soles, {})
    st.update(0.1, {"left": True, "right": False}, soles, soles, {})  # right lifts
    # The person stands on the right again and lifts the left before the robot's right landed:
    cmd = st.update(0.11, {"left": False, "right": True}, soles, soles, {})
    assert cmd.contacts == ("left",)  # the left waits (the robot never drops both feet) ...
    # ... unless the person is in flight: both feet up.
    cmd = st.update(0.2, {"left": False, "right": False}, soles, soles, {})
    assert cmd.contacts == () and set(cmd.states.values()) == {"swing"}


def test_a_pivoting_stance_foot_turns_its_anchor_at_the_pivot_rate():
    settings = StepSettings()
    st = KinematicStepper(settings, dt=0.01)
    soles = {"left": _flat(0, 0.1, 0), "right": _flat(0, -0.1, 0)}
    foot = {
        "left": (math.radians(25.0), np.array([0.0, 0.1, 0.08])),
        "right": (math.radians(25.0), np.array([0, -0.1, 0.08])),
    }
    st.update(0.0, {"left": True, "right": True}, soles, soles, foot)
    # The person lifts the right foot (pivots happen in single support only) ...
    one = {"left": True, "right": False}
    assert st.update(0.1, one, soles, soles, foot).states["right"] == "swing"
    # ... and turns on the left foot by 40 deg without moving it: a pivot.
    # (The pivot aims at the sole yaw the person's foot asks for, in the robot's frame: the
    # swing target's, ``desired``; the foot's own yaw is in the capture's frame, only its
    # change counts. The capture here is turned by 25 deg against the robot's frame.)
    foot["left"] = (math.radians(40.0 + 25.0), np.array([0.005, 0.1, 0.08]))
    asked = {"left": _flat(0, 0.1, 0, math.radians(40.0)), "right": soles["right"]}
    yaws = []
    for k in range(11, 50):
        cmd = st.update(0.01 * k, one, soles, asked, foot)
        if "left" in cmd.anchors:
            R = cmd.anchors["left"].rotation
            yaws.append(math.atan2(R[1, 0], R[0, 0]))
            assert np.allclose(cmd.anchors["left"].translation, [0, 0.1, 0])  # in place
    steps = np.diff([0.0, *yaws])
    assert np.all(steps <= settings.pivot_rate * 0.01 + 1e-12)  # ramped
    assert yaws[-1] == pytest.approx(math.radians(40.0), abs=1e-9)
    # A turn under pivot_yaw (15 deg) moves nothing.
    st2 = KinematicStepper(settings, dt=0.01)
    foot2 = {"left": (0.0, np.array([0.0, 0.1, 0.08])), "right": None}
    st2.update(0.0, {"left": True, "right": True}, soles, soles, foot2)
    foot2["left"] = (math.radians(10.0), np.array([0.0, 0.1, 0.08]))
    assert (
        "left" not in st2.update(0.01, {"left": True, "right": True}, soles, soles, foot2).anchors
    )
    # With both feet standing a turn past pivot_yaw_double (30 deg; 40 here, on the ball of the
    # foot) pivots too, to the person's foot yaw, one foot at a time ...
    both = {"left": True, "right": True}
    st4 = KinematicStepper(settings, dt=0.01)
    foot4 = {"left": (0.0, np.array([0.0, 0.1, 0.08])), "right": None}
    st4.update(0.0, both, soles, soles, foot4)
    foot4["left"] = (math.radians(40.0), np.array([0.0, 0.1, 0.08]))
    asked4 = {"left": _flat(0, 0.1, 0, math.radians(40.0)), "right": soles["right"]}
    turned = [
        st4.update(0.01 * k, both, soles, asked4, foot4).anchors.get("left") for k in range(1, 60)
    ]
    last = [a for a in turned if a is not None][-1]
    assert math.atan2(last.rotation[1, 0], last.rotation[0, 0]) == pytest.approx(
        math.radians(40.0), abs=1e-9
    )
    # ... but not under it (25 deg), nor with pivot_double: false, nor under a kick (the other
    # foot's target 0.5 m up), nor with pivot: false.
    kick = {"left": soles["left"], "right": _flat(0.3, -0.1, 0.5)}
    for settings3, support, desired3, turn in (
        (settings, both, soles, 25.0),
        (StepSettings(pivot_double=False), both, soles, 40.0),
        (settings, one, kick, 40.0),
        (StepSettings(pivot=False), one, soles, 40.0),
    ):
        st3 = KinematicStepper(settings3, dt=0.01)
        foot3 = {"left": (0.0, np.array([0.0, 0.1, 0.08])), "right": None}
        st3.update(0.0, both, soles, soles, foot3)
        st3.update(0.05, support, soles, desired3, foot3)  # the right lifted (or not) first
        foot3["left"] = (math.radians(turn), np.array([0.0, 0.1, 0.08]))
        for k in range(10, 50):
            assert "left" not in st3.update(0.01 * k, support, soles, desired3, foot3).anchors


def test_a_started_pivot_follows_the_foot_yaw_even_when_the_foot_then_slides():
    """Once a pivot has started (the foot in place), it goes on to the person's foot yaw even
    when the person's foot then moves beyond ``pivot_radius``; a turn whose foot has already
    moved does not start one."""
    settings = StepSettings()
    soles = {"left": _flat(0, 0.1, 0), "right": _flat(0, -0.1, 0)}
    one = {"left": True, "right": False}

    def run(path: list[tuple[float, float]]) -> float | None:
        """Yaw of the left anchor after the person's left foot goes through ``path`` (deg, m)."""
        st = KinematicStepper(settings, dt=0.01)
        foot = {"left": (0.0, np.array([0.0, 0.1, 0.08])), "right": None}
        st.update(0.0, {"left": True, "right": True}, soles, soles, foot)
        st.update(0.1, one, soles, soles, foot)  # the right foot lifts
        last = None
        for k, (deg, dx) in enumerate(path):
            foot["left"] = (math.radians(deg), np.array([dx, 0.1, 0.08]))
            asked = {"left": _flat(dx, 0.1, 0, math.radians(deg)), "right": soles["right"]}
            a = st.update(0.11 + 0.01 * k, one, soles, asked, foot).anchors.get("left")
            if a is not None:
                assert np.allclose(a.translation, [0, 0.1, 0])  # it turns in place
                last = math.degrees(math.atan2(a.rotation[1, 0], a.rotation[0, 0]))
        return last

    # 20 deg in place starts the pivot; then the foot slides 10 cm (> pivot_radius, 3 cm) while
    # turning on to 90 deg: the anchor gets there (before stop 36 it stopped at the slide).
    start = [(2.0 * k, 0.0) for k in range(11)]  # 0 -> 20 deg in place
    slide = [(20.0 + 7.0 * k, 0.01 * k) for k in range(1, 11)]  # to 90 deg, 10 cm away
    hold = [(90.0, 0.1)] * 60
    assert run(start + slide + hold) == pytest.approx(90.0, abs=1e-6)
    # The foot moves 10 cm before its turn reaches pivot_yaw: no pivot at all.
    moved = [(1.0 * k, 0.01 * k) for k in range(11)]  # 10 deg, 10 cm
    assert run(moved + [(10.0 + 8.0 * k, 0.1) for k in range(1, 11)] + hold) is None


def test_a_pivot_lagging_by_more_than_half_a_turn_goes_on_the_way_the_body_turns():
    """A pivot turns its sole the way that keeps it within half a turn of the body's heading
    (``base_yaw``), not the shorter way from where the sole is: once a sole lagged a fast turn
    by more than 180 deg the shorter way went back, the hip reached its yaw limit and turned
    the body back (DeepMimic's dance: 157 deg off)."""
    soles = {"left": _flat(0, 0.1, 0), "right": _flat(0, -0.1, 0)}
    one = {"left": True, "right": False}

    def path(base: bool) -> np.ndarray:
        """Unwrapped yaws [deg] of the left anchor while the person turns 250 deg in 0.1 s."""
        st = KinematicStepper(StepSettings(), dt=0.01)
        foot = {"left": (0.0, np.array([0.0, 0.1, 0.08])), "right": None}
        st.update(0.0, {"left": True, "right": True}, soles, soles, foot)
        st.update(0.1, one, soles, soles, foot)  # the right foot lifts
        yaws = [0.0]
        for k in range(1, 120):
            deg = min(250.0, 25.0 * k)  # the person's foot and body turn 2500 deg/s to 250 deg
            psi = math.radians(deg)
            foot["left"] = (psi, np.array([0.0, 0.1, 0.08]))
            asked = {"left": _flat(0, 0.1, 0, psi), "right": soles["right"]}
            # The robot's body follows, at most 150 deg ahead of its sole (G1's hip yaw: 158).
            body = math.radians(min(deg, yaws[-1] + 150.0))
            cmd = st.update(
                0.1 + 0.01 * k, one, soles, asked, foot, base_yaw=body if base else None
            )
            a = cmd.anchors.get("left")
            if a is not None:
                y = math.degrees(math.atan2(a.rotation[1, 0], a.rotation[0, 0]))
                yaws.append(yaws[-1] + (y - yaws[-1] + 180.0) % 360.0 - 180.0)
        return np.array(yaws)

    with_base = path(True)
    up = int(np.argmax(with_base >= 240.0))
    assert up > 0 and np.all(np.diff(with_base[: up + 1]) >= 0.0)  # the way the body turns
    # The ramped yaw rate overshoots its goal by at most 2 deg (pivot_accel's discretization).
    assert with_base.max() < 252.0 and with_base[-1] == pytest.approx(250.0, abs=1e-6)
    without = path(False)  # the shorter way once the lag passed 180 deg: back to -110 deg
    assert without[-1] == pytest.approx(-110.0, abs=1e-6) and without.min() < 0.0


@pytest.mark.parametrize("height, key", [(0.05, "swing_yaw_rate_floor"), (0.15, "swing_yaw_rate")])
def test_a_swing_sole_turns_at_most_swing_yaw_rate(height, key):
    # A foot lifted 170 deg from the person's foot yaw (left behind while the person turned on
    # both feet): its yaw target turns by at most the rate of its height a tick (8 rad/s up to
    # 5 cm over the floor, 12 from 10 cm), pitch and roll flat.
    settings = StepSettings()
    st = KinematicStepper(settings, dt=0.01)
    soles = {"left": _flat(0, 0.1, 0), "right": _flat(0, -0.1, 0)}
    st.update(0.0, {"left": True, "right": True}, soles, soles, {})
    desired = {"left": soles["left"], "right": _flat(0.0, -0.1, height, math.radians(170.0))}
    one = {"left": True, "right": False}
    yaws = []
    for k in range(10, 80):
        R = st.update(0.01 * k, one, soles, desired, {}).feet["right"].rotation
        yaws.append(math.atan2(R[1, 0], R[0, 0]))
        assert R[2, 2] == pytest.approx(1.0, abs=1e-12)  # flat: the turn is about the vertical
    steps = np.abs(np.diff(np.unwrap(yaws)))
    rate = getattr(settings, key)
    # 1e-12: round-off; the lift blend (0.1 s) itself stays under the rate at its start only.
    assert steps.max() <= rate * 0.01 + 1e-12
    assert steps.max() >= rate * 0.01 - 1e-9  # the limit binds: 170 deg is a fast turn
    assert yaws[-1] == pytest.approx(math.radians(170.0), abs=1e-9)  # reached in the end
    with pytest.raises(ValueError, match=key):
        StepSettings(**{key: 0.0})


def test_the_flight_starts_from_the_planted_foot_not_from_its_drift():
    # Rooting.takeoff_drift: the person's stance-foot travel since the robot foot's stance
    # began, scaled and aligned, less the robot ankle's own, horizontal, capped.
    rt = Retargeter(Controller.from_yaml(CONFIG))
    rt.retarget(load_motion(MOCAP / "cmu_16_15_walk.bvh").slice(0.0, 0.3))
    ro = rt._rooting
    assert ro is not None and ro.flight_drift == pytest.approx(0.15)  # the StepSettings default
    s = ro.leg_scale
    R = ro.calibration.rotation if ro.align is None else ro.align
    r0, h0 = np.array([0.1, 0.1, 0.05]), np.array([1.0, 2.0, 0.08])
    ro.planted, ro.standing_now = {}, {}
    ro.plant({"left": r0}, {"left_ankle": h0})
    d = np.array([0.04, -0.03, 0.02])  # the person's ankle swivels 5 cm (and rises 2 cm)
    ro.plant({"left": r0 + [0.01, 0.0, 0.0]}, {"left_ankle": h0 + d})  # keeps its first pair
    assert np.allclose(ro.planted["left"][0], r0) and np.allclose(ro.planted["left"][1], h0)
    c = ro.takeoff_drift({"left_ankle": h0 + d})
    want = s * (R @ d) - [0.01, 0.0, 0.0]
    want[2] = 0.0
    assert np.allclose(c, want, atol=1e-12)  # 1e-12: round-off
    ro.flight_drift = 0.01  # capped
    assert np.linalg.norm(ro.takeoff_drift({"left_ankle": h0 + d})) == pytest.approx(0.01)
    ro.flight_drift = 0.0  # off
    assert np.all(ro.takeoff_drift({"left_ankle": h0 + d}) == 0.0)
    ro.flight_drift = 0.15
    assert np.all(ro.takeoff_drift({}) == 0.0)  # the person's ankle unknown: no correction
    ro.plant({}, {"left_ankle": h0 + d})  # the foot lifted: forgotten
    assert ro.planted == {} and np.all(ro.takeoff_drift({"left_ankle": h0 + d}) == 0.0)
    with pytest.raises(ValueError, match="flight_drift"):
        StepSettings(flight_drift=0.0)


def test_the_start_width_range_is_validated():
    assert StepSettings(initial_width_min=1.0, initial_width_max=1.0).initial_width_min == 1.0
    with pytest.raises(ValueError, match="initial_width_min must not exceed initial_width_max"):
        StepSettings(initial_width_min=1.2, initial_width_max=1.0)
    with pytest.raises(ValueError, match="initial_width_min"):
        StepSettings(initial_width_min=0.0)


def test_a_rising_heel_rolls_the_stance_sole_onto_its_toes_about_the_front_edge():
    # Sole rectangle front edge 0.12 m ahead of the sole origin, ankle 0.04 m above it.
    toes = {s: (0.12, np.array([0.0, 0.0, 0.04])) for s in ("left", "right")}
    settings = StepSettings()
    st = KinematicStepper(settings, dt=0.01, toes=toes)
    soles = {"left": _flat(0, 0.1, 0), "right": _flat(0, -0.1, 0)}
    both = {"left": True, "right": True}
    st.update(0.0, both, soles, soles, {}, toe_rise={"left": 0.0, "right": 0.0})
    # The person's right heel rises 4 cm (scaled) while both feet are in support: toe-off.
    cmd = st.update(0.1, both, soles, soles, {}, toe_rise={"left": 0.0, "right": 0.04})
    assert cmd.states["right"] == "toe_off" and cmd.contacts == ("left",) and cmd.switched
    M = cmd.feet["right"]
    edge = M.act(np.array([0.12, 0.0, 0.0]))
    assert np.allclose(edge, [0.12, -0.1, 0.0], atol=1e-12)  # the front edge stays put
    ankle = M.act(toes["right"][1])
    assert ankle[2] - 0.04 == pytest.approx(0.04, abs=1e-9)  # the ankle rises as the person's
    # The heel comes down: the target goes flat, contact again once the sole is flat.
    rolled = {"left": soles["left"], "right": M}
    cmd = st.update(0.2, both, rolled, soles, {}, toe_rise={"left": 0.0, "right": 0.0})
    assert cmd.states["right"] == "toe_off" and np.allclose(cmd.feet["right"].rotation, np.eye(3))
    cmd = st.update(0.21, both, soles, soles, {}, toe_rise={"left": 0.0, "right": 0.0})
    assert cmd.states["right"] == "stance" and cmd.contacts == ("left", "right")
    # A heel held up longer than toe_time (on the ball of the foot) is put down again, and does
    # not roll again before the person's heel has been down.
    st.update(0.25, both, soles, soles, {}, toe_rise={"left": 0.0, "right": 0.0})
    rise = {"left": 0.0, "right": 0.04}
    states = []
    for k in range(30, 90):
        pose = st.update(0.01 * k, both, soles, soles, {}, toe_rise=rise).feet["right"]
        states.append(st.states["right"])
        soles["right"] = pose  # the sole follows its target
    rolled_for = 0.01 * states.count("toe_off")
    assert settings.toe_time <= rolled_for <= settings.toe_time + 0.03
    assert states[-1] == "stance" and np.allclose(soles["right"].rotation, np.eye(3))
    # No toe-off (contact off) while the other foot does not stand (the robot keeps a foot on
    # the ground; with `tiptoe` the sole rolls with its contact kept instead, next test).
    st2 = KinematicStepper(StepSettings(tiptoe=False), dt=0.01, toes=toes)
    st2.update(0.0, both, soles, soles, {}, toe_rise={"left": 0.0, "right": 0.0})
    st2.update(0.1, {"left": False, "right": True}, soles, soles, {})  # left swings
    cmd = st2.update(0.2, {"left": False, "right": True}, soles, soles, {}, toe_rise=rise)
    assert cmd.states == {"left": "swing", "right": "stance"}


def test_a_toe_off_turning_on_the_ball_of_the_foot_turns_its_sole_about_the_front_edge():
    """The person turns the foot 40 deg on its ball while the heel is up (toe-off): once past
    pivot_yaw the anchor turns after it, at most pivot_rate a tick, about the middle of the
    sole's front edge, and the sole goes down flat there (its ankle moved round the ball, as the
    person's). Under pivot_yaw nothing turns (a walk's push-off)."""
    toes = {s: (0.12, np.array([0.0, 0.0, 0.04])) for s in ("left", "right")}
    settings = StepSettings()

    def run(turn_deg: float) -> tuple[pin.SE3, list[float]]:
        st = KinematicStepper(settings, dt=0.01, toes=toes)
        soles = {"left": _flat(0, 0.1, 0), "right": _flat(0, -0.1, 0)}
        both = {"left": True, "right": True}
        flat = {"left": 0.0, "right": 0.0}
        foot = {"left": None, "right": (0.0, np.array([0.0, -0.1, 0.04]))}
        st.update(0.0, both, soles, soles, foot, toe_rise=flat)
        rise = {"left": 0.0, "right": 0.04}
        assert st.update(0.1, both, soles, soles, foot, toe_rise=rise).states["right"] == "toe_off"
        yaws = []
        for k in range(1, 31):  # 0.3 s, under toe_time: the heel stays up
            psi = math.radians(turn_deg) * min(1.0, (k - 1) / 20)
            foot["right"] = (psi, np.array([0.0, -0.1, 0.04]))
            cmd = st.update(0.1 + 0.01 * k, both, soles, soles, foot, toe_rise=rise)
            assert cmd.states["right"] == "toe_off"
            yaws.append(math.degrees(_yaw_of_se3(st._anchor["right"])))
            soles["right"] = cmd.feet["right"]
        return st._anchor["right"], yaws

    anchor, yaws = run(40.0)
    assert yaws[-1] == pytest.approx(40.0, abs=1e-6)
    lim = math.degrees(settings.pivot_rate * 0.01)
    assert np.all(np.abs(np.diff(yaws)) <= lim + 1e-9)
    # The middle of the front edge stayed where it was: (0.12, -0.1) on the floor.
    ball = anchor.act(np.array([0.12, 0.0, 0.0]))
    np.testing.assert_allclose(ball, [0.12, -0.1, 0.0], atol=1e-12)
    assert np.linalg.norm(anchor.translation[:2] - [0.0, -0.1]) > 0.08  # the ankle swung round
    small, yaws = run(10.0)  # under pivot_yaw (15 deg): no turn
    assert max(abs(y) for y in yaws) == 0.0
    np.testing.assert_allclose(small.translation, [0.0, -0.1, 0.0], atol=1e-12)


def _yaw_of_se3(M: pin.SE3) -> float:
    return math.atan2(M.rotation[1, 0], M.rotation[0, 0])


def test_the_no_crossing_floor_falls_with_the_fore_aft_distance():
    """FootTargets.crossing_floor: 70 % of the reference width while the soles side by side
    would overlap (fore-aft up to a sole length), 0 from two sole lengths (in line, never
    crossed); uncrossed pushes a crossed ankle to it along the hip line. The karate kata's front
    stance (feet crossed 4 cm, 70 cm apart) was put 15 cm beside the person's."""
    from types import SimpleNamespace

    from qpretarget.retarget.feet import FootTargets

    feet = SimpleNamespace(
        sole_rectangles={"left": (-0.05, 0.12, -0.03, 0.03), "right": (-0.05, 0.12, -0.03, 0.03)},
        ankle_of=lambda side, sole: sole.translation.copy(),
    )
    ft = FootTargets(feet, SimpleNamespace(), 1.0, {}, 0.97)  # type: ignore[arg-type]
    ft.width_r = 0.2
    assert ft.sole_length == pytest.approx(0.17)
    for f, floor in ((0.0, 0.14), (0.17, 0.14), (-0.255, 0.07), (0.34, 0.0), (1.0, 0.0)):
        assert ft.crossing_floor(f) == pytest.approx(floor, abs=1e-12)
    hips = (np.array([0.0, 0.1, 0.9]), np.array([0.0, -0.1, 0.9]))  # facing +x
    stance = _flat(0.0, 0.0, 0.0)  # the right ankle at the origin
    far = ft.uncrossed("left", np.array([0.7, -0.04, 0.0]), stance, hips)
    np.testing.assert_allclose(far, [0.7, 0.0, 0.0], atol=1e-12)  # in line, not crossed
    near = ft.uncrossed("left", np.array([0.1, -0.04, 0.0]), stance, hips)
    np.testing.assert_allclose(near, [0.1, 0.14, 0.0], atol=1e-12)  # 70 % of the width
    wide = np.array([0.7, 0.25, 0.0])
    np.testing.assert_allclose(ft.uncrossed("left", wide, stance, hips), wide)  # untouched
    ft.inline = False  # stepping.inline_feet: false (Talos): 70 % at any distance
    assert ft.crossing_floor(1.0) == pytest.approx(0.14, abs=1e-12)
    np.testing.assert_allclose(
        ft.uncrossed("left", np.array([0.7, -0.04, 0.0]), stance, hips), [0.7, 0.14, 0.0]
    )


def test_both_heels_rising_roll_both_soles_onto_their_toes_with_the_contacts_kept():
    toes = {s: (0.12, np.array([0.0, 0.0, 0.04])) for s in ("left", "right")}
    settings = StepSettings()
    st = KinematicStepper(settings, dt=0.01, toes=toes)
    soles = {"left": _flat(0, 0.1, 0), "right": _flat(0, -0.1, 0)}
    both = {"left": True, "right": True}
    flat = {"left": 0.0, "right": 0.0}
    st.update(0.0, both, soles, soles, {}, toe_rise=flat)
    # Both heels rise 4 cm (scaled): both soles roll, their contacts stay on, each anchor a
    # moving anchor turned about the sole's front edge, the pitch ramped from 0, held as long as
    # the person stands on the toes (0.5 s here, longer than a toe-off's toe_time).
    up = {"left": 0.04, "right": 0.04}
    pitches, edges = [], []
    assert settings.toe_time < 0.5
    for k in range(10, 60):
        cmd = st.update(0.01 * k, both, soles, soles, {}, toe_rise=up)
        assert cmd.states == {"left": "tiptoe", "right": "tiptoe"}
        assert cmd.contacts == ("left", "right") and st.rolled == ("left", "right")
        for side in ("left", "right"):
            M = cmd.feet[side]
            if side in cmd.anchors:
                assert side in cmd.pivoting  # fed forward by the contact rows
                assert np.allclose(cmd.anchors[side].homogeneous, M.homogeneous)
            edge = np.array([0.12, 0.05, 0.0])
            edges.append(M.act(edge) - soles[side].act(edge))
        R = cmd.feet["left"].rotation
        pitches.append(math.atan2(R[0, 2], R[2, 2]))
    assert np.abs(edges).max() < 1e-12  # the front edges stay where they stood
    rate = np.diff([0.0, *pitches]) / 0.01
    assert np.all(np.abs(rate) <= settings.tiptoe_rate + 1e-9)
    assert np.all(np.abs(np.diff([0.0, *rate])) <= settings.tiptoe_accel * 0.01 + 1e-6)
    ankle = cmd.feet["left"].act(toes["left"][1])
    assert ankle[2] - 0.04 == pytest.approx(0.04, abs=1e-9)  # the ankle rose as the person's
    # Back flat in stance on the same anchors when the heels come down.
    for k in range(60, 100):
        cmd = st.update(0.01 * k, both, soles, soles, {}, toe_rise=flat)
    assert cmd.states == {"left": "stance", "right": "stance"} and st.rolled == ()
    assert np.allclose(cmd.feet["left"].homogeneous, soles["left"].homogeneous)
    # A heel rising while the other foot is up and not about to land (a hop's push-off): the
    # standing sole rolls with its contact kept; not while the other foot is low (a walk's
    # heel-off before the other foot lands), which stays flat, then rolls off as a toe-off
    # (contact off) once the other foot stands.
    for low, state in ((False, "tiptoe"), (True, "stance")):
        st2 = KinematicStepper(settings, dt=0.01, toes=toes)
        st2.update(0.0, both, soles, soles, {}, toe_rise=flat)
        one = {"left": False, "right": True}
        st2.update(0.1, one, soles, soles, {}, toe_rise=flat)  # the left swings
        cmd = st2.update(
            0.2, one, soles, soles, {}, toe_rise={"left": 0.0, "right": 0.04},
            low={"left": low, "right": False},
        )  # fmt: skip
        assert cmd.states == {"left": "swing", "right": state} and "right" in cmd.contacts
    # Flight from tiptoe releases both.
    cmd = st.update(1.0, both, soles, soles, {}, toe_rise=up)
    cmd = st.update(1.01, both, soles, soles, {}, toe_rise=up)
    assert st.rolled == ("left", "right")
    cmd = st.update(1.02, {"left": False, "right": False}, soles, soles, {}, toe_rise=up)
    assert cmd.contacts == () and cmd.states == {"left": "swing", "right": "swing"}
    # tiptoe: false keeps the former behaviour (a toe-off needs the other foot standing flat).
    st3 = KinematicStepper(StepSettings(tiptoe=False), dt=0.01, toes=toes)
    st3.update(0.0, both, soles, soles, {}, toe_rise=flat)
    cmd = st3.update(0.1, both, soles, soles, {}, toe_rise=up)
    assert sorted(cmd.states.values()) == ["stance", "toe_off"] and len(cmd.contacts) == 1


def test_an_unreachable_swing_target_is_raised_before_it_is_pulled_under_the_hip():
    from types import SimpleNamespace

    from qpretarget.retarget.feet import REACH_RAISE, FootTargets

    # Leg 0.6 m, 92 % of it usable (rho L = 0.552 m), ankle 4 cm over the sole; the hip 0.6 m up:
    # the ankle 10 cm to the side, 4 cm up, is out of reach.
    feet = SimpleNamespace(ankle_to_sole={"left": np.array([0.0, 0.0, -0.04])})
    ft = FootTargets(feet, None, 1.0, {"left": 0.6}, 0.92)  # type: ignore[arg-type]
    hip, sole, R = np.array([0.0, 0.0, 0.6]), np.array([0.1, 0.0, 0.0]), np.eye(3)
    rho_l = 0.92 * 0.6

    def reach(out: np.ndarray) -> float:
        return float(np.linalg.norm(out + np.array([0.0, 0.0, 0.04]) - hip))

    # Without lift: pulled right under the hip (no horizontal reach left at that height).
    out = ft.reachable("left", sole, R, hip)
    assert np.allclose(out, [0.0, 0.0, 0.0], atol=1e-9)
    # With lift: raised to the height a_z = h_z - sqrt((rho L)^2 - n^2) where the leg reaches
    # the foot's horizontal offset, which is kept.
    out = ft.reachable("left", sole, R, hip, REACH_RAISE)
    dz = 0.6 - math.sqrt(rho_l**2 - 0.1**2) - 0.04
    assert 0.0 < dz <= REACH_RAISE
    assert np.allclose(out, [0.1, 0.0, dz], atol=1e-6) and reach(out) == pytest.approx(rho_l)
    # A lift smaller than needed: raised by all of it, then pulled in to the reach left.
    out = ft.reachable("left", sole, R, hip, 0.015)
    assert out[2] == pytest.approx(0.015) and 0.05 < out[0] < 0.1
    assert reach(out) == pytest.approx(rho_l)


def test_a_swing_target_within_swing_reach_is_kept():
    from types import SimpleNamespace

    from qpretarget.retarget.feet import FootTargets

    # Leg 0.6 m, the ankle 4 cm over the sole, the hip 0.6 m up: a landing 0.95 of the leg
    # length from the hip (a long stride, the knee nearly straight, as a person puts a foot
    # down) is kept with swing_reach 0.97 (the G1 default) and pulled in to 0.92 of it with
    # the standing legs' leg_extension (the landing 3-5 cm short of the person's foot that
    # every later stance kept: kicks ankle error 0.138 -> 0.127, kata 0.158 -> 0.130).
    feet = SimpleNamespace(ankle_to_sole={"left": np.array([0.0, 0.0, -0.04])})
    hip, R = np.array([0.0, 0.0, 0.6]), np.eye(3)
    d = 0.95 * 0.6
    ankle = hip + d * np.array([math.sin(0.6), 0.0, -math.cos(0.6)])
    sole = ankle - np.array([0.0, 0.0, 0.04])
    for rho, kept in ((0.97, True), (0.92, False)):
        ft = FootTargets(feet, None, 1.0, {"left": 0.6}, rho)  # type: ignore[arg-type]
        out = ft.reachable("left", sole, R, hip)
        assert np.allclose(out, sole, atol=1e-12) == kept
        if not kept:  # 1e-9: round-off of the closed form
            assert np.linalg.norm(out + [0.0, 0.0, 0.04] - hip) == pytest.approx(
                rho * 0.6, abs=1e-9
            )


def test_swing_reach_is_a_share_of_the_leg_length_and_reaches_the_feet():
    with pytest.raises(ValueError, match=r"swing_reach is a share of the leg length in \(0, 1\]"):
        StepSettings(swing_reach=1.2)
    with pytest.raises(ValueError, match="swing_reach"):
        StepSettings(swing_reach=0.0)
    # The setting is what the run's foot targets use (the standing legs keep leg_extension).
    config = yaml.safe_load(CONFIG.read_text())
    config["retarget"]["support"]["stepping"]["swing_reach"] = 0.9
    rt = Retargeter(Controller(config, base_dir=CONFIG.parent))
    rt.retarget(load_motion(MOCAP / "cmu_16_15_walk.bvh").slice(0.0, 0.3))
    assert rt._foot_targets is not None and rt._foot_targets.leg_extension == 0.9
    assert rt.spec.leg_extension == 0.92


def _left_foot_targets(dt: float):  # noqa: ANN202
    """FootTargets for the left foot only (the right has no key-points): reference sole yaw 0,
    the person's calibration foot yaw 0, a 0.2 m toe."""
    from types import SimpleNamespace

    from qpretarget.retarget.feet import FootTargets

    feet = SimpleNamespace(
        sole_ref={"left": pin.SE3.Identity()},
        swing_sole=lambda *a: pin.SE3.Identity(),
    )
    cal = SimpleNamespace(human_foot_yaw={"left": 0.0})
    ft = FootTargets(feet, cal, 1.0, {}, 0.92, dt=dt)  # type: ignore[arg-type]
    ft.toe_length["left"] = 0.2
    return ft


def test_a_sole_lifted_into_flight_turns_its_yaw_target_from_where_it_is():
    from qpretarget.retarget.feet import FOOT_YAW_RATE

    # The left foot (the right has no key-points), reference sole yaw 0, the person's foot 30 deg from its calibration yaw (toe
    # 0.2 m ahead of the ankle, turned), the waist turned as much (within FOOT_YAW_RANGE).
    dt = 0.01
    ft = _left_foot_targets(dt)
    psi = math.radians(30.0)
    kp = {
        "left_ankle": np.zeros(3),
        "left_toe": np.array([0.2 * math.cos(psi), 0.2 * math.sin(psi), 0.0]),
    }

    def target_yaw() -> float:
        soles = {"left": pin.SE3.Identity(), "right": pin.SE3.Identity()}
        desired, _ = ft.orient({}, kp, soles, lambda: psi)
        R = desired["left"].rotation
        return math.atan2(R[1, 0], R[0, 0])

    assert target_yaw() == pytest.approx(psi, abs=1e-9)  # the person's foot yaw
    # The sole stood 140 deg away (a swivel the pivot did not follow) and lifts into flight:
    # the target starts at the sole's yaw and turns towards the person's foot by at most
    # FOOT_YAW_RATE dt per tick (before, the lift-off blend turned it 110 deg in lift_time,
    # 0.1 s, and the whole robot in flight with it), the short way round.
    sole_yaw = math.radians(170.0)
    ft.lifted("left", _flat(0.0, 0.0, 0.0, sole_yaw))
    lim = FOOT_YAW_RATE * dt
    yaws = [target_yaw() for _ in range(40)]
    assert yaws[0] == pytest.approx(sole_yaw - lim, abs=1e-9)
    steps = np.diff(np.unwrap([sole_yaw, *yaws]))
    assert np.all(steps <= 1e-12) and np.all(steps >= -lim - 1e-12)
    assert yaws[-1] == pytest.approx(psi, abs=1e-9)  # 140 deg at 6.9 deg per tick: 21 ticks
    # Unwrapped near the last target: a sole at -190 deg is the same as one at 170 deg.
    ft.lifted("left", _flat(0.0, 0.0, 0.0, math.radians(-190.0)))
    assert target_yaw() == pytest.approx(sole_yaw - lim, abs=1e-9)


def test_in_flight_a_sole_yaw_target_turns_with_the_waist_and_slowly_against_it():
    """In the person's flight a swing sole's yaw target turns with the waist plus at most
    FLIGHT_FOOT_YAW_RATE relative to it (FootTargets.orient ``flight``): catching up at
    FOOT_YAW_RATE from where the sole lifted turned the whole robot in flight (the dance spin:
    the base at 600 deg/s for 50 ms, 21-24 deg past the person; heading error 23.9 -> 19.0
    deg with the relative limit)."""
    from qpretarget.retarget.feet import FLIGHT_FOOT_YAW_RATE

    dt = 0.01
    ft = _left_foot_targets(dt)
    offset = math.radians(30.0)  # the person's foot, 30 deg from the waist (in FOOT_YAW_RANGE)
    soles = {"left": pin.SE3.Identity(), "right": pin.SE3.Identity()}

    def target_yaw(waist: float, flight: bool) -> float:
        psi = waist + offset
        kp = {
            "left_ankle": np.zeros(3),
            "left_toe": np.array([0.2 * math.cos(psi), 0.2 * math.sin(psi), 0.0]),
        }
        desired, _ = ft.orient({}, kp, soles, lambda: waist, flight=flight)
        R = desired["left"].rotation
        return math.atan2(R[1, 0], R[0, 0])

    rate = math.radians(150.0)  # the waist turns at 150 deg/s
    assert target_yaw(0.0, False) == pytest.approx(offset, abs=1e-9)
    ft.lifted("left", _flat(0.0, 0.0, 0.0, 0.0))  # lifted in line with the waist
    lim = FLIGHT_FOOT_YAW_RATE * dt
    rel = []
    for k in range(1, 30):
        waist = rate * dt * k
        rel.append(target_yaw(waist, True) - waist)
    steps = np.diff([0.0, *rel])
    # Relative to the waist: towards the person's offset by lim a tick, then on it.
    assert np.all(steps >= -1e-12) and np.all(steps <= lim + 1e-12)
    assert steps[0] == pytest.approx(lim, abs=1e-9)
    assert rel[-1] == pytest.approx(offset, abs=1e-9)  # 30 deg at 2.3 deg a tick: 14 ticks
    # Out of flight the absolute limit again: the waist jumps 40 deg, the target turns
    # FOOT_YAW_RATE dt at most.
    from qpretarget.retarget.feet import FOOT_YAW_RATE

    before = target_yaw(rate * dt * 29, False)
    after = target_yaw(rate * dt * 29 + math.radians(40.0), False)
    assert after - before == pytest.approx(FOOT_YAW_RATE * dt, abs=1e-9)


def test_a_foot_pointing_down_since_the_first_sample_turns_with_the_waist():
    """A foot whose yaw was never measured (its ankle -> toe vector under 80 % horizontal since
    the first sample: a fighting stance on the balls of the feet) gets the waist's turn as its
    yaw target, not the raw ankle -> toe yaw, which is noise there. On DeepMimic's punch the
    raw yaw turned the rear foot's target 113 deg the other way from the waist's turn, and the
    twisted leg held the pelvis 74 deg behind the person's heading (5 deg with the waist's)."""
    from types import SimpleNamespace

    from qpretarget.retarget.feet import FootTargets
    from qpretarget.retarget.support import rot_z

    def raw_sole(side, scaled, kp, cal, current, waist_dyaw):  # noqa: ANN001, ANN202
        if f"{side}_toe" not in kp:
            return pin.SE3.Identity()
        d = kp[f"{side}_toe"] - kp[f"{side}_ankle"]  # FootSupport.swing_sole's raw yaw
        return pin.SE3(rot_z(math.atan2(d[1], d[0])), np.zeros(3))

    feet = SimpleNamespace(sole_ref={"left": pin.SE3.Identity()}, swing_sole=raw_sole)
    cal = SimpleNamespace(human_foot_yaw={"left": 0.0})
    ft = FootTargets(feet, cal, 1.0, {}, 0.92, dt=0.01)  # type: ignore[arg-type]
    ft.toe_length["left"] = 0.2
    soles = {"left": pin.SE3.Identity(), "right": pin.SE3.Identity()}
    for k in range(51):  # the waist turns 60 deg in 0.5 s, the toe's direction -90 deg
        waist = math.radians(60.0) * k / 50
        psi = -math.radians(90.0) * k / 50
        kp = {  # toe 0.1 m ahead (half the length) and 0.17 m down: pointing down
            "left_ankle": np.zeros(3),
            "left_toe": np.array([0.1 * math.cos(psi), 0.1 * math.sin(psi), -0.17]),
        }
        desired, human_foot = ft.orient({}, kp, soles, lambda w=waist: w)
        R = desired["left"].rotation
        assert math.atan2(R[1, 0], R[0, 0]) == pytest.approx(waist, abs=1e-9)
        assert human_foot["left"] is None  # no measured yaw: no pivot either
    # Once the foot is level its measured yaw counts again (within FOOT_YAW_RANGE of the
    # waist, turning at most FOOT_YAW_RATE): toe level 20 deg left of the waist.
    psi = waist + math.radians(20.0)
    kp = {
        "left_ankle": np.zeros(3),
        "left_toe": 0.2 * np.array([math.cos(psi), math.sin(psi), 0.0]),
    }
    for _ in range(10):
        desired, human_foot = ft.orient({}, kp, soles, lambda: waist)
    R = desired["left"].rotation
    assert math.atan2(R[1, 0], R[0, 0]) == pytest.approx(psi, abs=1e-9)
    assert human_foot["left"] is not None


def test_a_foot_whose_target_is_unknown_lands_under_itself():
    """A swing target with NaN (the person's foot markers missing, C3D gaps) is no landing
    spot: the sole goes down where it is. A NaN spot left the OpenSim C3D walk's foot hovering
    in ``landing`` to the end of the clip, and the body rooted at it ran 1.8 m ahead."""
    st = KinematicStepper(StepSettings(), dt=0.01)
    soles = {"left": _flat(0, 0.1, 0), "right": _flat(0, -0.1, 0)}
    st.update(0.0, {"left": True, "right": True}, soles, soles, {})
    up = {"left": True, "right": False}
    desired = {"left": soles["left"], "right": _flat(0.2, -0.1, 0.05)}
    for k in range(1, 20):
        cmd = st.update(0.01 * k, up, soles, desired, {})
    assert cmd.states["right"] == "swing"
    soles["right"] = _flat(0.15, -0.12, 0.04)  # where the sole is when the person's foot lands
    unknown = pin.SE3(np.eye(3), np.array([np.nan, np.nan, np.nan]))
    cmd = st.update(0.2, {"left": True, "right": True}, soles, dict(desired, right=unknown), {})
    assert cmd.states["right"] == "landing"
    spot = st.landing_spot("right").translation
    assert np.allclose(spot, [0.15, -0.12, 0.0])
    soles["right"] = _flat(0.15, -0.12, 0.001)
    cmd = st.update(0.21, {"left": True, "right": True}, soles, dict(desired, right=unknown), {})
    assert cmd.states["right"] == "stance"


def test_a_foot_the_person_moves_without_a_detected_lift_steps_there():
    settings = StepSettings()
    st = KinematicStepper(settings, dt=0.01)
    soles = {"left": _flat(0, 0.1, 0), "right": _flat(0, -0.1, 0)}
    both = {"left": True, "right": True}
    desired = {"left": soles["left"], "right": _flat(0.15, -0.1, 0.03)}
    st.update(0.0, both, soles, desired, {}, moved={"left": 0.0, "right": 0.0})
    # Moved 4 cm (under restep, 5 cm): stays. Moved 8 cm (a shuffle the detector did not see
    # lifted, or a slide): the foot is lifted for lift_time, then put down where the person's
    # foot is.
    cmd = st.update(0.1, both, soles, desired, {}, moved={"left": 0.0, "right": 0.04})
    assert cmd.states["right"] == "stance"
    cmd = st.update(0.2, both, soles, desired, {}, moved={"left": 0.0, "right": 0.08})
    assert cmd.states["right"] == "swing" and cmd.contacts == ("left",)
    for k in range(21, 30):
        cmd = st.update(0.01 * k, both, soles, desired, {}, moved={"left": 0.0, "right": 0.08})
        assert cmd.states["right"] == "swing"  # held up lift_time (0.1 s)
    cmd = st.update(0.31, both, soles, desired, {}, moved={"left": 0.0, "right": 0.08})
    assert cmd.states["right"] == "landing"
    assert np.allclose(st.landing_spot("right").translation, [0.15, -0.1, 0.0])
    # Never both feet: the left cannot re-step while the right is up.
    cmd = st.update(0.32, both, soles, desired, {}, moved={"left": 0.2, "right": 0.0})
    assert cmd.states["left"] == "stance"


def test_a_foot_put_down_off_the_persons_spot_settles_there_once_the_person_stands_still():
    settings = StepSettings()
    st = KinematicStepper(settings, dt=0.01)
    soles = {"left": _flat(0, 0.1, 0), "right": _flat(0, -0.1, 0)}
    both = {"left": True, "right": True}
    desired = {"left": soles["left"], "right": _flat(0.08, -0.1, 0.0)}
    off = {"left": 0.02, "right": 0.08}  # the robot's right ankle 8 cm from the person's

    def tick(k: int, offset=off, support=both):
        return st.update(0.01 * k, support, soles, desired, {}, offset=offset)

    # Not before the person has stood still on both feet for settle_time (0.5 s).
    for k in range(0, 50):
        assert tick(k).states["right"] == "stance"
    # Then the foot furthest off (beyond restep, 5 cm) steps, held up lift_time, and goes down
    # on the person's spot; its swing target stays at the clearance (not a counted step).
    cmd = tick(50)
    assert cmd.states == {"left": "stance", "right": "swing"} and cmd.contacts == ("left",)
    for k in range(51, 61):
        cmd = tick(k)
        assert cmd.states["right"] == "swing"
        assert cmd.feet["right"].translation[2] <= settings.clearance + 1e-12
    assert tick(61).states["right"] == "landing"
    assert np.allclose(st.landing_spot("right").translation, [0.08, -0.1, 0.0])
    soles["right"] = _flat(0.08, -0.1, 0.0)
    assert tick(62).states["right"] == "stance"
    # Once per stance of the person's foot: still off (a spot the leg could not reach), no
    # second settle step ...
    for k in range(63, 200):
        assert tick(k).states["right"] == "stance"
    # ... until the person lifts that foot and puts it down again.
    tick(200, support={"left": True, "right": False})
    assert st.states["right"] == "swing"


@pytest.mark.parametrize(
    ("offset", "why"),
    [
        ({"left": 0.0, "right": 0.04}, "under restep"),
        ({"left": 0.0, "right": 0.0}, "the person's spot out of reach (offset 0)"),
    ],
)
def test_no_settle_step_near_the_persons_spot_or_when_it_cannot_be_reached(offset, why):
    st = KinematicStepper(StepSettings(), dt=0.01)
    soles = {"left": _flat(0, 0.1, 0), "right": _flat(0, -0.1, 0)}
    both = {"left": True, "right": True}
    for k in range(0, 150):
        cmd = st.update(0.01 * k, both, soles, soles, {}, offset=offset)
        assert cmd.states == {"left": "stance", "right": "stance"}, why


def test_no_settle_step_while_the_person_steps_or_when_switched_off():
    soles = {"left": _flat(0, 0.1, 0), "right": _flat(0, -0.1, 0)}
    off = {"left": 0.0, "right": 0.1}
    # The person's double supports in a walk are short (0.1 s here, each foot up 0.1 s every
    # 0.4 s): the clock restarts at every lift, and no foot swings while the person stands on it.
    st = KinematicStepper(StepSettings(), dt=0.01)
    for k in range(0, 300):
        support = {"right": not 0 <= k % 40 < 10, "left": not 20 <= k % 40 < 30}
        st.update(0.01 * k, support, soles, soles, {}, offset=off)
        for side in ("left", "right"):
            assert not (st.states[side] == "swing" and support[side])
    st = KinematicStepper(StepSettings(settle_step=False), dt=0.01)
    for k in range(0, 150):
        cmd = st.update(0.01 * k, {"left": True, "right": True}, soles, soles, {}, offset=off)
        assert cmd.states["right"] == "stance"


def test_a_hovering_foot_is_put_down_so_that_the_other_can_restep():
    settings = StepSettings()
    st = KinematicStepper(settings, dt=0.01)
    soles = {"left": _flat(0, 0.1, 0), "right": _flat(0, -0.1, 0)}
    desired = {"left": _flat(0.12, 0.1, 0.0), "right": _flat(0.0, -0.1, 0.02)}
    left_only = {"left": True, "right": False}
    st.update(0.0, {"left": True, "right": True}, soles, desired, {})
    cmd = st.update(0.1, left_only, soles, desired, {})
    assert cmd.states["right"] == "swing"
    soles["right"] = _flat(0.0, -0.1, 0.02)  # held 2 cm up, as the person's foot

    def tick(k: int, moved: float, hover: bool = True):
        return st.update(
            0.01 * k, left_only, soles, desired, {}, moved={"left": moved, "right": 0.0},
            hover={"left": False, "right": hover},
        )  # fmt: skip

    # The person's standing foot slides 12 cm (on the ball of the foot) while the other hovers:
    # nothing before the hover lasted HOVER_TIME (0.2 s) ...
    for k in range(11, 30):
        assert tick(k, 0.12).states["right"] == "swing"
    # ... then the hovering foot is put down straight under itself ...
    cmd = tick(31, 0.12)
    assert cmd.states["right"] == "landing"
    assert np.allclose(st.landing_spot("right").translation, [0.0, -0.1, 0.0])
    soles["right"] = _flat(0.0, -0.1, 0.0)
    assert tick(32, 0.12).states["right"] == "stance"
    # ... the standing foot re-steps to the person's spot (the hovering one stays down) ...
    cmd = tick(38, 0.12)
    assert cmd.states == {"left": "swing", "right": "stance"}
    for k in range(39, 49):
        assert tick(k, 0.12).states["right"] == "stance"
    assert tick(49, 0.12).states["left"] == "landing"
    soles["left"] = _flat(0.12, 0.1, 0.0)
    assert tick(50, 0.0).states["left"] == "stance"
    # ... and once it stands, the other goes up again with the person's.
    for k in range(51, 60):
        tick(k, 0.0)
    assert st.states == {"left": "stance", "right": "swing"}


def test_no_handover_for_a_foot_held_up_or_without_a_slide():
    left_only = {"left": True, "right": False}
    slide, hovering = {"left": 0.12, "right": 0.0}, {"left": False, "right": True}
    cases = [
        (StepSettings(), {"left": 0.03, "right": 0.0}, hovering, 0.02, "no slide"),
        (StepSettings(), slide, {"left": False, "right": False}, 0.02, "not hovering"),
        (StepSettings(), slide, hovering, 0.06, "the robot's foot 6 cm up"),
        (StepSettings(handover=False), slide, hovering, 0.02, "switched off"),
    ]
    for settings, moved, hover, height, why in cases:
        st = KinematicStepper(settings, dt=0.01)
        soles = {"left": _flat(0, 0.1, 0), "right": _flat(0, -0.1, 0)}
        st.update(0.0, {"left": True, "right": True}, soles, soles, {})
        st.update(0.1, left_only, soles, soles, {})  # the right foot lifts ...
        soles["right"] = _flat(0, -0.1, height)  # ... and is held there
        for k in range(11, 100):
            st.update(0.01 * k, left_only, soles, soles, {}, moved=moved, hover=hover)
            assert st.states == {"left": "stance", "right": "swing"}, why


def test_a_landing_short_of_its_spot_goes_down_once_the_person_lifts_the_other_foot():
    settings = StepSettings()
    st = KinematicStepper(settings, dt=0.01)
    soles = {"left": _flat(0, 0.1, 0), "right": _flat(0, -0.1, 0)}
    desired = {"left": soles["left"], "right": _flat(0.6, -0.1, 0.03)}
    st.update(0.0, {"left": True, "right": True}, soles, desired, {})
    for k in range(10, 30):  # the right swings, its target blended up to 3 cm
        st.update(0.01 * k, {"left": True, "right": False}, soles, desired, {})
    # The person puts the right foot down 60 cm in front; the robot's sole stalls 8 cm short.
    soles["right"] = _flat(0.52, -0.1, 0.03)
    cmd = st.update(0.3, {"left": True, "right": True}, soles, desired, {})
    assert cmd.states["right"] == "landing"
    # While the person stands on both feet the sole waits over its approach (land_timeout) ...
    for k in range(31, 45):
        cmd = st.update(0.01 * k, {"left": True, "right": True}, soles, desired, {})
        assert cmd.feet["right"].translation[2] == pytest.approx(0.03)
    # ... but once the person lifts the other foot it goes down where it is after land_wait.
    up = {"left": False, "right": True}
    cmd = st.update(0.45, up, soles, desired, {})
    assert cmd.feet["right"].translation[2] < 0.03
    soles["right"] = _flat(0.52, -0.1, 0.008)  # within 5 land_height: engaged
    cmd = st.update(0.46, up, soles, desired, {})
    assert cmd.states["right"] == "stance"
    assert np.allclose(cmd.anchors["right"].translation, [0.52, -0.1, 0.0])
    # Without waiting (land_wait longer than the test): no descent before land_timeout.
    st = KinematicStepper(StepSettings(land_wait=10.0), dt=0.01)
    soles["right"] = _flat(0, -0.1, 0)
    st.update(0.0, {"left": True, "right": True}, soles, desired, {})
    for k in range(10, 30):
        st.update(0.01 * k, {"left": True, "right": False}, soles, desired, {})
    soles["right"] = _flat(0.52, -0.1, 0.03)
    st.update(0.3, {"left": True, "right": True}, soles, desired, {})
    cmd = st.update(0.45, up, soles, desired, {})
    assert cmd.feet["right"].translation[2] == pytest.approx(0.03)


def test_the_initial_stance_is_the_persons_first_stance():
    from qpretarget.retarget.feet import INITIAL_STRIDE, initial_soles

    ctrl = Controller.from_yaml(CONFIG)
    rt = Retargeter(ctrl)
    motion = load_motion(MOCAP / "cmu_16_15_walk.bvh").slice(0.0, 0.5)
    traj = rt.retarget(motion)
    feet, cal, s = rt._fs, rt._cal, rt._leg_scale
    ref = {x: feet.sole_ref[x].translation for x in ("left", "right")}
    # The person starts mid-stride (left foot 0.40 m ahead, scaled) with the feet 6 cm apart
    # across (scaled): the robot's first sample has its soles that far apart forward and, across,
    # at the person's width within 0.7-1.0 of the robot's reference width (here 0.7 of it),
    # about the reference mid-point, at their reference height and yaw (1 mm: the settling
    # tolerance of the foot tasks), both in contact.
    first = {k: v[0] for k, v in traj.human.items() if k != "t"}
    d = s * (cal.rotation @ (first["left_ankle"] - first["right_ankle"]))
    fwd = min(d[0], INITIAL_STRIDE * min(rt.leg_lengths.values()))
    width = ref["left"][1] - ref["right"][1]
    start = min(max(d[1], 0.7 * width), 1.0 * width)
    assert start == pytest.approx(0.7 * width)  # the person's 6 cm, narrower than 0.7 of it
    model = ctrl.robot.model
    data = model.createData()
    pin.framesForwardKinematics(model, data, traj.q[0])
    got = {x: data.oMf[feet.sole_ids[x]] for x in ("left", "right")}
    assert got["left"].translation[0] - got["right"].translation[0] == pytest.approx(fwd, abs=3e-3)
    for x, sign in (("left", 1.0), ("right", -1.0)):
        y = ref[x][1] + sign * 0.5 * (start - width)
        assert got[x].translation[1] == pytest.approx(y, abs=1e-3)
        assert abs(got[x].translation[2] - ref[x][2]) < 1e-3
        assert np.allclose(got[x].rotation, feet.sole_ref[x].rotation, atol=5e-3)
    assert traj.contacts[0].all()
    stance = initial_soles(feet, cal, s, rt.leg_lengths, first, 0.05, (0.7, 1.0))
    assert stance is not None and stance.standing == ("left", "right")
    # The width range (1, 1) keeps the robot's reference width; a range over the person's
    # width gives it.
    same = initial_soles(feet, cal, s, rt.leg_lengths, first, 0.05)
    assert same is not None
    for x in ("left", "right"):
        assert same.soles[x].translation[1] == pytest.approx(ref[x][1], abs=1e-9)
    free = initial_soles(feet, cal, s, rt.leg_lengths, first, 0.05, (0.1, 1.0))
    assert free is not None
    dy = free.soles["left"].translation[1] - free.soles["right"].translation[1]
    assert dy == pytest.approx(d[1], abs=1e-9)
    # A person standing on one foot at the first sample (the right 8 cm higher, over the 5 cm
    # lift height): the robot starts on the left, placed as before; the right sole, flat, where
    # the scaled person's foot is from the left one (forward as before; across, the person's
    # offset but not narrower than the robot's stance width, the foot being lower than
    # CROSS_HEIGHT), raised by s times the height of its lowest point over the left's.
    kp = {k: np.asarray(v, float).copy() for k, v in first.items()}
    for p in ("ankle", "toe"):
        kp[f"right_{p}"][2] += 0.08
    one = initial_soles(feet, cal, s, rt.leg_lengths, kp, 0.05, (0.7, 1.0))
    assert one is not None and one.standing == ("left",)
    for x in ("left", "right"):
        assert np.allclose(one.soles[x].rotation, stance.soles[x].rotation, atol=1e-12)
    left, right = one.soles["left"].translation, one.soles["right"].translation
    # The standing sole as from both feet with the robot's width (no width on one foot).
    assert np.allclose(left, same.soles["left"].translation)
    assert left[0] - right[0] == pytest.approx(fwd, abs=1e-9)  # reference heading along x
    width = ref["left"][1] - ref["right"][1]
    assert left[1] - right[1] == pytest.approx(max(d[1], width), abs=1e-9)
    low = {x: min(kp[f"{x}_{p}"][2] for p in ("ankle", "toe", "heel") if f"{x}_{p}" in kp)
           for x in ("left", "right")}  # fmt: skip
    up = right[2] - stance.soles["right"].translation[2]
    assert up == pytest.approx(s * (low["right"] - low["left"]), abs=1e-9)
    # The person's right foot held 0.3 m out to the side, and 0.3 m across the left one's line,
    # 28 cm up (over CROSS_HEIGHT, scaled): the person's offsets, crossing allowed.
    for p in ("ankle", "toe"):
        kp[f"right_{p}"][2] += 0.20
    for y in (-0.3, 0.3):
        kq = {k: v.copy() for k, v in kp.items()}
        lateral = cal.rotation.T @ np.array([0.0, y, 0.0])  # the person's frame: 0.3 m across
        for p in ("ankle", "toe", "heel"):
            if f"right_{p}" in kq:
                up_z = [0.0, 0.0, kq[f"right_{p}"][2] - kq[f"left_{p}"][2]]
                kq[f"right_{p}"] = kq[f"left_{p}"] + lateral + up_z
        side = initial_soles(feet, cal, s, rt.leg_lengths, kq, 0.05)
        assert side is not None and side.standing == ("left",)
        dy = side.soles["left"].translation[1] - side.soles["right"].translation[1]
        assert dy == pytest.approx(-s * y, abs=1e-6)
    assert one.soles["left"].translation[2] == stance.soles["left"].translation[2]
    # A foot key-point missing: the reference posture.
    del kp["right_ankle"]
    assert initial_soles(feet, cal, s, rt.leg_lengths, kp, 0.05) is None


def test_a_slow_foot_near_the_floor_is_stood_on_when_the_other_is_up():
    from qpretarget.motion.phases import SupportPhaseDetector

    det = SupportPhaseDetector()
    ground = np.array([[0.0, 0.1, 0.0]])
    det.update(0.0, ground, ground + [0, -0.2, 0])  # both down: calibrates the floor
    # Both feet up (a hop: flight), then the left comes down onto the ball of the foot at 4 cm
    # (between height_on 3 cm and height_off 5 cm) and stays still while the right stays up: it
    # is stood on (no flight), whereas the same foot at 4 cm beside a standing foot does not
    # re-enter support (hysteresis).
    for k in range(1, 6):
        det.update(0.01 * k, ground + [0, 0, 0.08], ground + [0, -0.2, 0.3])
    assert det.flight
    for k in range(6, 40):  # held TIPTOE_TIME (0.2 s) + min_duration
        det.update(0.01 * k, ground + [0, 0, 0.04], ground + [0, -0.2, 0.3])
    assert det.feet == {"left": True, "right": False} and not det.flight
    det2 = SupportPhaseDetector()
    det2.update(0.0, ground, ground + [0, -0.2, 0])
    for k in range(1, 20):
        det2.update(0.01 * k, ground + [0, 0, 0.08 if k < 5 else 0.04], ground + [0, -0.2, 0])
    assert det2.feet == {"left": False, "right": True}


# ------------------------------------------------------------------------------ shared clips
def _run(
    clip: str | HumanMotion,
    start: float | None = None,
    end: float | None = None,
    config: Path = CONFIG,
):
    """Retarget a shared clip (file name) or a motion with ``config``; the run, metrics, ctrl."""
    ctrl = Controller.from_yaml(config)
    motion = load_motion(MOCAP / clip) if isinstance(clip, str) else clip
    traj = Retargeter(ctrl).retarget(motion, start=start, end=end)
    return traj, human_metrics(traj, ctrl.robot), ctrl


def test_swing_soles_weigh_less_high_in_the_air_and_in_flight():
    """stepping.swing_orientation_weight / flight_foot_weight on the jumps clip's first hop.

    Observed at every tick through Controller.set_weight_scale's effect (the foot tasks'
    ``weight_scale``): a swing sole 10 cm or more over the floor has its orientation rows at
    swing_orientation_weight (0.03 in the G1 config; position rows at full weight) outside the
    person's flight, its position rows at flight_foot_weight (0.1) and its orientation rows at
    the product in flight; a standing sole keeps 1; each factor moves at most dt / lift_time a
    tick.
    """
    ctrl = Controller.from_yaml(CONFIG)
    rt = Retargeter(ctrl)
    seen: list[tuple[str, np.ndarray, np.ndarray]] = []

    def observe(res) -> None:  # noqa: ANN001
        scales = [np.broadcast_to(ctrl.tasks[n].weight_scale, (6,)).copy() for n in FEET]
        seen.append((rt.detector.flight, *scales))

    FEET = ("left_foot", "right_foot")
    ctrl.add_observer(observe)
    traj = rt.retarget(load_motion(MOCAP / "cgspeed_cmu_01_01_playground_jumps.bvh"), end=2.6)
    states = [s.split("/") for s in traj.extra["support_state"]]
    seen = seen[-len(states) :]  # the ticks of the run (the initial stance's come first)
    flight = np.array([f for f, _, _ in seen])
    left = np.array([x for _, x, _ in seen])
    assert flight.any(), "the clip's first hop (1.9 s) is a flight"
    # Lowest factors reached in flight: position rows f_f, orientation rows f_o f_f (1e-9:
    # float products).
    assert rt.support is not None
    st = rt.support.stepping
    f_f, f_o = st.flight_foot_weight, st.swing_orientation_weight
    assert (f_f, f_o) == (0.1, 0.03)
    assert left[flight][:, :3].min() == pytest.approx(f_f, abs=1e-9)
    assert left[flight][:, 3:].min() == pytest.approx(f_o * f_f, abs=1e-9)
    for k, (st, row) in enumerate(zip(states, left, strict=True)):
        if st[0] != "swing":
            assert np.all(row[:3] == 1.0)  # a standing sole's position rows keep their weight
        if k:
            assert np.abs(row - left[k - 1]).max() <= ctrl.dt / 0.1 + 1e-12  # the rate limit
    # Back at full weight once the robot stands again at the end of the segment.
    assert np.all(left[-1] == 1.0) and states[-1][0] == "stance"


def _tiptoe_edge_slip(traj, robot) -> tuple[int, float]:
    """Tiptoe stances and the largest horizontal motion of their soles' front edge [m].

    For every run of ``tiptoe`` ticks of a foot (``support_state``), from the tick before it (the
    flat stance it rolled from) to the tick after it when that is a flat stance again: the
    motion of the front corners of the sole rectangle from where they stood (the contact's
    points while the sole is rolled; the run's ``contacts`` column records the flat soles only).
    """
    states = [s.split("/") for s in traj.extra["support_state"]]
    data = robot.model.createData()
    T, n, worst = len(states), 0, 0.0
    for i, side in enumerate(("left", "right")):
        (foot,) = [f for f in robot.feet if side in f.lower()]
        fid = robot.frame_id(robot.feet[foot].frame)
        _, x1, y0, y1 = robot.feet[foot].rectangle
        corners = np.array([[x1, y0, 0.0], [x1, y1, 0.0]])
        tip = np.array([s[i] == "tiptoe" for s in states])
        k = 0
        while k < T:
            if not tip[k]:
                k += 1
                continue
            j = k
            while j < T and tip[j]:
                j += 1
            end = j + 1 if j < T and states[j][i] == "stance" else j
            pts = []
            for m in range(max(k - 1, 0), end):
                pin.framesForwardKinematics(robot.model, data, traj.q[m])
                M = data.oMf[fid]
                pts.append(corners @ M.rotation.T + M.translation)
            d = np.asarray(pts) - pts[0]
            worst = max(worst, float(np.linalg.norm(d[..., :2], axis=-1).max()))
            n += 1
            k = j
    return n, worst


def _accel_overshoot_on_ok_ticks(traj, ctrl) -> float:
    """Largest joint velocity change past ``acceleration_limits`` on ticks reported ``ok`` [rad/s].

    A tick whose hard constraints conflicted is ``relaxed`` (what gave is reported); an ``ok``
    tick holds them all (the corrector step once re-solved a relaxed tick inside its widened
    box and called it ``ok``: 0.087 rad/s over on the kicks).
    """
    con = next(c for c in ctrl.constraints if c.name == "acceleration_limits")
    v = np.asarray(traj.v)[:, 6:]
    ok = np.asarray(traj.status)[1:] == "ok"
    over = np.abs(np.diff(v, axis=0)) - np.asarray(con.a_max) * ctrl.dt
    return float(max(over[ok].max(initial=0.0), 0.0))


def _zigzag_share(traj, ctrl) -> float:
    """Share of ticks on which a joint's velocity zigzags at the acceleration limit.

    A tick counts when some joint's velocity changes by at least 0.99 of ``a_max dt`` and the
    tick before changed it by as much the other way: bang-bang chatter, the velocity level's
    whole-error-per-tick gains overshooting a target the acceleration limit keeps it from
    stopping at.
    """
    con = next(c for c in ctrl.constraints if c.name == "acceleration_limits")
    dv = np.diff(np.asarray(traj.v)[:, 6:], axis=0)
    sat = np.abs(dv) >= 0.99 * np.asarray(con.a_max) * ctrl.dt
    flip = sat[1:] & sat[:-1] & (np.sign(dv[1:]) != np.sign(dv[:-1]))
    return float(flip.any(axis=1).mean())


def _limit_overshoot(traj, robot) -> float:
    qi = robot.joint_q_index
    q = traj.q[:, qi]
    return float(np.max(np.maximum(robot.q_min[qi] - q, q - robot.q_max[qi]).clip(0.0)))


# Ankle displacement error bound per walk [leg lengths RMS]: issue 15 asks 0.10. Measured 0.089
# on the walk and 0.062 on the walk-stop (0.50 and 0.38 before the run started in the person's
# first stance, rolled the soles onto their toes at push-off, fed the foot targets' speed
# forward and measured a step's width across both feet's heading).
WALK_ANKLE = {"cmu_16_15_walk.bvh": 0.10, "cmu_16_33_walk_stop.bvh": 0.10}


@pytest.mark.parametrize("clip", ["cmu_16_15_walk.bvh", "cmu_16_33_walk_stop.bvh"])
def test_the_robot_walks_with_the_person(clip):
    traj, m, ctrl = _run(clip)
    assert m["ankle_displacement_error_legs"]["rms"] <= WALK_ANKLE[clip]
    # Issue 15 acceptance. Steps: lifts > 3 cm, one per human step (a foot planted through a
    # human step fails here). Travel within 10 %, final heading within 10 deg.
    assert m["steps_total"]["robot"] == m["steps_total"]["human"] >= 3
    assert abs(m["root_travel"]["ratio"] - 1.0) <= 0.10
    assert abs(m["heading_error_deg"]["final"]) <= 10.0
    # Stance feet pinned (the contact equality holds to well under 1 mm), no sole in the floor
    # by more than 2 mm, no joint past its limit (1e-9 rad: integration round-off), no held tick.
    assert m["stance_slip_mm"]["max"] < 1.0
    assert m["sole_below_ground_mm"] < 2.0
    assert _limit_overshoot(traj, ctrl.robot) <= 1e-9
    assert m["held_ticks"] == 0


def test_talos_walks_with_the_person_too():
    ctrl = Controller.from_yaml(REPO / "configs" / "talos_whole_body.yaml")
    traj = Retargeter(ctrl).retarget(load_motion(MOCAP / "cmu_16_15_walk.bvh"))
    m = human_metrics(traj, ctrl.robot)
    # Same acceptance as G1's on the walk (measured: 7/7 steps, travel 0.93, slip 0.41 mm).
    assert m["steps_total"]["robot"] == m["steps_total"]["human"] >= 6
    assert abs(m["root_travel"]["ratio"] - 1.0) <= 0.10
    assert m["stance_slip_mm"]["max"] < 1.0 and m["sole_below_ground_mm"] < 2.0
    assert _limit_overshoot(traj, ctrl.robot) <= 1e-9


def test_talos_turns_with_the_person_through_the_kata():
    """Talos's config pivots its stance feet since stop 36 (with land_reach 3 cm).

    Before, with its pivots off, the kata's 100-180 deg turns on one foot left the robot
    facing 134 deg away at the end and its pelvis folded over (lean error 198 deg, pelvis 47 cm
    off, ankle error 0.384 leg lengths). Measured now: final heading 0.3 deg, lean 33 deg,
    pelvis 22.5 cm, ankle 0.270, stance slip 0.07 mm. Bounds: final heading 15 deg (the chaotic
    clip moves by a few degrees), lean 90 deg, ankle 0.33, slip under issue 15's 1 mm.
    """
    traj, m, ctrl = _run(
        "cmu_135_06_karate_kata.bvh", config=REPO / "configs" / "talos_whole_body.yaml"
    )
    assert abs(m["heading_error_deg"]["final"]) <= 15.0
    assert m["pelvis_tilt_error_deg"]["max"] <= 90.0
    assert m["ankle_displacement_error_legs"]["rms"] <= 0.33
    assert m["stance_slip_mm"]["max"] < 1.0
    assert m["held_ticks"] == 0
    assert _limit_overshoot(traj, ctrl.robot) <= 1e-9


def test_the_robot_stands_on_one_leg_when_the_person_does():
    traj, m, ctrl = _run("cmu_49_18_one_leg_balance.bvh")
    # Whenever the person's foot is up (>= 3 cm), the robot's is off the ground: 99 % measured
    # (the rest is the detection delay, about 40 ms at each lift and touch-down).
    assert m["lift_agreement"] >= 0.95
    assert m["stance_slip_mm"]["max"] < 1.0
    # Issue 15: pelvis height within 5 cm of the scaled person's (4.0 cm measured; 3.8 cm when
    # the run started on both feet; 35 cm while the raised foot's yaw was not measured and the
    # leg went over the back) and the heading with the person's (4.6 deg measured).
    assert m["pelvis_height_error_m"]["max"] <= 0.05
    assert m["heading_error_deg"]["max"] <= 6.0
    # The person's pelvis is pitched 21 deg at the first sample and leans back 11 deg from
    # there: the robot's follows within 2.2 deg (RMS 1.7). 21.6 (RMS 14.7) while the start
    # pose's pitch was applied twice (RobotBinding.task_targets' reference vs start). Bound 4.
    assert m["pelvis_tilt_error_deg"]["max"] <= 4.0
    # The person stands on the left foot at the first sample, the right held out to the side:
    # so does the robot's first tick, its right sole raised (7.7 cm), out of contact.
    assert traj.contacts[0].tolist() == [True, False]
    model = ctrl.robot.model
    data = model.createData()
    pin.framesForwardKinematics(model, data, traj.q[0])
    z = {
        x: data.oMf[model.getFrameId(f"{x}_ankle_roll_link")].translation[2]
        for x in ("left", "right")
    }
    assert 0.05 <= z["right"] - z["left"] <= 0.12
    # The raised foot follows the person's from where the person's is (it started on the floor
    # beside the other: 0.194 leg lengths, the person's first-sample stagger kept all along)
    # and across the body's midline (a raised foot may cross the standing foot's line): ankle
    # displacement error 0.077 leg lengths measured; issue 15's 0.10 asserted.
    assert m["ankle_displacement_error_legs"]["rms"] <= 0.10
    assert _limit_overshoot(traj, ctrl.robot) <= 1e-9


def test_kicks_lift_the_robot_foot():
    traj, m, ctrl = _run("cmu_135_04_front_kicks.bvh")
    # Every human lift over 5 cm (the kicks) is followed by the robot foot to >= 70 % of its
    # height (issue 15), each lift above where the foot stood: min 0.98, median 0.98 measured
    # (0.78 / 0.97 with the default 0.2 mm self-collision trust region, which held the legs
    # back; 0.74 / 0.85 above the clip's lowest point, the former definition; the figure moves
    # by a few hundredths with any change of the run); a high swing sole turns its toes
    # up like the person's foot (0.66 / 0.71 with a flat sole: the knee folded to 2.8 rad and
    # the ankle pitch stopped at its -0.87 rad limit).
    assert m["swing_height_ratio"]["lifts"] >= 3
    assert m["swing_height_ratio"]["min"] >= 0.7
    # Ankle displacement error: 0.097 leg lengths measured (stop 36: the stance pivots aimed in
    # the robot's frame and land_reach 4 cm; 0.109 with land_reach 3 cm, the landing at 3.5 s
    # stopping 5.7 cm short; 0.088 / 0.092 before, with the pivots aiming at the capture frame's
    # yaw, which read 0.085-0.109 with the clip turned about the vertical; 0.095 at stop 33,
    # 0.096 with the corrector's residual
    # in Python; 0.093 / 0.096 with stepping.land_wait 0.05 / 0.15 s; 0.106 while a landing
    # sole waited for its spot with the person's other foot already up, 0.109 while a robot
    # leg still standing on a foot the person lifted did not bound the pelvis, 0.114 without
    # the settle steps,
    # 0.127 before the absolute placement took the metrics' heading alignment, 0.128 before the
    # swing yaw rate limit and the pivots with both feet down; 0.138 with swing targets kept
    # within the standing legs' 0.92 of the leg length instead of stepping.swing_reach 0.97,
    # 0.156 with the 0.2 mm self-collision trust region, 0.177 before the contacts'
    # corrector step and plane_trust; 0.69 while each landing was placed by the person's
    # stride from the robot's standing foot: a kick landing 0.5 m short was carried into every
    # later step). Issue 15's 0.10 asserted.
    assert m["ankle_displacement_error_legs"]["rms"] <= 0.10
    # The person stands still on both feet for the last 3 s: the robot's feet end where the
    # person's do (settle steps, stepping.settle_step): 1.7 / 2.2 cm measured, 3.8 / 9.3 before
    # (the last kick's landing, 8 cm off, kept to the end). Bound 4 cm.
    assert max(m["ankle_displacement_error_legs"]["final_m"].values()) <= 0.04
    assert m["swing_height_ratio"]["median"] >= 0.7
    assert m["stance_slip_mm"]["max"] < 1.0  # horizontal, as evaluate's foot_slip
    # A kicking sole coming down fast stays above the floor (sole_ground rows: 15 mm under it
    # without them, 0.4 mm measured with them; 2 mm is issue 15's bound).
    assert m["sole_below_ground_mm"] < 2.0
    assert m["held_ticks"] == 0
    assert _accel_overshoot_on_ok_ticks(traj, ctrl) <= 1e-9  # 1e-9: round-off
    # The wrists zigzagged at the acceleration limit on 37 % of the ticks with the former
    # damping 0.3; 4.5 % measured with 1.0. Bound 10 %.
    assert _zigzag_share(traj, ctrl) <= 0.10


@pytest.mark.parametrize("clip", ["cmu_135_06_karate_kata.bvh", "cmu_131_04_dance_spin.bvh"])
def test_fast_clips_keep_the_soles_above_the_floor_and_the_stances_pinned(clip):
    traj, m, ctrl = _run(clip)
    # Issue 15: no sole more than 2 mm under the floor, measured at the sole rectangle's lowest
    # corner (spin 0.5 mm; kata 2.6: a sole put down 1.4 deg tilted is flattened by the contact's
    # drift correction about its origin, one corner 2.6 mm under for 70 ms; 0.9 at the sole
    # origins; 18 and 19 mm before the sole_ground rows; kata 0.6-1.5 mm since stop 37, 0.8 at
    # stop 38). Issue 15's 2 mm asserted. Stance slip < 1 mm (kata 0.61, spin 0.92 measured, with the stance
    # feet pivoting: a pivot's yaw rate ramped at 50 rad/s^2; at 100 the spin's slipped 1.2 mm).
    assert m["sole_below_ground_mm"] < 2.0
    assert m["stance_slip_mm"]["max"] < 1.0
    # Pelvis height error (kata 11.0, spin 11.3 cm measured, RMS 3.2 and 3.1; 16.5 on the
    # spin with swing soles turning 12 rad/s near the floor: a hop whose twisted stance leg
    # could not fold; 25 and 28 cm before the person's ball-of-the-foot stance counted as
    # support) and heading (spin 47 deg measured since the stance feet
    # pivot towards the person's foot yaw and the swing soles' yaw targets turn at most
    # 690 deg/s (39 before raised feet could cross the standing foot's line); 67 before the
    # pivots; 23.9 since the contacts' corrector step let the ground rows' trust region bound
    # a turn by its change of height (plane_trust, 4e-4 m); issue 15 asks 20 deg).
    assert m["pelvis_height_error_m"]["max"] <= (0.20 if "spin" in clip else 0.15)
    if "spin" in clip:
        # 18.8 measured (19.5 at stop 35; 17.0 starting at the robot's stance width, 16.2 at stop 30, 17.3 with the 0.2 mm self-collision trust region; 18.3 with the stance
        # pivots ramped at 100 rad/s^2 at stop 28, 20.9 at 50, 19.0 at 50 with
        # the corrector's residual in Python: round-off moves this chaotic clip by 2 deg), since
        # a sole's yaw target in flight turns with the waist plus at most FLIGHT_FOOT_YAW_RATE
        # (23.9 before: the robot spun past the person at two flights). 6.8 since stop 38 (the
        # ground rows' trust region growing with the gap: a standing shank 2-5 cm over the
        # floor no longer caps the body's roll and pitch near 3 rad/s). Issue 15: 20, asserted.
        assert m["heading_error_deg"]["max"] <= 20.0
        # Pelvis tilt, issue 15's 15 deg, as the pelvis's lean (forward, sideways) since the
        # first sample, robot vs the person's waist-and-hips triangle: 9.6 measured, RMS 2.1
        # (10.6 before flight_drift; 10.2, RMS 2.2, starting at the robot's stance width)
        # (10.2 with the corrector's residual in Python; the chaotic clip's figure moves by
        # 1-2 deg with round-off, 11.7 before the swing soles' yaw rate limit). 15.04 with a high swing sole's orientation rows at 0.1 of
        # their weight instead of 0.03 (the raised leg at its ankle limits turned the pelvis
        # back); 29.2 (RMS 9.9) while the start pose's pelvis pitch was applied twice and a
        # fully weighted sole high in the air or in flight turned the pelvis
        # (swing_orientation_weight, flight_foot_weight).
        assert m["pelvis_tilt_error_deg"]["max"] <= 15.0
        assert m["pelvis_tilt_error_deg"]["rms"] <= 5.0
        # Ankle displacement error: 0.095 measured (0.103 while a flight started from a waist
        # rooted at the drifted stance foot, stepping.flight_drift: the pelvis flew 12-13 cm
        # ahead of the person's from 5.3 s; 0.117 while the run started at the robot's
        # stance width, 0.237 m, not the person's 0.112 m within 0.7-1.0 of it,
        # stepping.initial_width_min; 0.125 while the waist travelled in flight
        # like the person's times the root scale, not the leg ratio; 0.133 before a hovering
        # foot was put down
        # for the other's re-step, stepping.handover: the person slides the left foot 13-16 cm
        # on its ball with the right 3 cm up, at 1.6 s and from 7.6 s to the end). Issue 15
        # asks 0.10, asserted (the same 0.095 with flight_drift 0.08 and 0.25 m). The left
        # foot ends 7.2 cm from the person's (7.8 from the robot's width, 15.3 before the
        # handover; the person's feet end 0.63 m apart scaled, about what the robot's legs
        # reach): bound 12 cm.
        assert m["ankle_displacement_error_legs"]["rms"] <= 0.10
        assert m["ankle_displacement_error_legs"]["final_m"]["left"] <= 0.12
    else:
        # The kata's steps: 14 for the person's 15 (14-15 with any change of the run, 15 at stop 30, 14 at stop 28; 15-16 before the pivots'
        # ramp went from 50 to 100 rad/s^2; 8 before a foot the person moves without a detected
        # lift re-steps, 12 with toe-offs alone, 13-14 before the stance feet pivoted).
        assert m["steps_total"]["robot"] >= 14
        # Ankle displacement error: 0.124 measured (0.123 at stop 35, before the pivots that go
        # on; 0.126 before stepping.flight_drift; 0.123
        # before the flight waist travelled by
        # the leg ratio, its one robot flight; 0.129 before the settle steps and the
        # metrics' heading alignment of the absolute placement, 0.148 with that alignment
        # alone; 0.130 before the pivots with both feet down; 0.158 with swing targets kept
        # within the
        # standing legs' 0.92 of the leg length, stepping.swing_reach). 0.098 since stop 38:
        # 0.122 -> 0.106 with the front stance's feet in line (stepping.inline_feet: the
        # no-crossing floor falls with the fore-aft distance), -> 0.098 with a toe-off turning
        # its sole about the front edge as the person's foot turns on its ball. Issue 15 asks
        # 0.10, asserted (runs repeat to the bit on one machine; the chaotic clip moves by
        # about 0.01 with any change of the run, so another change may cross it).
        assert m["ankle_displacement_error_legs"]["rms"] <= 0.10
        # Its turns on one foot (100-150 deg in 0.5 s on the ball of the foot) are followed by
        # pivoting the stance sole: the heading ends 5 deg from the person's (146 deg with the
        # soles pinned flat; the largest error, 120 deg, is a 300 deg/s turn the pelvis lags).
        assert abs(m["heading_error_deg"]["final"]) <= 30.0
        # Its lifts, each above where the foot stood: 0.72 of the person's height at least (0.77 with the corrector's residual in Python, 0.73 at stop 30),
        # issue 15's 0.7 asserted. Above the clip's lowest point (the former definition) the
        # first lift read 0.69: the person's left foot stood 1.9 cm (scaled) above the lowest
        # point the feet reach elsewhere in the capture volume, and its 5.2 cm lift counted as
        # 7.1. Before: 0.40 before the contacts' corrector step and plane_trust, 0.00 before
        # the pivots, 0.49 before the braking sole rows.
        assert m["swing_height_ratio"]["min"] >= 0.7
        # Heading: 14.6 deg at most measured (24.4 at stop 35; 126 before the corrector step and
        # plane_trust).
        assert m["heading_error_deg"]["max"] <= 35.0
    assert _limit_overshoot(traj, ctrl.robot) <= 1e-9
    assert _accel_overshoot_on_ok_ticks(traj, ctrl) <= 1e-9
    assert m["held_ticks"] == 0
    # Joint velocities zigzag at the acceleration limit on 5.6 % (kata) and 3.2 % (spin) of
    # the ticks, 26 % and 19 % with the former damping 0.3. Bound 10 %.
    assert _zigzag_share(traj, ctrl) <= 0.10


def test_both_feet_leave_the_ground_when_the_person_jumps():
    traj, m, ctrl = _run("cgspeed_cmu_01_01_playground_jumps.bvh")
    # Ankle displacement error (issue 15 asks 0.10 leg lengths): 0.039 measured (0.037 before
    # stepping.flight_drift; 0.048 while
    # the run started at the robot's stance width, not the person's 0.157 m; 0.052 while
    # the waist travelled in flight by the root scale, not the leg ratio; 0.059 before
    # the pivots with both feet down, 0.070 before the take-offs were anticipated,
    # stepping.takeoff; 0.095 at stop 27; 0.26 with the
    # stride from the standing foot, which carried every short landing into the next steps;
    # 0.112 with the absolute foot spots; 0.105 with the push-offs on the toes; 0.096 with swing
    # targets raised rather than pulled under the hip in flight and at landing, REACH_RAISE).
    # 0.039 at stop 38. Issue 15's 0.10 asserted (the chaotic clip's figure moves by about
    # 0.01 with round-off, kernel vs Python path).
    assert m["ankle_displacement_error_legs"]["rms"] <= 0.10
    # Flight (both feet up): the robot flies in all but at most one of the person's 12 flights
    # (12/12 with the former 20 self-collision pairs, 11/12 with `pairs: auto`), and for most
    # of the person's flight time (86 % measured: detection delay at take-off and landing).
    assert m["flight"]["human"] >= 10
    # 11/10 measured (the clip's T-pose frame 0 dropped: 12/12 with it). A hop's push-off on
    # tiptoe is not flight: the robot's feet are off the ground when their soles' lowest
    # corners are (13/12 while the metric took the sole origin, 1-3 cm up on a rolled sole).
    assert m["flight"]["robot"] >= m["flight"]["human"]
    # Share of the person's flight time the robot flies: asserted below (0.86 at stop 26,
    # 0.72 since a foot held slow under 5 cm for 0.2 s while the other is up counts as stood
    # on: the metric's flight is both feet over 3 cm, a ball-of-the-foot stance, or feet on a
    # raised surface, count as flight there; the dance spin's 4.6 s of false flight needed the
    # detector change).
    assert m["stance_slip_mm"]["max"] < 1.0
    # A landing sole comes down no faster than it can stop from at 30 m/s^2 (sole_ground
    # brake_accel): 1.4 mm measured at its lowest corner; 10.8 mm with first-order rows alone,
    # which gave to the acceleration limits (0.86 m/s of slack on 4 ticks).
    assert m["sole_below_ground_mm"] < 2.0
    assert _limit_overshoot(traj, ctrl.robot) <= 1e-9
    assert m["held_ticks"] == 0
    # The push-offs on the toes are anticipated take-offs now (stepping.takeoff): the robot's
    # soles leave the floor as the person's waist rises out of their reach, before rolling
    # onto the toes (14 tiptoe stances before, 0 now); the roll itself is tested on the
    # reach-up clip below, where the person stands on tiptoe without jumping.
    # Root height vs the person's, issue 15's 5 cm: max 4.7 cm and RMS 1.8 cm measured (4.8
    # starting at the robot's stance width rather than the person's; 4.9
    # with the corrector's residual in Python too), with the take-offs anticipated
    # (stepping.takeoff: 10.4 and 2.8 without, the robot on its soles 8-10 cm under the
    # person's waist rising on the toes), the stance feet pivoting with both feet down (8.3
    # without: a sole left 177 deg behind turned within the 0.1 s lift blend and dragged the
    # pelvis down) and swing soles turning at most 8 rad/s near the floor (6.2 at 12 rad/s:
    # a re-step turning its sole 80 deg and a lift-off turning it 140 deg pulled the pelvis
    # 4-5 cm under its target); 13.5 and 3.0 with the 0.2 mm self-collision trust region.
    # The largest errors left are the anticipated take-offs' lag (4.6-4.9 cm).
    assert m["pelvis_height_error_m"]["max"] <= 0.05
    assert m["pelvis_height_error_m"]["rms"] <= 0.025
    # Heading: 9 deg max measured (6.4 starting at the robot's stance width, 37 before the
    # pivots with both feet down).
    assert m["heading_error_deg"]["max"] <= 15.0
    # The robot's feet are off the ground through the person's flights: 0.99 of the person's
    # flight time shared, and 0.96 of the samples with a person's foot up (lift agreement)
    # have the robot's foot up (0.82 and 0.80 without the anticipation).
    assert m["flight"]["shared_share"] >= 0.9
    assert m["lift_agreement"] >= 0.9


def test_the_robot_takes_off_with_the_person_not_after():
    """stepping.takeoff on one jump of the playground clip (19.1-20.8 s, take-off at 20.2 s).

    The person's waist rises 14 cm in 0.12 s with the toes still down; the detector sees the
    flight once the feet are up (20.27 s). With the anticipation the robot's soles are released
    when the scaled waist rises faster than takeoff_speed and out of the legs' reach, before
    that; without it, at it, the pelvis 8-10 cm under the person's meanwhile.
    """
    runs = {}
    for on in (True, False):
        config = yaml.safe_load(CONFIG.read_text())
        config["retarget"]["support"]["stepping"]["takeoff"] = on
        ctrl = Controller(config, base_dir=CONFIG.parent)
        motion = load_motion(MOCAP / "cgspeed_cmu_01_01_playground_jumps.bvh")
        traj = Retargeter(ctrl).retarget(motion, start=19.1, end=20.8)
        states = list(traj.extra["support_state"])
        person = list(traj.extra["human_phase"]).index("flight")
        runs[on] = (states.index("swing/swing"), person, human_metrics(traj, ctrl.robot))
    (robot_on, person, m_on), (robot_off, person_off, m_off) = runs[True], runs[False]
    assert person == person_off  # the person's phases do not depend on the robot
    # Released 1-15 ticks (10-150 ms, takeoff_hold) before the person's flight is detected
    # (9 measured); without the anticipation at the same tick or later.
    assert person - 15 <= robot_on < person <= robot_off
    # The root height follows the person through the push-off: 4.4 cm max measured on the
    # excerpt (8.9 without), RMS 1.6 (2.7). Bounds 6 cm and 3 cm better: the excerpt's
    # figures move by a few mm with any change of the run.
    assert m_on["pelvis_height_error_m"]["max"] <= 0.06
    assert m_on["pelvis_height_error_m"]["max"] <= m_off["pelvis_height_error_m"]["max"] - 0.03
    # Both feet still leave the ground (the robot's flight interval covers the person's) and
    # come down with contacts pinned.
    assert m_on["flight"]["robot"] >= 1 and m_on["flight"]["human"] >= 1
    assert m_on["stance_slip_mm"]["max"] < 1.0 and m_on["held_ticks"] == 0


def test_rising_on_the_toes_to_reach_up_rolls_the_soles_with_their_contacts():
    # A clip not tuned for: the person reaches up on tiptoe and steps about (cmu_14_07).
    traj, m, ctrl = _run("cmu_14_07_reach_up_tiptoe.bvh")
    n_tiptoe, edge_slip = _tiptoe_edge_slip(traj, ctrl.robot)
    assert n_tiptoe >= 5  # 9 measured
    assert edge_slip < 1e-3  # front edges pinned: 0.52 mm measured
    # Ankle displacement error 0.081 leg lengths measured (0.118 with flat soles; 0.108 with
    # the roll alone, whose raised hips pulled a swing foot 18 cm sideways). Bound 0.10
    # (issue 15's): the figure moves by about 0.01 with any change.
    assert m["ankle_displacement_error_legs"]["rms"] <= 0.10
    assert m["pelvis_height_error_m"]["rms"] <= 0.05  # 4.5 cm measured (4.7 with flat soles)
    assert m["stance_slip_mm"]["max"] < 1.0 and m["sole_below_ground_mm"] < 2.0
    assert _limit_overshoot(traj, ctrl.robot) <= 1e-9
    assert m["held_ticks"] == 0


# Excerpts: a walk's first steps; a jump's two-foot push-off into flight (the take-off
# anticipated); a rise on the toes (tiptoe) into a hop; a run that starts on one foot (the
# initial stance with the other raised); a slide on one foot with the other hovering (the
# hovering foot put down, stepping.handover); kicks with a landing put down after land_wait and
# a settle step once the person stands still; a spin's flight after the person's stance foot
# swivelled (the flight's waist corrected by that travel, stepping.flight_drift).
@pytest.mark.parametrize(
    "clip, start, end",
    [
        ("cmu_16_33_walk_stop.bvh", 0.0, 1.4),
        ("cgspeed_cmu_01_01_playground_jumps.bvh", 12.0, 13.2),
        ("cmu_14_07_reach_up_tiptoe.bvh", 6.0, 7.2),
        ("cmu_49_18_one_leg_balance.bvh", 0.0, 1.0),
        ("cmu_131_04_dance_spin.bvh", 1.0, 2.4),
        ("cmu_135_04_front_kicks.bvh", 6.5, 8.8),
        ("cmu_131_04_dance_spin.bvh", 2.0, 3.2),
    ],
)
def test_online_push_equals_offline_causal_with_contacts_switching(
    clip, start, end, monkeypatch, push_all
):
    from qpretarget.retarget.rooting import Rooting

    drifts: list[float] = []
    takeoff_drift = Rooting.takeoff_drift

    def logged(self: Rooting, human: dict) -> np.ndarray:
        c = takeoff_drift(self, human)
        drifts.append(float(np.linalg.norm(c)))
        return c

    monkeypatch.setattr(Rooting, "takeoff_drift", logged)
    ctrl = Controller.from_yaml(CONFIG)
    motion = load_motion(MOCAP / clip).slice(start, end)
    rt = Retargeter(ctrl)
    offline = rt.retarget(motion, causal=True)
    if "spin" in clip and start == 2.0:  # a take-off 10.8 cm from the drifted foot's root
        assert drifts and max(drifts) > 0.05
    assert not offline.contacts.all()  # a foot was lifted: contacts switched in the excerpt
    states, phases = list(offline.extra["support_state"]), list(offline.extra["human_phase"])
    if "jumps" in clip:  # released 11 ticks before the person's flight is detected
        assert states.index("swing/swing") < phases.index("flight")
    if "reach_up" in clip:
        assert "tiptoe/tiptoe" in states
    both = [k for k, (st, ph) in enumerate(zip(states, phases, strict=True)) if ph == "double"]
    if "spin" in clip and start == 1.0:  # the person on the left foot, the robot's right put
        # down for a re-step
        pairs = zip(states, phases, strict=True)
        assert any(st == "stance/stance" and ph == "left" for st, ph in pairs)
    if "kicks" in clip:  # a foot lifted while the person stands still on both (settle step)
        assert any(states[k] in ("swing/stance", "stance/swing") for k in both)
    commands = push_all(rt, motion)
    q = np.array([c.q for c in commands])
    assert q.shape == offline.q.shape
    # Same code after the streaming filter (equal to the batch one to ~1e-12): 1e-6 is the
    # issue's bound, far above what is measured.
    assert np.abs(q - offline.q).max() < 1e-6
    assert [c.support for c in commands] == list(offline.extra["support_state"])


def test_a_motion_without_feet_keeps_them_planted_and_says_so():
    import yaml

    cmu = yaml.safe_load(
        (REPO / "qpretarget" / "motion" / "keypoint_maps" / "cmu.yaml").read_text()
    )
    for side in ("left", "right"):
        for p in ("ankle", "toe"):
            cmu["keypoints"].pop(f"{side}_{p}", None)
    cmu["name"] = "cmu_without_feet"
    ctrl = Controller.from_yaml(CONFIG)
    motion = load_motion(MOCAP / "cmu_16_15_walk.bvh").slice(0.0, 1.0)
    traj = Retargeter(ctrl, keypoint_map=cmu).retarget(motion)
    assert traj.contacts.all()  # documented fallback: feet planted, never a crouch or a guess
    notes = [m for m in traj.meta["messages"] if m.startswith("support phases:")]
    assert len(notes) == 1 and "no foot key-points" in notes[0] and "cmu_without_feet" in notes[0]


def _turned(motion, angle: float):  # noqa: ANN001, ANN202
    """The motion turned by ``angle`` [rad] about the world x axis (a skeleton lying down)."""
    import dataclasses

    c, s_ = math.cos(angle), math.sin(angle)
    R = np.array([[1.0, 0.0, 0.0], [0.0, c, -s_], [0.0, s_, c]])
    ori = motion.orientations
    if ori is not None:
        ori = np.einsum("ab,tjbc->tjac", R, ori)
    return dataclasses.replace(motion, positions=motion.positions @ R.T, orientations=ori)


@pytest.mark.parametrize(("angle", "what"), [(90.0, "lying down"), (180.0, "upside down")])
def test_a_skeleton_lying_down_holds_the_start_posture_and_says_why(angle, what):
    """Issue 15, bad input: a person not upright at the start (lying down, upside down, or a
    file read with the wrong up axis) gets a message naming the problem and the fix, and the
    documented fallback: the start posture held, both feet planted. Before, the walk turned 90
    deg put the robot's pelvis 0.41 m high against 0.75 (a silent crouch) and lifted its feet."""
    walk = load_motion(MOCAP / "cmu_16_15_walk.bvh").slice(0.0, 1.0)
    ctrl = Controller.from_yaml(CONFIG)
    traj = Retargeter(ctrl).retarget(_turned(walk, math.radians(angle)))
    assert traj.contacts.all()
    assert set(traj.extra["support_state"]) == {"stance/stance"}
    # Held: the joints move by less than 1e-6 rad (the start posture is the reference one,
    # the controller at rest there).
    assert np.abs(traj.q - traj.q[0]).max() < 1e-6
    notes = [m for m in traj.meta["messages"] if "not upright" in m]
    assert len(notes) == 1 and what in notes[0]
    assert "--up-axis z" in notes[0]  # the walk was read y-up: the other axis is the fix
    # Online, frame by frame: the same hold and the same note (Retargeter.notes).
    turned = _turned(walk, math.radians(angle))
    rt = Retargeter(Controller.from_yaml(CONFIG))
    rt.start(turned)
    q = [c.q for k in range(len(turned)) for c in rt.push(turned.positions[k], turned.t[k],
         orientations=turned.orientations[k])]  # fmt: skip
    assert rt.notes == notes and np.abs(np.array(q) - traj.q[0]).max() < 1e-6
    # Upright, no message; a config without feet follows the motion and says so.
    upright = Retargeter(Controller.from_yaml(CONFIG)).retarget(walk)
    assert not [m for m in upright.meta["messages"] if "not upright" in m]
    arms = Controller.from_yaml(REPO / "configs" / "g1_augmentation.yaml")
    free = Retargeter(arms).retarget(_turned(walk, math.radians(angle)))
    notes = [m for m in free.meta["messages"] if "not upright" in m]
    assert len(notes) == 1 and "followed as read" in notes[0]
    assert np.abs(free.q - free.q[0]).max() > 0.05


def test_a_motion_starting_in_the_air_measures_heights_from_the_floor():
    """Issue 15, bad input: the playground jumps cut at a flight's apex (the person's feet
    15-37 cm up at the first sample, where the run is calibrated). The robot stands on both
    feet until the person lands, a message says so, and the pelvis height is measured from the
    floor the person lands on: error against the floor-aligned person (the metrics' alignment
    for a start in the air) RMS 5.3 cm, 7.6 without the correction (every landing 17-26 cm
    low). Bound 6.5 cm: 1.2 cm above the measured value for round-off of this jumping clip.
    The same offline (causal) and pushed frame by frame, within 1e-6."""
    jumps = load_motion(MOCAP / "cgspeed_cmu_01_01_playground_jumps.bvh").slice(2.05, 4.0)
    ctrl = Controller.from_yaml(CONFIG)
    rt = Retargeter(ctrl)
    traj = rt.retarget(jumps, causal=True)
    notes = [m for m in traj.meta["messages"] if "starts in the air" in m]
    assert len(notes) == 1
    m = human_metrics(traj, ctrl.robot)
    assert 0.1 < m["start_in_air_m"] < 0.2  # s times the person's 19 cm
    from qpretarget.analysis.human_metrics import format_human_metrics

    assert "in the air at t0, heights aligned" in format_human_metrics(m)[0]
    assert m["pelvis_height_error_m"]["rms"] <= 0.065
    phases = list(traj.extra["human_phase"])
    states = list(traj.extra["support_state"])
    assert phases[0] == "double" and states[0] == "stance/stance"  # stood until the landing
    rt.start(jumps)
    commands = []
    for k in range(len(jumps)):
        commands += rt.push(jumps.positions[k], jumps.t[k], orientations=jumps.orientations[k])
    commands += rt.finish()
    assert np.abs(np.array([c.q for c in commands]) - traj.q).max() < 1e-6
    # A clip that starts on the floor: no message, no floor shift in the metrics.
    floor = Retargeter(Controller.from_yaml(CONFIG)).retarget(jumps.slice(2.5, 3.5))
    assert not [m for m in floor.meta["messages"] if "in the air" in m]
    assert "start_in_air_m" not in human_metrics(floor, ctrl.robot)


def test_body_tilt_and_the_detectors_floor():
    from qpretarget.motion.calibration import UPRIGHT_TILT, body_tilt
    from qpretarget.motion.phases import SupportPhaseDetector
    from qpretarget.retarget.rooting import Rooting

    # From the lower (standing) ankle to the waist, degrees from the vertical.
    up = {"waist": [0.0, 0.0, 1.0], "left_ankle": [0.0, 0.1, 0.1], "right_ankle": [0.0, -0.1, 0.1]}
    assert body_tilt(up) == pytest.approx(math.degrees(math.atan2(0.1, 0.9)), abs=1e-9)
    lying = {"waist": [1.0, 0.0, 0.1], "left_ankle": [0.0, 0.1, 0.1], "right_ankle": [0, -0.1, 0.1]}
    assert body_tilt(lying) == pytest.approx(90.0, abs=1e-9)
    squat = {"waist": [0.3, 0.0, 0.5], "left_ankle": [0.0, 0.1, 0.1], "right_ankle": [0, -0.1, 0.1]}
    assert body_tilt(squat) < UPRIGHT_TILT  # a deep squat, hips behind the heels: 38 deg
    # A kick at head height: the standing ankle sets the axis (the mid-ankle point: 63 deg).
    kick = {"waist": [0.0, 0.0, 1.0], "left_ankle": [0.6, 0.1, 1.2], "right_ankle": [0, -0.1, 0.1]}
    assert body_tilt(kick) == pytest.approx(math.degrees(math.atan2(0.1, 0.9)), abs=1e-9)
    one = dict(kick, left_ankle=[np.nan, 0.0, 0.0])  # a missing ankle: the other one
    assert body_tilt(one) == pytest.approx(body_tilt(kick), abs=1e-9)
    assert body_tilt({"waist": [0.0, 0.0, 1.0]}) is None
    nan = dict(up, waist=[np.nan, 0.0, 1.0])
    assert body_tilt(nan) is None
    det = SupportPhaseDetector()
    assert det.ground == math.inf
    det.update(0.0, [[0.0, 0.1, 0.30], [0.1, 0.1, 0.25]], [[0.0, -0.1, 0.32], [0.1, -0.1, 0.26]])
    det.update(0.01, [[0.0, 0.1, 0.05], [0.1, 0.1, 0.02]], [[0.0, -0.1, 0.3], [0.1, -0.1, 0.3]])
    assert det.ground == pytest.approx(0.02)
    # The kinematic pelvis height from the floor: z0 + s (z_h - (z_cal - drop)).
    from types import SimpleNamespace

    cal = SimpleNamespace(human_waist=np.array([0.0, 0.0, 1.2]))
    ro = Rooting.__new__(Rooting)
    ro.calibration, ro.waist_height, ro.leg_scale, ro.ground_drop = cal, 0.7, 0.75, 0.0
    assert ro.waist_goal(1.0) == pytest.approx(0.7 - 0.75 * 0.2)
    ro.ground_drop = 0.2  # calibrated 20 cm in the air: standing at 1.0 is the reference
    assert ro.waist_goal(1.0) == pytest.approx(0.7)


@pytest.mark.parametrize("key", ["flight_foot_weight", "swing_orientation_weight"])
def test_a_swing_weight_factor_is_in_zero_one(key):
    with pytest.raises(ValueError, match=rf"{key} is a factor on the sole's weight in \(0, 1\]"):
        StepSettings(**{key: 1.5})
    with pytest.raises(ValueError, match=key):
        StepSettings(**{key: 0.0})
    assert getattr(StepSettings(**{key: 1.0}), key) == 1.0  # 1: off


def test_in_flight_the_waist_travels_like_the_scaled_person_of_the_metrics():
    # Kinematic mode: horizontally the person's waist travel times the leg-length ratio (the
    # scaled person of the human-referenced metrics and of the absolute foot placement), not the
    # calibration's root scale (0.86 against 0.78 on the dance spin: every leap travelled 11 %
    # too far, ankle error 0.125 -> 0.117 with the leg ratio).
    ctrl = Controller.from_yaml(CONFIG)
    rt = Retargeter(ctrl)
    motion = load_motion(MOCAP / "cmu_131_04_dance_spin.bvh").slice(0.0, 0.2)
    traj = rt.retarget(motion)
    rooting, cal = rt._rooting, rt._cal
    assert rooting is not None and abs(cal.root_scale - rt._leg_scale) > 0.05
    n = len(traj.human["t"])
    human = {
        k: np.asarray(v, float).reshape(n, 3)[0]
        for k, v in traj.human.items()
        if k != "t" and np.asarray(v).size == 3 * n
    }
    waist = np.asarray(human["waist"], float)
    rooting.flight_root = (np.array([1.0, 2.0, 0.7]), waist.copy())
    moved = {k: np.asarray(v, float) + np.array([0.3, -0.1, 0.05]) for k, v in human.items()}
    out = rooting.scale_from(moved, "flight", {})
    expect = rt._leg_scale * (cal.rotation @ np.array([0.3, -0.1, 0.05]))
    assert np.allclose(out["waist"][:2] - [1.0, 2.0], expect[:2], atol=1e-12)


def test_a_squat_flexes_the_hips_past_the_rest_rule_without_touching():
    """The bend-and-scoop's first squat: the pelvis goes down with the person's.

    G1's hip-roll motors fold into the pelvis shell as the hips flex; the rest rule's 6 mm
    safety distance held the hips at 1.17 rad and the pelvis 26 cm over the scaled person's at
    the bottom of the squat. With the shipped config's 2 mm for those pairs (``safety:``) the
    hips flex past 1.4 rad, the pelvis is within 13 cm (12.1 measured: the ankles at their
    dorsiflexion limit and the hands reaching the floor keep it up from there), and no pair of
    links touches on the meshes (the audit of every pair, exact where the hulls meet).
    """
    from qpretarget.analysis.mesh_audit import audit_run

    traj, m, ctrl = _run("cmu_02_06_bend_scoop_lift_arm.bvh", end=1.6)
    assert m["pelvis_height_error_m"]["max"] <= 0.13
    robot = ctrl.robot
    q = np.asarray(traj.q)
    for side in ("left", "right"):
        hip = robot.joint_q_index[robot.joint_index(f"{side}_hip_pitch_joint")]
        assert q[:, hip].min() < -1.4
    audit = audit_run(q, robot)
    assert audit is not None and audit.penetrating_frames == 0


def _transformed(
    clip: str,
    speed: float = 1.0,
    mirror: bool = False,
    turn_deg: float = 0.0,
    shift: tuple[float, float, float] = (0.0, 0.0, 0.0),
):
    """A shared clip played ``speed`` times faster, mirrored left/right, turned about the
    vertical by ``turn_deg`` and moved by ``shift`` [m] in the capture.

    Motions the shipped config was not tuned on, made from real ones: the mirror across the
    sagittal plane swaps the CMU skeleton's ``l``/``r`` joints and negates y (positions, and
    the orientations conjugated by the reflection); the turn rotates positions and
    orientations.
    """
    m = load_motion(MOCAP / clip)
    names, pos, ori = m.names, np.array(m.positions), m.orientations
    if mirror:
        other = {"l": "r", "r": "l"}
        names = tuple(
            other[n[0]] + n[1:] if n[:1] in other and other[n[0]] + n[1:] in m.names else n
            for n in m.names
        )
        pos[..., 1] *= -1.0
        F = np.diag([1.0, -1.0, 1.0])
        ori = None if ori is None else np.einsum("ij,tnjk,kl->tnil", F, ori, F)
    if turn_deg:
        c, s_ = math.cos(math.radians(turn_deg)), math.sin(math.radians(turn_deg))
        R = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
        pos = pos @ R.T
        ori = None if ori is None else np.einsum("ij,tnjk->tnik", R, ori)
    return HumanMotion(
        t=np.asarray(m.t) / speed, names=names, positions=pos + np.asarray(shift),
        parents=m.parents, orientations=ori, rate=m.rate * speed,
        source=f"{m.source} x{speed} mirror={mirror} turn={turn_deg}", meta=m.meta,
    )  # fmt: skip


@pytest.mark.parametrize("mirror", [False, True])
def test_the_kata_played_faster_keeps_its_heading(mirror):
    """The karate kata 1.25 times faster (and mirrored): its 180 deg turns on the ball of one
    foot come at 600-700 deg/s and the person's foot slides 6-10 cm as it turns.

    A pivot that stopped once the foot had moved ``pivot_radius`` (before stop 36) left the
    anchor 94 deg behind, the pelvis twisted 160 deg over it and the heading 135 deg off to the
    end (max 144 deg, ankle error 0.236 leg lengths; mirrored 34 deg, 0.159). Now the pivot goes
    on: measured max 25.7 / 25.1 deg, final 0.2 / -0.2 deg, ankle error 0.145 / 0.154 (stop
    38, with the front stances in line and the toe-offs' ball pivots: about 0.09 and 12 deg).
    Bounds: final 10 deg, max 35 deg, ankle 0.18 (the chaotic clip moves by about 0.01-0.03).
    """
    traj, m, ctrl = _run(_transformed("cmu_135_06_karate_kata.bvh", 1.25, mirror))
    assert abs(m["heading_error_deg"]["final"]) <= 10.0
    assert m["heading_error_deg"]["max"] <= 35.0
    assert m["ankle_displacement_error_legs"]["rms"] <= 0.18
    assert m["stance_slip_mm"]["max"] < 1.0
    assert m["held_ticks"] == 0
    assert _limit_overshoot(traj, ctrl.robot) <= 1e-9


def test_the_capture_s_heading_and_position_do_not_change_the_run():
    """A clip turned about the vertical (and moved) in the capture gives the same run.

    The robot starts facing its own +x whatever way the person faces in the capture, so turning
    the whole clip by 90 or 180 deg (and moving it 2 m) changes nothing but round-off. Until stop
    36 a stance pivot aimed at the person's foot yaw in the capture's frame: on the first 4 s of
    the dance spin the heading error reached 81 deg (turned 90 deg) and 220 deg (180 deg)
    instead of 19, and the whole karate kata turned 180 deg ended 355 deg off (ankle error 1.78
    leg lengths instead of 0.12). Measured now: 16.571 / 16.574 / 16.571 deg, ankle error
    0.0864 in all three. Tolerances: 0.5 deg and 0.002 leg lengths (round-off grows through the
    chaotic clip's contact switches: the joints differ by up to 0.04 rad at some ticks).
    """
    figures = []
    for deg, shift in ((0.0, (0.0, 0.0, 0.0)), (90.0, (0.0, 0.0, 0.0)), (180.0, (2.0, -1.0, 0.0))):
        motion = _transformed("cmu_131_04_dance_spin.bvh", turn_deg=deg, shift=shift)
        _, m, _ = _run(motion, end=4.0)
        figures.append((m["heading_error_deg"]["max"], m["ankle_displacement_error_legs"]["rms"]))
    for heading, ankle in figures[1:]:
        assert heading == pytest.approx(figures[0][0], abs=0.5)
        assert ankle == pytest.approx(figures[0][1], abs=0.002)
    assert figures[0][0] <= 20.0  # issue 15's spin line, on these 4 s
