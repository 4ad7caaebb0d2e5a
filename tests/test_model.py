"""The robot description: URDF facts survive compilation, bad URDFs fail clearly."""

import re
import subprocess
import sys
import xml.etree.ElementTree as ET

import mujoco
import numpy as np
import pytest

from hopper_mjx import model
from hopper_mjx.model.layout import Layout
from hopper_mjx.model.robot import LegGeometry

SEED_URDF = model.DEFAULT_URDF.read_text()
REDUCTION = "<mechanicalReduction>{}</mechanicalReduction>"


def _variant(text: str, **replace) -> str:
    for old, new in replace.values():
        assert old in text, old
        text = text.replace(old, new, 1)
    return text


def test_seed_geometry_and_masses(mj_model):
    lay, leg = Layout.of(mj_model), LegGeometry.of(mj_model)
    assert leg.haa_below_base + leg.hfe_below_haa == pytest.approx(0.15 + 0.08)
    assert leg.thigh == pytest.approx(0.35) and leg.shank == pytest.approx(0.35)
    assert leg.foot_radius == pytest.approx(0.03)
    assert lay.total_mass == pytest.approx(5.0 + 0.5 + 0.8 + 0.4 + 0.1)
    assert lay.joint_range == ((-1.6, 1.6), (-1.6, 1.6), (-1.6, 0.0))
    assert lay.effort_limit == (40.0, 80.0, 80.0)
    assert mj_model.opt.timestep == 1e-3
    # The base is the 0.20 x 0.20 x 0.30 box of the seed, with the inertia of a solid box.
    base = mj_model.body("base")
    assert base.mass[0] == 5.0
    np.testing.assert_allclose(base.inertia, 5.0 / 12 * np.array([0.04 + 0.09, 0.04 + 0.09, 0.08]), rtol=1e-5)


def test_shipped_inertias_are_those_of_the_collision_solids(mj_model):
    # hipassembly, upperleg, lowerleg are solid cylinders along z; the foot a solid sphere.
    for body, r, h in (("hipassembly", 0.04, 0.08), ("upperleg", 0.025, 0.35), ("lowerleg", 0.02, 0.35)):
        b = mj_model.body(body)
        m = b.mass[0]
        np.testing.assert_allclose(b.inertia, [m * (3 * r**2 + h**2) / 12] * 2 + [m * r**2 / 2], rtol=1e-5)
    foot = mj_model.body("foot")
    np.testing.assert_allclose(foot.inertia, [0.4 * foot.mass[0] * 0.03**2] * 3, rtol=1e-5)


def test_second_urdf_compiles_with_its_own_lengths_and_masses(tmp_path):
    text = _variant(
        SEED_URDF,
        thigh=('<origin xyz="0 0 -0.35" rpy="0 0 0"/>\n    <parent link="upperleg"/>',
               '<origin xyz="0 0 -0.42" rpy="0 0 0"/>\n    <parent link="upperleg"/>'),
        shank=('<origin xyz="0 0 -0.35" rpy="0 0 0"/>\n    <parent link="lowerleg"/>',
               '<origin xyz="0 0 -0.28" rpy="0 0 0"/>\n    <parent link="lowerleg"/>'),
        hip=('<origin xyz="0 0 -0.08" rpy="0 0 0"/>', '<origin xyz="0 0 -0.10" rpy="0 0 0"/>'),
        base_mass=('<mass value="5.0"/>', '<mass value="8.25"/>'),
        shank_mass=('<mass value="0.4"/>', '<mass value="0.65"/>'),
    )
    path = tmp_path / "long_thigh.urdf"
    path.write_text(text)
    lay, leg = Layout.of(model.load(path)), LegGeometry.of(model.load(path))
    assert leg.thigh == pytest.approx(0.42)
    assert leg.shank == pytest.approx(0.28)
    assert leg.haa_below_base + leg.hfe_below_haa == pytest.approx(0.15 + 0.10)
    assert lay.total_mass == pytest.approx(8.25 + 0.5 + 0.8 + 0.65 + 0.1)
    m = model.load(path)
    assert m.body("base").mass[0] == pytest.approx(8.25)
    assert m.body("lowerleg").mass[0] == pytest.approx(0.65)


