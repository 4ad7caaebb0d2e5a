"""Gymnasium over any task: `MonopedVectorEnv` (a `gymnasium.vector.VectorEnv`), numpy in and out.

    from hopper_mjx.envs.gym import MonopedVectorEnv
    env = MonopedVectorEnv("hop", num_envs=64, max_episode_steps=500)
    obs, info = env.reset(seed=0)                       # (64, 27) float32
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())

All instances step together in one compiled, vmapped call of the task's Brax `step`.
Auto-reset follows Gymnasium 1.x's default, `AutoresetMode.NEXT_STEP`: the step after an
instance ends (terminated: a fall; truncated: `max_episode_steps` reached) resets it, ignores
its action and returns its first observation with reward 0 and both flags False. A reset
draws a fresh gravity, command and initial state. `reset(seed=s)` fixes every draw that follows.
`SingleEnv` is one instance as a `gymnasium.Env` (for Gymnasium's env checker and single-env code).
"""

from __future__ import annotations

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from hopper_mjx.envs import tasks
from hopper_mjx.envs.wrappers import where_done


class MonopedVectorEnv(gymnasium.vector.VectorEnv):
    """`num_envs` instances of task `task` (with config `overrides`), stepped together."""

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(self, task: str = "hop", num_envs: int = 16, max_episode_steps: int = 500, **overrides):
        if num_envs < 1 or max_episode_steps < 1:
            raise ValueError(f"num_envs and max_episode_steps must be >= 1, got {num_envs}, {max_episode_steps}")
        self.env = tasks.make(task, **overrides)
        self.num_envs, self.max_episode_steps = num_envs, max_episode_steps
        self.single_observation_space = spaces.Box(-np.inf, np.inf, (self.env.observation_size,), np.float32)
        self.single_action_space = spaces.Box(-1.0, 1.0, (self.env.action_size,), np.float32)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        reset, step = jax.vmap(self.env.reset), self.env.batch_step

        def step_or_reset(state, action, needs_reset, keys):
            stepped, fresh = step(state, action), reset(keys)
            state = where_done(needs_reset, fresh, stepped)
            reward = jnp.where(needs_reset, 0.0, stepped.reward)
            return state, reward, (stepped.done > 0) & ~needs_reset

        self._reset, self._step = jax.jit(reset), jax.jit(step_or_reset)
        self._state = None
        self._key = None

    def _keys(self) -> jax.Array:
        self._key, sub = jax.random.split(self._key)
        return jax.random.split(sub, self.num_envs)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)  # seeds self.np_random as Gymnasium does
        if seed is not None or self._key is None:
            self._key = jax.random.PRNGKey(int(self.np_random.integers(2**31)))
        self._state = self._reset(self._keys())
        self._steps = np.zeros(self.num_envs, np.int64)
        self._needs_reset = np.zeros(self.num_envs, bool)
        return np.array(self._state.obs), {}

    def step(self, actions):
        if self._state is None:
            raise RuntimeError("call reset() before step()")
        actions = np.asarray(actions, np.float32)
        if actions.shape != self.action_space.shape:  # a reshape took any array of that size, in any layout
            raise ValueError(f"actions must be (num_envs, actions) = {self.action_space.shape}, got {actions.shape}")
        self._state, reward, terminated = self._step(self._state, jnp.asarray(actions),
                                                     jnp.asarray(self._needs_reset), self._keys())
        terminated = np.array(terminated)
        self._steps = np.where(self._needs_reset, 0, self._steps + 1)
        truncated = (self._steps >= self.max_episode_steps) & ~terminated
        self._needs_reset = terminated | truncated
        return np.array(self._state.obs), np.array(reward, np.float64), terminated, truncated, {}


class SingleEnv(gymnasium.Env):
    """Instance 0 of a `MonopedVectorEnv` as a `gymnasium.Env` (it ends at termination or truncation;
    call `reset` to go on, as a single Gymnasium env expects)."""

    metadata = {"render_modes": []}

    def __init__(self, vector: MonopedVectorEnv):
        self.vector = vector
        self.observation_space = vector.single_observation_space
        self.action_space = vector.single_action_space

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        obs, info = self.vector.reset(seed=seed)
        return obs[0], info

    def step(self, action):
        batch = np.repeat(np.asarray(action, np.float32)[None], self.vector.num_envs, axis=0)
        obs, reward, terminated, truncated, info = self.vector.step(batch)
        return obs[0], float(reward[0]), bool(terminated[0]), bool(truncated[0]), info
