"""The MuJoCo model built from the G1 URDF matches the pinocchio model it was retargeted with."""

from __future__ import annotations

import builtins

import numpy as np
import pinocchio as pin
import pytest

from qpretarget.errors import MissingDependencyError
from qpretarget.physics.model import PhysicsModelError, build_physics_model, set_configuration

mujoco = pytest.importorskip("mujoco")


def test_g1_mass_and_kinematics_match_pinocchio(g1_physics):
    robot, pm = g1_physics
    # Same URDF, same inertias: masses agree to round-off (1e-9 kg).
    assert pm.mass == pytest.approx(pin.computeTotalMass(robot.model), abs=1e-9)
    assert len(pm.joint_names) == 29 and pm.model.nq == 7 + 29
    # Joints are mapped by name: a random configuration puts every foot and the torso where
    # pinocchio puts them (1e-9 m: the same kinematic tree, float round-off only).
    rng = np.random.default_rng(0)
    q = pin.randomConfiguration(robot.model, robot.q_min.clip(-3, 3), robot.q_max.clip(-3, 3))
    q[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(*rng.uniform(-0.3, 0.3, 3))).coeffs()
    d = mujoco.MjData(pm.model)
    set_configuration(d, q[:7], q[robot.joint_q_index], pm.qpos_adr)
    mujoco.mj_kinematics(pm.model, d)
    pin.framesForwardKinematics(robot.model, robot.data, q)
    for body in (
        "left_ankle_roll_link",
        "right_ankle_roll_link",
        "torso_link",
        "left_wrist_yaw_link",
    ):
        p_pin = robot.data.oMf[robot.model.getFrameId(body)].translation
        np.testing.assert_allclose(d.xpos[pm.model.body(body).id], p_pin, atol=1e-9)
    # Torque limits are the URDF efforts.
    i = pm.joint_names.index("left_knee_joint")
    assert pm.effort[i] == 139.0
    assert [pm.model.body(b).name for b in pm.foot_bodies] == [
        "left_ankle_roll_link",
        "right_ankle_roll_link",
    ]


def test_vendor_gain_profiles_are_the_cited_numbers():
    from qpretarget.physics.gains import GAIN_PROFILES

    u = GAIN_PROFILES["unitree"]
    assert (u.gains("left_knee_joint").kp, u.gains("left_knee_joint").kd) == (100.0, 2.0)
    assert u.gains("right_ankle_roll_joint").kp == 40.0
    bm = GAIN_PROFILES["beyondmimic"].gains("left_hip_roll_joint")
    # BeyondMimic: kp = armature (2 pi 10 Hz)^2 with the 7520-22 rotor inertia.
    assert bm.kp == pytest.approx(0.025101925 * (20 * np.pi) ** 2, rel=1e-9)


def test_collada_collision_mesh_is_named(tmp_path):
    """Romeo and iCub ship .dae collision meshes, which MuJoCo does not read: the link is named."""
    from qpretarget.robot import RobotModel

    robot = RobotModel.from_name("romeo")
    with pytest.raises(PhysicsModelError, match=r"link '.*' <collision> mesh .*\.dae"):
        build_physics_model(robot)


def test_fixed_base_robot_refused():
    from qpretarget.robot import RobotModel
    from qpretarget.robots import robots_directory

    urdf = robots_directory() / "ur_description/urdf/ur5_robot.urdf"
    if not urdf.is_file():
        pytest.skip("ur5 URDF not in this example-robot-data")
    robot = RobotModel(urdf, free_flyer=False)
    with pytest.raises(PhysicsModelError, match="fixed base"):
        build_physics_model(robot)


def test_missing_mujoco_gives_install_hint(monkeypatch):
    from qpretarget.physics import model

    real_import = builtins.__import__

    def fake(name, *a, **k):
        if name == "mujoco":
            raise ImportError("no mujoco")
        return real_import(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", fake)
    with pytest.raises(MissingDependencyError, match=r"physics.*pip install"):
        model.import_mujoco()


def test_talos_converts_and_stands_in_its_reference_posture():
    """Talos (90 kg, 32 joints) converts; held in its half-sitting posture for 1 s it stays up."""
    from qpretarget.physics.replay import check_run
    from qpretarget.robot import RobotModel
    from qpretarget.trajectory import RobotTrajectory

    robot = RobotModel.from_name("talos")
    pm = build_physics_model(robot)
    assert pm.mass == pytest.approx(pin.computeTotalMass(robot.model), abs=1e-9)
    T = 100
    traj = RobotTrajectory(
        t=np.arange(T) * 0.01,
        q=np.tile(robot.q_reference, (T, 1)),
        v=np.zeros((T, robot.nv)),
        joint_names=list(robot.joint_names),
        robot="talos",
        config_yaml="robot: talos\n",
    )
    m, _, _ = check_run(traj, pm=pm, assisted=False)
    assert m["verdict"] == "ok"
    # Stiff servo, quiet stance: the base stays within 2 cm (measured 7 mm p95 over 2 s).
    assert m["unassisted"]["root_position_error_mm"]["p95"] < 20.0


_URDF = """<robot name="t">
  <link name="base"><inertial><mass value="1"/><inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="arm"><inertial><mass value="1"/><inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><geometry>GEOM</geometry></collision></link>
  <joint name="j" type="JTYPE"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="10" velocity="1"/></joint>
</robot>
"""


@pytest.mark.parametrize(
    ("geom", "jtype", "match"),
    [
        (
            '<mesh filename="package://nowhere/arm.stl"/>',
            "revolute",
            r"link 'arm' <collision> mesh .* not found",
        ),
        ('<box size="0.1 0.1 0.1"/>', "planar", r"joint 'j' is of type 'planar'"),
    ],
)
def test_unconvertible_urdf_element_is_named(tmp_path, geom, jtype, match):
    from qpretarget.physics.model import rewrite_urdf

    urdf = tmp_path / "t.urdf"
    urdf.write_text(_URDF.replace("GEOM", geom).replace("JTYPE", jtype), encoding="utf-8")
    with pytest.raises(PhysicsModelError, match=match):
        rewrite_urdf(urdf)