def test_exported_mjcf_loads_in_plain_mujoco(tmp_path):
    out = tmp_path / "monoped.xml"
    done = subprocess.run([sys.executable, "-m", "hopper_mjx.model", "--export", str(out)],
                          capture_output=True, text=True, check=True)
    assert "3 motors" in done.stdout
    m = mujoco.MjModel.from_xml_path(str(out))
    hinges = [m.joint(i).name for i in range(m.njnt) if m.jnt_type[i] == mujoco.mjtJoint.mjJNT_HINGE]
    assert hinges == list(model.JOINTS)
    assert m.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE
    sensors = {m.sensor(i).name for i in range(m.nsensor)}
    assert {"imu_quat", "imu_gyro", "imu_accel", "odom_pos", "odom_linvel", "odom_angvel", "foot_touch"} <= sensors
    assert m.nu == 3 and m.opt.timestep == 1e-3


@pytest.mark.parametrize("source", [None, "tests/data/long_shin_hopper.urdf"], ids=["seed", "long-shin"])
def test_exported_urdf_is_the_loaded_robot_with_colours(tmp_path, source):
    """--export-urdf writes the robot the simulation loads: loaded back, every body's mass and inertia,
    every joint's axis, range and damping and every motor's gear and range are the original's."""
    out = tmp_path / "display.urdf"
    urdf = [] if source is None else ["--urdf", source]
    subprocess.run([sys.executable, "-m", "hopper_mjx.model", "--export-urdf", str(out), *urdf],
                   capture_output=True, text=True, check=True)
    streamed = subprocess.run([sys.executable, "-m", "hopper_mjx.model", "--export-urdf", "-", *urdf],
                              capture_output=True, text=True, check=True).stdout
    assert streamed == out.read_text()
    original, exported = model.load(source), model.load(out)
    for field in ("body_mass", "body_inertia", "body_pos", "body_quat", "jnt_axis", "jnt_range", "dof_damping",
                  "actuator_gear", "actuator_ctrlrange", "geom_size"):
        np.testing.assert_array_equal(getattr(exported, field), getattr(original, field), err_msg=field)
    for kind, count in (("joint", "njnt"), ("body", "nbody")):
        names = [[getattr(m, kind)(i).name for i in range(getattr(m, count))] for m in (original, exported)]
        assert names[0] == names[1], kind
    if source is not None:  # the pictures' colours are for the seed's link names
        return
    from hopper_mjx.model.scene import LINK_COLOURS

    colours = {link.get("name"): [float(c) for c in link.find("visual/material/color").get("rgba").split()]
               for link in ET.fromstring(streamed).findall("link")}
    assert colours == {name: list(rgba) for name, rgba in LINK_COLOURS.items()}


def test_exported_urdf_draws_every_link_and_finds_its_meshes(tmp_path):
    """A link with only a collision shape is drawn by a copy of it; a relative mesh path becomes a file:// URL."""
    from hopper_mjx.model.display_urdf import display_urdf

    text = re.sub(r"<visual>\s*<geometry><sphere radius=\"0.03\"/></geometry>\s*</visual>", "", SEED_URDF)
    text = text.replace('<geometry><box size="0.20 0.20 0.30"/></geometry>\n    </visual>',
                        '<geometry><mesh filename="meshes/base.stl"/></geometry>\n    </visual>', 1)
    assert text.count("<visual>") == 4 and "meshes/base.stl" in text
    path = tmp_path / "robot.urdf"
    path.write_text(text)
    robot = ET.fromstring(display_urdf(path))
    foot = robot.find("link[@name='foot']")
    assert foot.find("visual/geometry/sphere").get("radius") == "0.03"
    mesh = robot.find("link[@name='base']/visual/geometry/mesh").get("filename")
    assert mesh == (tmp_path / "meshes" / "base.stl").as_uri()


def test_a_frame_prefix_renames_the_links_as_the_streams_tf_frames(tmp_path):
    from hopper_mjx.model.display_urdf import display_urdf

    path = tmp_path / "monoped_3.urdf"
    path.write_text(display_urdf(frame_prefix="monoped_3/"))
    prefixed, original = model.load(path), model.load()
    assert [prefixed.body(i).name for i in range(1, prefixed.nbody)] == \
        [f"monoped_3/{original.body(i).name}" for i in range(1, original.nbody)]
    np.testing.assert_array_equal(prefixed.body_mass, original.body_mass)
    np.testing.assert_array_equal(prefixed.jnt_axis, original.jnt_axis)


