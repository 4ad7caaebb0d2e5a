"""Gazebo world files: what is read from them, what is refused, and their gravity in the batch."""

import jax
import numpy as np
import pytest

from hopper_mjx import model
from hopper_mjx.control.base import zero_torque
from hopper_mjx.hardware import signals
from hopper_mjx.model import world

LOW_GRAVITY = world.LOW_GRAVITY_WORLD
# Same steps, sensors and batch size as test_core's limp drop: one compiled rollout serves both.
STEPS = 500
SENSORS = signals.SensorConfig(imu_rate=100, odom_rate=500, contact_rate=1000, state_rate=1000, torque=True)


def sdf(body: str, version: str = "1.6") -> str:
    return f'<?xml version="1.0"?>\n<sdf version="{version}"><world name="test">{body}</world></sdf>\n'


MARS = sdf("<gravity>0 0 -3.71</gravity><include><uri>model://ground_plane</uri></include>"
           "<physics type='ode'><max_step_size>0.001</max_step_size></physics>")
# A level floor with gravity leaning 0.5 m/s² along x, on a slippery inline ground (mu 0.3, mu2 0.2).
SLOPE = sdf("""
<gravity>0.5 0 -1.62</gravity>
<physics type="ode"><max_step_size>0.001</max_step_size><ode><solver><iters>50</iters></solver></ode></physics>
<model name="ground"><static>true</static><link name="link"><collision name="collision">
  <geometry><plane><normal>0 0 1</normal><size>100 100</size></plane></geometry>
  <surface><friction><ode><mu>0.3</mu><mu2>0.2</mu2></ode></friction><bounce/></surface>
</collision></link></model>
<model name="box"/>""")


def test_the_seeds_low_gravity_world():
    w = world.read(LOW_GRAVITY)
    assert w.gravity == (0.0, 0.0, 0.0)  # "an empty world in gazebo with zero gravity"
    assert w.timestep == 0.001
    assert w.ground_friction == world.GROUND_PLANE_MU
    b = world.batch([w])
    # Gazebo's ground_plane (mu 100, 50) against our foot (1.0): ODE takes the smaller.
    assert b.model_options(model.loader.FOOT_FRICTION) == {"timestep": 0.001, "friction": (1.0, 1.0)}
    warning = b.warning()
    assert "\n" not in warning
    for ignored in ("include model://sun", "physics/real_time_factor", "physics/real_time_update_rate"):
        assert ignored in warning


def test_full_vectors_friction_and_every_ignored_tag_named():
    w = world.parse(SLOPE, "slope.world")
    assert w.gravity == (0.5, 0.0, -1.62) and w.timestep == 0.001 and w.ground_friction == (0.3, 0.2)
    assert set(w.ignored) == {"physics/ode", "model[ground]/surface/bounce", "model[box]"}
    old = world.parse(sdf("<physics><gravity>0 0 -1.62</gravity><max_step_size>0.002</max_step_size></physics>",
                          version="1.4"))
    assert old.gravity == (0.0, 0.0, -1.62) and old.timestep == 0.002 and old.ground_friction is None
    assert world.parse(sdf("")).gravity == world.SDF_DEFAULT_GRAVITY


def test_world_friction_reaches_the_compiled_contact():
    b = world.batch([world.parse(SLOPE, "slope.world")])
    m = model.load(**b.model_options(model.loader.FOOT_FRICTION))
    foot_pair = [i for i in range(m.npair) if m.geom(m.pair_geom2[i]).name == model.FOOT_GEOM]
    np.testing.assert_allclose(m.pair_friction[foot_pair[0], :2], [0.3, 0.2])


@pytest.mark.parametrize("text, message", [
    ("<sdf><world><gravity>0 0</gravity></world></sdf>", "<world><gravity> must be 3 finite numbers"),
    ("<sdf><world><gravity>0 0 nan</gravity></world></sdf>", "3 finite numbers"),
    ("<sdf><world><physics><max_step_size>-1</max_step_size></physics></world></sdf>", "must be > 0"),
    ("<sdf><world><gravity>0 0 -9.8</world></sdf>", "not well-formed XML"),
    ("<robot name='monoped'/>", "expected <sdf><world>"),
])
def test_garbled_worlds_are_refused_in_one_line(text, message):
    with pytest.raises(world.WorldError, match=message) as err:
        world.parse(text, "bad.world")
    assert "\n" not in str(err.value)


