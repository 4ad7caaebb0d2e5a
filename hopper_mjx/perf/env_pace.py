"""How fast a task's training env steps its physics, to set beside the core's (`perf.bench --env TASK`).

Brax's PPO and SAC step the env for `--num-envs` instances split over the local devices (pmap), a policy
decision every `n_frames` physics steps, inside its training step. This times that unroll alone: the env as
train.py wraps it (auto-reset, episode counter), sharded the same way, the stance held (zero actions) or under
random actions (`ACTIONS`): an untrained policy's robots flail and fall, and their legs and bases meet the ground
as a standing robot's never do. Its physics steps/s beside the core's at the same N say whether training's physics
keeps the core's pace; train.py's env steps/s beside this one's say how much of a training step is the learner's
(its gradient steps, the policy, Brax's evaluations).
"""

from __future__ import annotations

import dataclasses
import time

EPISODE = 1_000_000  # policy steps: no episode ends by its length inside a timed unroll
ACTIONS = {"hold": "stance held", "random": "random actions"}  # --env-actions: what each means in the table


def run(task: str, num: int, steps: int, physics, repeat: int = 2, actions: str = "hold") -> dict:
    """`steps` physics steps of `num` instances of `task`'s env on `physics` (its robot, engine, timestep, ground
    and robots drawn per episode), best of `repeat` timed runs after a first (compiling) one, each from the same
    reset; `actions` "hold" (zeros) or "random" (uniform in [-1, 1], drawn anew each policy step from a fixed key,
    the same in every run). The JSON record's `env_` fields."""
    import jax
    import jax.numpy as jnp

    from hopper_mjx import envs
    from hopper_mjx.envs.wrappers import wrap_for_training

    overrides = {"engine": physics.engine, "timestep": physics.timestep,
                 "terrain": "" if physics.ground.is_flat else str(physics.ground)}
    if physics.variation:
        overrides |= {"randomize": str(physics.variation), "randomize_seed": 0}
    env = envs.from_config(dataclasses.replace(envs.default_config(task), **overrides), physics.mj_model)
    if steps % env.n_frames:
        raise ValueError(f"--steps={steps} must be whole policy steps of {env.n_frames} physics steps for --env {task}")
    devices = jax.local_device_count()
    if num % devices:
        raise ValueError(f"--num={num} must be a multiple of the {devices} local devices for --env")
    wrapped, per = wrap_for_training(env, episode_length=EPISODE), num // devices
    keys = jax.random.split(jax.random.PRNGKey(0), num).reshape(devices, per, -1)
    start = jax.block_until_ready(jax.pmap(wrapped.reset)(keys))
    decisions = steps // env.n_frames
    if actions == "hold":
        drawn = jnp.zeros((devices, decisions, per, env.action_size))
    else:
        drawn = jax.random.uniform(jax.random.PRNGKey(1), (devices, decisions, per, env.action_size), minval=-1.0,
                                   maxval=1.0)

    def unroll(state, each):
        return jax.lax.scan(lambda s, action: (wrapped.step(s, action), None), state, each)[0]

    stepped = jax.pmap(unroll)
    clock = time.perf_counter()
    final = jax.block_until_ready(stepped(start, drawn))
    first = time.perf_counter() - clock
    runs = []
    for _ in range(repeat):
        clock = time.perf_counter()
        jax.block_until_ready(stepped(start, drawn))
        runs.append(time.perf_counter() - clock)
    best = min(runs)
    # One pass through the compiled unroll's loops: a physics step (the frame loop's body) and the env's own work
    # around it once (actions to targets, reward, observation, auto-reset), as the core's count is one step.
    from hopper_mjx.perf import kernels

    count = kernels.count(stepped.lower(start, drawn).compile().as_text())
    return {"env_kernels_per_pass": count, "env_task": task, "env_actions": actions,
            "env_steps_per_s": num * steps / env.n_frames / best,
            "env_physics_steps_per_s": num * steps / best, "env_policy_rate_hz": 1.0 / env.dt,
            "env_first_call_s": first, "env_runs_s": runs,
            # each instance's simulated time: `steps` physics steps of the timestep unless an episode ended
            "env_final_time_s": [float(t) for t in jax.device_get(final.pipeline_state.time).ravel()]}