def test_timestep_is_configurable():
    assert model.load(timestep=2e-3).opt.timestep == 2e-3
    for bad in (0.0, -1e-3, float("nan"), 0.5):
        with pytest.raises(ValueError, match="timestep"):
            model.load(timestep=bad)


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda t: t.replace("</robot>", ""), "not well-formed XML"),
        (lambda t: t.replace('name="kfe_joint" type', 'name="knee" type'), r"lacks the joint\(s\) \['kfe_joint'\]"),
        (lambda t: re.sub(r"<inertial>.*?</inertial>", "", t, count=1, flags=re.S), "link 'base' has no <inertial>"),
        (lambda t: t.replace('<mass value="0.8"/>', '<mass value="-0.8"/>'), "link 'upperleg' has mass -0.8"),
        (lambda t: t.replace('<sphere radius="0.03"/>', '<box size="0.03 0.03 0.03"/>'), "one <sphere> collision"),
        (lambda t: re.sub(r'<transmission name="hfe_joint_trans">.*?</transmission>', "", t, flags=re.S),
         r"no EffortJointInterface <transmission> drives \['hfe_joint'\]"),
        (lambda t: t.replace('<limit effort="80" lower="-1.6" upper="0"', '<limit effort="abc" lower="-1.6" upper="0"'),
         "'effort' is not a number"),
        (lambda t: t.replace('<joint name="hfe_joint" type="revolute">', '<joint name="hfe_joint" type="prismatic">'),
         "'hfe_joint' must be revolute"),
        (lambda t: t.replace(REDUCTION.format(1), REDUCTION.format(0)),
         r"transmission 'haa_joint_trans' <mechanicalReduction> must be a finite number > 0, got 0"),
        (lambda t: t.replace(REDUCTION.format(1), REDUCTION.format("nan")),
         "must be a finite number > 0, got nan"),
        (lambda t: t.replace('effort="80" lower="-1.6" upper="1.6"', 'effort="80" lower="1.6" upper="-1.6"'),
         "joint 'hfe_joint' <limit>: lower 1.6 must be below upper -1.6"),
        (lambda t: t.replace('<origin xyz="0 0 -0.15" rpy="0 0 0"/>', '<origin xyz="0 nan -0.15" rpy="0 0 0"/>'),
         r"<joint name='haa_joint'> <origin xyz> must be three finite numbers, got '0 nan -0.15'"),
        (lambda t: t.replace('<sphere radius="0.03"/>', '<sphere radius="-0.03"/>'),
         "the foot's radius must be > 0, got -0.03"),
    ],
    ids=["xml", "missing-joint", "no-inertia", "negative-mass", "no-foot", "no-transmission", "bad-effort",
         "prismatic", "zero-reduction", "nan-reduction", "reversed-limits", "nan-origin", "negative-foot"],
)
def test_bad_urdf_is_rejected_with_a_clear_message(tmp_path, edit, message, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = tmp_path / "bad.urdf"
    path.write_text(edit(SEED_URDF))
    with pytest.raises(model.URDFError, match=message) as err:
        model.load(path)
    assert "\n" not in str(err.value)  # one line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.urdf"]  # no MUJOCO_LOG.TXT left behind


def test_missing_or_binary_file_is_a_urdf_error_naming_it(tmp_path):
    with pytest.raises(model.URDFError, match="cannot read URDF .*nope.urdf"):
        model.load(tmp_path / "nope.urdf")
    binary = tmp_path / "binary.urdf"
    binary.write_bytes(b"\x89PNG\r\n\x1a\n\xff\xfe\x00")
    with pytest.raises(model.URDFError, match="binary.urdf is not a text"):
        model.load(binary)


def test_export_cli_reports_bad_urdf_without_traceback(tmp_path):
    path = tmp_path / "bad.urdf"
    path.write_text("<robot name='x'><link name='base'/></robot>")
    done = subprocess.run([sys.executable, "-m", "hopper_mjx.model", "--export", str(tmp_path / "o.xml"),
                           "--urdf", str(path)], capture_output=True, text=True)
    assert done.returncode == 2
    assert "error:" in done.stderr and "Traceback" not in done.stderr


def test_reversed_transmissions_clip_each_joint_at_its_own_limit(tmp_path):
    """Transmissions listed kfe, hfe, haa (actuators in reverse joint order) with reductions 2, 1, 4:
    every joint still saturates at its own URDF effort (haa 40, hfe 80, kfe 80 N·m) and an unsaturated
    torque reaches its joint exactly, whatever the actuator order and gear."""
    from hopper_mjx.control.base import clip_to_limits

    blocks = re.findall(r"  <transmission.*?</transmission>\n", SEED_URDF, flags=re.S)
    assert len(blocks) == 3
    one = "<mechanicalReduction>1</mechanicalReduction>"
    geared = [b.replace(one, f"<mechanicalReduction>{r}</mechanicalReduction>")
              for b, r in zip(blocks, (4, 1, 2))]  # haa, hfe, kfe
    text = SEED_URDF
    for b in blocks:
        text = text.replace(b, "")
    text = text.replace("</robot>", "".join(reversed(geared)) + "</robot>")
    path = tmp_path / "reversed.urdf"
    path.write_text(text)
    m = model.load(path)
    lay = Layout.of(m)
    assert lay.actuator_of_joint == (2, 1, 0) and lay.gear == (4.0, 1.0, 2.0)
    assert lay.effort_limit == (40.0, 80.0, 80.0)
    dofs = list(lay.joint_dof)
    d = mujoco.MjData(m)
    saturated = ([1000.0, -1000.0, 1000.0], [40.0, -80.0, 80.0])
    within = ([-30.0, 70.0, -55.0], [-30.0, 70.0, -55.0])
    for torque, expected in (saturated, within):
        d.ctrl[:] = np.asarray(clip_to_limits(lay, np.array(torque, np.float32)))
        mujoco.mj_forward(m, d)
        np.testing.assert_allclose(d.qfrc_actuator[dofs], expected, rtol=1e-6)


def test_the_robot_fingerprint_tells_robots_apart_and_not_worlds():
    """A policy records the robot it learnt on: another timestep or floor is the same robot, a longer
    shank is another one, and running a policy on it is refused in one line."""
    from hopper_mjx.model.robot import fingerprint, same_robot

    seed, other = model.load(), model.load("tests/data/long_shin_hopper.urdf")
    assert fingerprint(seed) == fingerprint(model.load(timestep=0.002, friction=(0.5, 0.5)))
    assert fingerprint(seed) != fingerprint(other)
    assert same_robot("", other, "a policy") == fingerprint(other)  # unrecorded: accepted
    with pytest.raises(ValueError, match=r"^the policy p is for another robot \(fingerprint \w{16}\) than the one "
                                         r"given \(\w{16}\): give the --urdf it was trained with$"):
        same_robot(fingerprint(other), seed, "the policy p")


def test_the_holding_torque_balances_the_robot_as_mujoco_weighs_it():
    """The joint torques that hold the standing pose: with them and a force at the foot alone, MuJoCo's own
    gravity forces (qfrc_bias at rest, from its recursive Newton-Euler) balance in every degree of freedom; the
    knee carries the load (the centre of mass is above the foot, so the hip almost none), and the strongest
    gravity the robot stands under is the knee's effort limit over its torque per m/s²."""
    from hopper_mjx.model.robot import holding_torque, max_standing_gravity, standing_qpos

    m = model.load()
    lay = Layout.of(m)
    per_g = holding_torque(m)
    d = mujoco.MjData(m)
    d.qpos[:] = standing_qpos(m)
    mujoco.mj_forward(m, d)
    g = -m.opt.gravity[2]
    foot = d.geom_xpos[lay.foot_geom] - [0.0, 0.0, m.geom_size[lay.foot_geom, 0]]
    jac = np.zeros((3, m.nv))
    mujoco.mj_jac(m, d, jac, None, foot, m.geom_bodyid[lay.foot_geom])
    applied = np.zeros(m.nv)
    applied[list(lay.joint_dof)] = per_g * g
    # qfrc_bias = applied + J^T f: solved for f over all nine rows, the residual is zero
    force, *_ = np.linalg.lstsq(jac.T, d.qfrc_bias - applied, rcond=None)
    np.testing.assert_allclose(jac.T @ force + applied, d.qfrc_bias, atol=1e-9)
    np.testing.assert_allclose(force, [0.0, 0.0, m.body_mass.sum() * g], atol=1e-9)  # the floor carries the weight
    assert abs(per_g[2]) > 0.5 and abs(per_g[1]) < 1e-9
    top, joint = max_standing_gravity(m)
    assert joint == 2 and top == pytest.approx(lay.effort_limit[2] / abs(per_g[2]))