def test_a_step_too_long_is_blamed_on_the_files_tag(tmp_path):
    path = tmp_path / "slow.world"
    path.write_text(sdf("<physics><max_step_size>1e6</max_step_size></physics>"))
    with pytest.raises(world.WorldError) as err:
        world.read(path)
    assert str(err.value) == f"{path}: <physics><max_step_size> 1e+06 s is over the 0.01 s a step may take here"


def test_unreadable_files_and_incompatible_batches(tmp_path):
    with pytest.raises(world.WorldError, match="cannot read world file .*missing.world"):  # model.loader.read_text
        world.read(tmp_path / "missing.world")
    fine, fast = world.parse(MARS, "mars.world"), world.parse(sdf("<physics><max_step_size>0.0005</max_step_size>"
                                                                  "</physics>"), "fast.world")
    with pytest.raises(world.WorldError, match="must share <max_step_size>"):
        world.batch([fine, fast])
    with pytest.raises(world.WorldError, match="must share the ground's friction"):
        world.batch([fine, world.parse(SLOPE, "slope.world")])
    with pytest.raises(world.WorldError, match="points up"):
        world.batch([world.parse(sdf("<gravity>0 0 1</gravity>"), "up.world")])


def test_world_gravities_in_one_batch(sim):
    """Zero, Mars and a leaning gravity in one batch of the core: the weightless robot does not move
    at all, the others fall as the semi-implicit Euler step says, the leaning one also drifts along x."""
    b = world.batch([world.read(LOW_GRAVITY), world.parse(MARS, "mars.world"),
                     world.parse(sdf("<gravity>0.5 0 -1.62</gravity>"), "lean.world")])
    limp = zero_torque(sim.layout)
    state = sim.reset(b.gravity, key=7, controller=limp)
    _, traj = sim.rollout(state, limp, steps=STEPS, sensors=SENSORS)
    qpos = np.asarray(traj.qpos)
    np.testing.assert_array_equal(qpos[0], np.broadcast_to(qpos[0, :1], qpos[0].shape))
    assert not np.asarray(traj.contact.flag)[0].any()
    dt, n = sim.layout.timestep, np.arange(qpos.shape[1])
    steps_down = n * (n + 1) / 2 * dt**2  # Σ of the velocity increments, semi-implicit Euler
    airborne = slice(0, 50)  # both falling robots are still in the air after 50 ms
    for i, (gx, _, gz) in enumerate(b.gravity[1:], start=1):
        np.testing.assert_allclose(qpos[i, airborne, 2], qpos[i, 0, 2] + gz * steps_down[airborne], atol=5e-5)
        np.testing.assert_allclose(qpos[i, airborne, 0], qpos[i, 0, 0] + gx * steps_down[airborne], atol=5e-5)
    imu = jax.tree_util.tree_map(np.asarray, traj.imu)
    np.testing.assert_allclose(imu.accel[0], 0.0, atol=1e-4)  # weightless and at rest: no specific force


def test_world_files_give_the_results_of_gravity_values(tmp_path):
    """`simulate --world low_gravity.world mars.world` is `simulate --gravity 0,3.71`, to the bit, in one
    batch. (Two instances, 0.4 s, hold at 100 Hz: test_record's reference run, so one compiled rollout.)"""
    from hopper_mjx import simulate

    mars = tmp_path / "mars.world"
    mars.write_text(MARS)
    common = ["--duration", "0.4", "--controller", "hold", "--rate", "100"]
    by_world = simulate.run(simulate.parser().parse_args(["--world", str(LOW_GRAVITY), str(mars), *common]))
    by_value = simulate.run(simulate.parser().parse_args(["--gravity", "0,3.71", *common]))
    assert by_world.keys() == by_value.keys()
    for key, value in by_value.items():
        np.testing.assert_array_equal(by_world[key], value, err_msg=key)
    qpos, contact = by_world["qpos"], by_world["contact"]
    np.testing.assert_array_equal(qpos[0], np.broadcast_to(qpos[0, :1], qpos[0].shape))  # floats, still
    assert not contact[0].any() and contact[1].any()  # Mars pulls its robot down onto the floor


