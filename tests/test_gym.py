"""The Gymnasium adapter: Gymnasium's own env checker, its auto-reset semantics, spaces, dtypes, seeding.

One compiled step (2 instances of `stand`, short episodes) shared by every test.
"""

import re

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode

from hopper_mjx.envs.gym import MonopedVectorEnv, SingleEnv

N = 2


@pytest.fixture(scope="module")
def vec():
    return MonopedVectorEnv("stand", num_envs=N, max_episode_steps=3, observe_gravity=True)


def test_spaces_and_dtypes_follow_gymnasium(vec):
    assert isinstance(vec, gymnasium.vector.VectorEnv) and vec.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    assert vec.single_observation_space.shape == (25,) and vec.single_action_space.shape == (3,)
    assert vec.observation_space.shape == (N, 25) and vec.action_space.shape == (N, 3)
    assert vec.single_action_space.dtype == vec.single_observation_space.dtype == np.float32
    obs, info = vec.reset(seed=3)
    assert isinstance(obs, np.ndarray) and obs.dtype == np.float32 and obs in vec.observation_space
    obs, reward, terminated, truncated, info = vec.step(vec.action_space.sample())
    assert obs.shape == (N, 25) and obs.dtype == np.float32
    assert reward.shape == (N,) and reward.dtype == np.float64
    assert terminated.dtype == truncated.dtype == np.bool_ and isinstance(info, dict)


def test_same_seed_same_episode_and_another_seed_differs(vec):
    actions = [np.full((N, 3), 0.2, np.float32), np.full((N, 3), -0.4, np.float32)]

    def run(seed):
        first, _ = vec.reset(seed=seed)
        return [first] + [vec.step(a)[0] for a in actions]

    a, b, c = run(5), run(5), run(6)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)
    assert not np.allclose(a[0], c[0])  # another gravity per instance: the observed g differs


def test_next_step_autoreset(vec):
    """Episodes of 3 steps: the third step is truncated; the fourth ignores its action and returns the
    first observation of a fresh episode, reward 0, neither flag; a new gravity was drawn."""
    obs0, _ = vec.reset(seed=1)
    zero = np.zeros((N, 3), np.float32)
    flags = [vec.step(zero)[2:4] for _ in range(3)]
    assert not any(t.any() for t, _ in flags[:2]) and not any(u.any() for _, u in flags[:2])
    terminated, truncated = flags[2]
    assert (truncated | terminated).all() and not (truncated & terminated).any()
    obs, reward, terminated, truncated, _ = vec.step(np.ones((N, 3), np.float32))
    np.testing.assert_array_equal(reward, 0.0)
    assert not terminated.any() and not truncated.any()
    assert (obs[:, -1] != obs0[:, -1]).all()  # the observed gravity of the fresh episode
    np.testing.assert_array_equal(obs[:, 21:24], 0.0)  # previous action of a fresh episode: none


def test_gymnasium_env_checker_passes_on_one_instance(vec):
    check_env(SingleEnv(vec), skip_render_check=True)


def test_bad_sizes_are_rejected():
    with pytest.raises(ValueError, match="num_envs"):
        MonopedVectorEnv("stand", num_envs=0)
    with pytest.raises(ValueError, match="unknown task"):
        MonopedVectorEnv("fly")


def test_actions_of_another_shape_are_rejected(vec):
    """A reshape took any array of num_envs x 3 values, so (3, 2) ran as (2, 3) with its values moved between
    instances, and (3, 3) failed in NumPy's words."""
    vec.reset(seed=0)
    for shape in ((3, 2), (3, 3), (6,)):
        expected = re.escape(f"actions must be (num_envs, actions) = (2, 3), got {shape}")
        with pytest.raises(ValueError, match=expected):
            vec.step(np.zeros(shape, np.float32))
