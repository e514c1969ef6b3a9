# SPDX-License-Identifier: Apache-2.0
"""Fixtures of the point-cloud tests: G1 and its meshes and template, rendered sequences, once."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import qpretarget as qp
from qpretarget.cloud.meshes import load_link_meshes
from qpretarget.cloud.render import kinect_camera, render_sequence
from qpretarget.cloud.template import Template

MOCAP = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "mocap"

#: The robot-posed sequence: 2 s at 30 Hz (the tests use every third frame, see there).
RATE = 30.0
DURATION = 2.0


@pytest.fixture(scope="session")
def g1() -> qp.RobotModel:
    return qp.load_robot("g1")


@pytest.fixture(scope="session")
def g1_meshes(g1):
    return load_link_meshes(g1.model, g1.urdf_path)


@pytest.fixture(scope="session")
def g1_template(g1, g1_meshes) -> Template:
    """The default template of configs/cloud_g1.yaml (5,000 points)."""
    return Template(g1, n_points=5000, meshes=g1_meshes, link_density_exponent=0.5)


def g1_truth(g1: qp.RobotModel, t: np.ndarray) -> np.ndarray:
    """Known joint trajectories (T, nq): both arms, the waist and a knee bend, 0.5 Hz."""
    q = np.tile(g1.q_reference, (len(t), 1))

    def add(name: str, values: np.ndarray) -> None:
        q[:, g1.joint_q_index[g1.joint_index(name)]] += values

    w = np.pi * t
    add("left_shoulder_pitch_joint", -0.9 * np.sin(w))
    add("left_shoulder_roll_joint", 0.4 * (1 - np.cos(w)))
    add("left_elbow_joint", -0.5 * np.sin(w))
    add("right_shoulder_pitch_joint", -0.7 * (1 - np.cos(w)))
    add("right_shoulder_roll_joint", -0.3 * np.sin(w))
    add("right_elbow_joint", 0.4 * np.sin(w))
    add("waist_yaw_joint", 0.25 * np.sin(w))
    add("waist_pitch_joint", 0.15 * (1 - np.cos(w)))
    bend = 0.15 * (1 - np.cos(w))
    for side in ("left", "right"):
        add(f"{side}_knee_joint", bend)
        add(f"{side}_hip_pitch_joint", -0.5 * bend)
        add(f"{side}_ankle_pitch_joint", -0.5 * bend)
    return q


@pytest.fixture(scope="session")
def g1_sequence(g1, g1_meshes):
    """G1 posed by :func:`g1_truth`, every third frame of 2 s at 30 Hz (20 frames), rendered by a
    half-resolution Kinect V2 1.8 m away, 5 mm range noise, 5 % outliers."""
    t = np.arange(0.0, DURATION, 1.0 / RATE)[::3]
    camera = kinect_camera([1.8, 0.3, 1.0], [0.0, 0.0, 0.65], downscale=2)
    return render_sequence(
        g1.model, g1_meshes, g1_truth(g1, t), t, camera, noise=0.005, outlier_fraction=0.05, seed=0
    )


@pytest.fixture(scope="session")
def mocap() -> Path:
    if not MOCAP.is_dir():
        pytest.skip(f"mocap clips not found at {MOCAP}")
    return MOCAP
