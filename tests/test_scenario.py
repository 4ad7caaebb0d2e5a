"""The scenario: one typed description of a batch, from the command line, a YAML file or Python,
checked whole before anything is built (no compile in this file)."""

import numpy as np
import pytest

from hopper_mjx import cli, simulate
from hopper_mjx.scenario import Scenario


def scenario_of(argv) -> Scenario:
    return cli.check_batch(simulate.parser().parse_args(argv))


def test_the_command_line_builds_the_whole_scenario():
    s = scenario_of(["--gravity", "9.81,1.62", "--num", "3", "--controller", "raibert", "--height", "0.12",
                     "--speed", "0.3,0", "--seed", "5", "--engine", "mjx", "--timestep", "0.002"])
    assert s.n == 6 and s.gravity.shape == (6, 3)
    np.testing.assert_allclose(s.gravity[:, 2], [-9.81] * 3 + [-1.62] * 3)  # gravity-major
    assert (s.controller, s.height, s.speed, s.seed, s.physics.engine, s.timestep) == ("raibert", 0.12, (0.3, 0.0),
                                                                                      5, "mjx", 0.002)
    assert s.physics.urdf is None and s.physics.ground.is_flat and s.physics.variation is None


def test_the_terrain_spec_is_the_scenarios_ground(tmp_path):
    s = scenario_of(["--terrain", "obstacle:height=0.12,x=0.8", "--engine", "mjx"])
    ground = s.physics.ground
    assert ground.name == "obstacle" and dict(ground.values) == {"height": 0.12, "x": 0.8, "length": 0.1}
    assert str(s.physics.ground) == "obstacle:height=0.12,x=0.8,length=0.1,size=4x4,cell=0.04"
    (tmp_path / "rough.yaml").write_text("terrain: rough:amp=0.02,seed=3\nengine: auto\n")
    s = scenario_of(["--scenario", str(tmp_path / "rough.yaml")])
    ground = s.physics.ground
    assert ground.name == "rough" and dict(ground.values)["seed"] == 3 and s.physics.engine == "auto"
    heights = s.physics.ground.terrain().heights
    assert np.abs(heights).max() == pytest.approx(0.02) and heights.shape == (101, 101)
    import imageio.v3 as iio

    (tmp_path / "maps").mkdir()
    iio.imwrite(tmp_path / "maps" / "g.png", np.full((3, 4), 255, np.uint8))
    (tmp_path / "hm.yaml").write_text("terrain: heightmap:maps/g.png,height=0.04\n")  # from the file's folder
    s = scenario_of(["--scenario", str(tmp_path / "hm.yaml")])
    assert s.physics.ground.path == str(tmp_path / "maps" / "g.png") and s.physics.ground.shape == (3, 4)
    assert s.physics.ground.start_height() == pytest.approx(0.04)  # the cell around the start, however coarse
    np.testing.assert_allclose(s.physics.ground.terrain().heights, 0.04)


def test_a_scenario_file_sets_options_and_the_command_line_wins(tmp_path):
    (tmp_path / "robot").mkdir()
    urdf = (tmp_path / "robot" / "leg.urdf")
    urdf.write_text(open("tests/data/long_shin_hopper.urdf").read())
    f = tmp_path / "moon.yaml"
    f.write_text("gravity: [1.62, 3.71]\nnum: 2\ncontroller: raibert\nspeed: [0.2, 0]\nurdf: robot/leg.urdf\n")
    s = scenario_of(["--scenario", str(f), "--num", "4"])
    assert s.n == 8 and s.controller == "raibert" and s.speed == (0.2, 0.0)
    np.testing.assert_allclose(s.gravity[::4, 2], [-1.62, -3.71])
    assert s.physics.urdf == str(urdf)  # a path in the file is read from the file's folder


def test_a_randomize_block_is_the_same_variation_as_the_option(tmp_path):
    from hopper_mjx.variation.spec import Spec

    f = tmp_path / "rough.yaml"
    f.write_text("num: 4\nseed: 3\nrandomize:\n  foot_friction: uniform(0.4, 1.0)\n  base_mass: scale(0.9,1.1)\n"
                 "  dof_damping: 0.1\n  base_com: -0.02..0.02\n")
    s = scenario_of(["--scenario", str(f)])
    same = scenario_of(["--num", "4", "--seed", "3", "--randomize",
                        "foot_friction=0.4..1,base_mass=scale(0.9,1.1),dof_damping=0.1,base_com=-0.02..0.02"])
    assert s.physics.variation == same.physics.variation == Spec.parse(str(same.physics.variation))
    assert s.physics.variation.names == ("foot_friction", "base_mass", "dof_damping", "base_com")
    assert scenario_of(["--scenario", str(f), "--randomize", "dof_armature=0.01"]).physics.variation.names == \
        ("dof_armature",)  # the command line wins over the file, as for every option


@pytest.mark.parametrize("text, message", [
    ("gravity: [9.81]\nwings: 2\n", "unknown option(s) wings; known: "),
    ("- 9.81\n", "must be a mapping of option names to values"),
    ("num: many\n", "num: invalid literal for int()"),
    ("gravity: [9.81, x]\n", "gravity: --gravity must be comma-separated numbers"),
    ("gravity: [9.81\n", "not YAML"),
])
def test_a_bad_scenario_file_is_one_line_naming_it(tmp_path, capsys, text, message):
    f = tmp_path / "bad.yaml"
    f.write_text(text)
    with pytest.raises(SystemExit) as exit_:
        simulate.parser().parse_args(["--scenario", str(f)])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and err.count("\n") == 1
    assert err.startswith(f"error: --scenario {f}: ") and message in err


def test_the_physics_compiles_its_model_once_on_first_use(monkeypatch):
    """The checks (a policy's robot) and the build share one compiled model: no second compile."""
    from hopper_mjx import model

    compiled = []
    load = model.load
    monkeypatch.setattr(model, "load", lambda *a, **k: compiled.append(a) or load(*a, **k))
    s = scenario_of(["--gravity", "9.81", "--urdf", "tests/data/long_shin_hopper.urdf"])
    first = s.physics.mj_model
    assert s.physics.mj_model is first and len(compiled) == 1
    assert first.body_mass.sum() == pytest.approx(model.load("tests/data/long_shin_hopper.urdf").body_mass.sum())


def test_every_tool_that_lays_out_its_own_instances_takes_the_same_physics_options():
    """The sweeps, the bench, the profile and training read --urdf and --engine through one function."""
    import argparse

    from hopper_mjx.perf import bench
    from hopper_mjx.sweep import __main__ as sweep

    argv = ["--urdf", "tests/data/long_shin_hopper.urdf", "--engine", "mjx"]
    sweep_args = sweep.parser().parse_args(["gravity", *argv])
    bench_args = bench.parser().parse_args(argv)
    for args in (sweep_args, bench_args):
        physics = cli.check_physics(args)
        assert (physics.urdf, physics.engine) == ("tests/data/long_shin_hopper.urdf", "mjx")
    with pytest.raises(ValueError, match="unknown engine 'warp'"):
        cli.check_physics(argparse.Namespace(urdf=None, engine="warp"))
