"""Brax's training wrappers, with an auto-reset that starts a fresh episode.

`BatchWrapper` steps a batch with the engine's model as one run-time value.
Brax's `AutoResetWrapper` returns a finished environment to the state its first
`reset` produced, so the gravity and command drawn there would stay for the whole
run. `ResampleAutoReset` resets a finished environment with a new key instead:
every episode draws its own gravity, command and initial state.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from brax.envs.base import State, Wrapper
from brax.envs.wrappers.training import EpisodeWrapper


def where_done(done: jax.Array, fresh, old):
    """`fresh` where `done` (a mask over the leading axes), else `old`, leaf by leaf."""
    return jax.tree_util.tree_map(
        lambda x, y: jnp.where(done.reshape(done.shape + (1,) * (x.ndim - done.ndim)), x, y), fresh, old)


class BatchWrapper(Wrapper):
    """Brax's `VmapWrapper` for a `MonopedEnv`: a batch of instances, stepped by `batch_step` so that
    the engine's model is one run-time value for the whole batch (see `MonopedEnv.run_time_model`)."""

    def reset(self, rng: jax.Array) -> State:
        return jax.vmap(self.env.reset)(rng)

    def step(self, state: State, action: jax.Array) -> State:
        return self.env.batch_step(state, action)


class ResampleAutoReset(Wrapper):
    """On `done`, the environment's pipeline state, observation and task info come from a fresh
    `reset` (keyed by the episode's own `info["rng"]`); the episode bookkeeping stays as stepped. On a course the
    fresh episode's level follows from how the finished one went (`curriculum.Curriculum.next_level`)."""

    def step(self, state: State, action: jax.Array) -> State:
        if "steps" in state.info:  # EpisodeWrapper's counter restarts after a reset, as in Brax
            steps = jnp.where(state.done, jnp.zeros_like(state.info["steps"]), state.info["steps"])
            state = state.replace(info={**state.info, "steps": steps})
        state = self.env.step(state.replace(done=jnp.zeros_like(state.done)), action)
        keys = jax.vmap(lambda k: jax.random.split(k)[1])(state.info["rng"])
        done = state.done > 0
        if "level" in state.info:  # the terrain curriculum: the next episode's level from how this one ended
            info = state.info
            travelled = jnp.linalg.norm(state.pipeline_state.qpos[:, :2] - info["start"], axis=-1)
            asked = jnp.linalg.norm(info["command"][:, 1:3], axis=-1) * info["steps"] * self.env.dt
            level = jax.vmap(self.env.curriculum.next_level)(info["level"], info["truncation"] > 0, travelled,
                                                             asked, keys)
            fresh = jax.vmap(self.env.reset_at)(keys, level)
        else:
            fresh = self.env.reset(keys)
        info = {**state.info, **{k: where_done(done, fresh.info[k], state.info[k]) for k in self.env.task_info}}
        return state.replace(pipeline_state=where_done(done, fresh.pipeline_state, state.pipeline_state),
                             obs=where_done(done, fresh.obs, state.obs), info=info)


def wrap_for_training(env, episode_length: int = 1000, action_repeat: int = 1, randomization_fn=None):
    """Brax's `training.wrap` with `ResampleAutoReset`; gravity is the env's own per-episode draw,
    so no `randomization_fn` is taken."""
    if randomization_fn is not None:
        raise ValueError("the monoped tasks draw gravity per episode themselves; pass no randomization_fn")
    return ResampleAutoReset(EpisodeWrapper(BatchWrapper(env), episode_length, action_repeat))