def test_sweep_takes_downward_worlds_as_its_gravity_grid(tmp_path):
    from hopper_mjx.sweep import __main__ as sweep

    (tmp_path / "mars.world").write_text(MARS)
    (tmp_path / "moon.world").write_text(sdf("<gravity>0 0 -1.62</gravity>"))
    args = sweep.parser().parse_args(["gravity", "--world", str(tmp_path / "moon.world"), str(tmp_path / "mars.world"),
                                      "--out", str(tmp_path / "run")])
    (spec,), out = sweep.check(args)  # one spec: one controller
    assert spec.gravity == (1.62, 3.71) and out == tmp_path / "run" and not out.exists()


def _heightmap_world(tmp_path, heightmap: str, pose: str = ""):
    world_file = tmp_path / "hills.world"
    world_file.write_text(sdf(f"""<gravity>0 0 -3.71</gravity>
<model name="hills"><static>true</static>{pose}<link name="link"><collision name="collision">
  <geometry><heightmap>{heightmap}</heightmap></geometry>
  <surface><friction><ode><mu>0.6</mu><mu2>0.6</mu2></ode></friction></surface>
</collision></link></model>"""))
    return world_file


def test_a_gazebo_heightmap_is_the_ground_the_compiled_model_holds(tmp_path):
    """A world's <heightmap> (PNG relative to the world file, <size> x y z) becomes the terrain: the
    compiled hfield holds the image's grey values times z, its top row at +y, as Gazebo lays it."""
    import imageio.v3 as iio

    from hopper_mjx import simulate
    from hopper_mjx.cli import check_batch
    from hopper_mjx.terrain import from_model

    grey = np.add.outer(np.arange(9), 3 * np.arange(17)).astype(np.uint8) * 3  # 9 rows x 17 columns, distinct
    (tmp_path / "img").mkdir()
    iio.imwrite(tmp_path / "img" / "hills.png", grey)
    world_file = _heightmap_world(tmp_path, "<uri>file://img/hills.png</uri><size>3 2 0.12</size>")
    w = world.read(world_file)
    assert w.terrain == f"heightmap:{tmp_path / 'img' / 'hills.png'},size=3x2,height=0.12"
    assert w.ground_friction == (0.6, 0.6)
    scenario = check_batch(simulate.parser().parse_args(["--world", str(world_file), "--engine", "mjx"]))
    heights = from_model(scenario.physics.mj_model).heights
    np.testing.assert_allclose(heights, 0.12 * grey[::-1] / 255.0, atol=1e-6)  # float32 hfield data
    hfield = scenario.physics.mj_model.hfield_size[0]
    assert tuple(hfield[:2]) == (1.5, 1.0)  # half extents
    with pytest.raises(ValueError, match=r"give --terrain or a world's <heightmap> \(heightmap:.*\), not both"):
        check_batch(simulate.parser().parse_args(["--world", str(world_file), "--terrain", "rough"]))


@pytest.mark.parametrize("heightmap, pose, message", [
    ("<uri>model://hills/hills.png</uri>", "", "needs Gazebo's resource paths"),
    ("<uri>hills.png</uri><pos>1 0 0</pos>", "", r"<pos> 1 0 0 moves it off the origin"),
    ("<uri>hills.png</uri>", "<pose>0 0 0.5 0 0 0</pose>", "the model's <pose> 0 0 0.5 0 0 0 moves it off"),
    ("<uri>hills.png</uri><size>1 -1 1</size>", "", "<size> must be 3 lengths > 0"),
    ("<size>1 1 1</size>", "", "has no <uri>"),
])
def test_heightmaps_the_terrain_cannot_lay_as_gazebo_does_are_refused(tmp_path, heightmap, pose, message):
    with pytest.raises(world.WorldError, match=message):
        world.read(_heightmap_world(tmp_path, heightmap, pose))
