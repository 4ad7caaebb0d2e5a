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
    assert (s.controller, s.height, s.speed, s.seed, s.engine, s.timestep) == ("raibert", 0.12, (0.3, 0.0), 5,
                                                                              "mjx", 0.002)
    assert s.urdf is None and s.ground == "flat" and s.variation is None


def test_a_scenario_file_sets_options_and_the_command_line_wins(tmp_path):
    (tmp_path / "robot").mkdir()
    urdf = (tmp_path / "robot" / "leg.urdf")
    urdf.write_text(open("tests/data/long_shin_hopper.urdf").read())
    f = tmp_path / "moon.yaml"
    f.write_text("gravity: [1.62, 3.71]\nnum: 2\ncontroller: raibert\nspeed: [0.2, 0]\nurdf: robot/leg.urdf\n")
    s = scenario_of(["--scenario", str(f), "--num", "4"])
    assert s.n == 8 and s.controller == "raibert" and s.speed == (0.2, 0.0)
    np.testing.assert_allclose(s.gravity[::4, 2], [-1.62, -3.71])
    assert s.urdf == str(urdf)  # a path in the file is read from the file's folder


def test_a_randomize_block_is_the_same_variation_as_the_option(tmp_path):
    from hopper_mjx.randomize import Spec

    f = tmp_path / "rough.yaml"
    f.write_text("num: 4\nseed: 3\nrandomize:\n  foot_friction: uniform(0.4, 1.0)\n  base_mass: scale(0.9,1.1)\n"
                 "  dof_damping: 0.1\n  base_com: -0.02..0.02\n")
    s = scenario_of(["--scenario", str(f)])
    same = scenario_of(["--num", "4", "--seed", "3", "--randomize",
                        "foot_friction=0.4..1,base_mass=scale(0.9,1.1),dof_damping=0.1,base_com=-0.02..0.02"])
    assert s.variation == same.variation == Spec.parse(str(same.variation))
    assert s.variation.names == ("foot_friction", "base_mass", "dof_damping", "base_com")
    assert scenario_of(["--scenario", str(f), "--randomize", "dof_armature=0.01"]).variation.names == \
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
