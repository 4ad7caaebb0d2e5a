"""Shared, compiled-once fixtures. Tests run on one host device per core, like the CLIs."""

import pytest

from hopper_mjx.shell import jaxsetup

# Before any JAX computation: 2 host devices here, persistent compile cache; stderr left to pytest's capture (the
# commands' filtered stderr is tested on their own processes, tests/test_command.py).
jaxsetup.configure(quiet=False)
pytest_plugins = ("build_time",)  # the report of how long each test spent building programs

# The files that take longest with an empty compile cache, longest first: each file's setup, call and teardown times
# summed from `make test`'s parallel phase run with `--durations=0` (1 Dec, 2 cores; the refusal files since made
# cheap: their processes no longer import JAX). `make test` hands whole files to two processes in collection order
# (`--dist loadfile --no-loadscope-reorder`): a long file handed out last would leave the other process idle at the end.
LONGEST_FIRST = ("test_tour.py", "test_core.py", "test_terrain_physics.py", "test_chain.py", "test_control.py",
                 "test_bench.py", "test_chain_terrain.py", "test_chain_terrain_legs.py",  # 50-70 s warm, 140 s cold
                 "test_jump.py", "test_latency.py",
                 "test_train.py", "test_policy.py", "test_actuators.py",
                 "test_train_sac.py", "test_faults.py",
                 "test_leap_against_c.py",  # well after test_jump.py: it reads back their run's stored program
                 "test_sweep.py", "test_chain_terrain_box.py", "test_step.py",
                 "test_variation.py", "test_export_onnx.py", "test_programs.py", "test_cross_cpu.py", "test_env.py",
                 "test_raibert.py", "test_render.py", "test_bad_inputs.py", "test_hostile.py",
                 "test_control_variation.py", "test_balance.py", "test_record.py", "test_env_robot_io.py",
                 "test_command.py")


def pytest_collection_modifyitems(items):
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: the others keep pytest's order


@pytest.fixture(scope="session")
def mj_model():
    from hopper_mjx import model

    return model.load()


@pytest.fixture(scope="session")
def sim(mj_model):
    from hopper_mjx.sim import Sim

    return Sim(mj_model)


@pytest.fixture(scope="session")
def jump_leaps():
    """The jump's leaps over the sweeps' blocks and gaps, run once for the two files that check them (test_jump,
    test_leap_against_c): its program on a terrain with DC motors takes minutes to trace and compile."""
    from test_jump import leap_run

    return leap_run()
