"""Shared, compiled-once fixtures. Tests run on one host device per core, like the CLIs."""

import pytest

from hopper_mjx import runtime

runtime.configure()  # before any JAX computation: 2 host devices here, persistent compile cache


@pytest.fixture(scope="session")
def mj_model():
    from hopper_mjx import model

    return model.load()


@pytest.fixture(scope="session")
def sim(mj_model):
    from hopper_mjx.sim import Sim

    return Sim(mj_model)
