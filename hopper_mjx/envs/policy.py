"""`policy:PATH`: a PPO policy trained on `hopper_mjx.envs.MonopedEnv`, run inside the core's rollout.

A policy directory is a Brax PPO checkpoint (orbax params + ``ppo_network_config.json``)
with the environment's ``hopper_env.json`` beside it, as written by `save`
(experiments/train_ppo.py saves every checkpoint and the final ``policy/`` this way).

The controller replays the environment's control loop: every
``n_frames`` physics steps it builds the same observation (`envs.monoped.observe`)
and asks the deterministic policy for new joint targets; at every physics step
the same PD law (`envs.monoped.pd_torque`) turns them into torques. Only the physics
differs: the core's own timestep (1 ms) and full constraint solve instead of the
training's 2 ms and capped solve; the policy rate stays the same.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
from brax.training import networks as brax_networks
from brax.training.acme import running_statistics
from brax.training.agents.ppo import checkpoint as ppo_checkpoint
from brax.training.agents.ppo import networks as ppo_networks

from hopper_mjx.control.base import Controller, joint_state, to_ctrl
from hopper_mjx.envs import monoped
from hopper_mjx.model.layout import Layout
from hopper_mjx.model.robot import Robot
from hopper_mjx.signals import Observation

ENV_CONFIG = "hopper_env.json"
NETWORK_CONFIG = "ppo_network_config.json"  # written by brax's ppo checkpoint.save


class PolicyState(NamedTuple):
    command: jax.Array  # (3,) apex height m, vx, vy m/s
    target: jax.Array  # (3,) joint targets, rad
    last_action: jax.Array  # (3,)
    tick: jax.Array  # () physics steps since the start
    work: jax.Array  # J, ∫ Σ|τ·q̇| dt of the three motors (for the cost of transport)


def save(directory, step: int, params, network_config, env_config: monoped.MonopedConfig) -> Path:
    """Writes a Brax PPO checkpoint at directory/<step> with the env config beside it."""
    ppo_checkpoint.save(directory, step, params, network_config)
    path = Path(directory) / f"{step:012d}"
    (path / ENV_CONFIG).write_text(json.dumps(env_config.to_dict(), indent=1))
    return path


def resolve(path) -> Path:
    """A checkpoint directory, or a training output folder (its final ``policy/``)."""
    path = Path(path).resolve()  # orbax reads absolute paths only
    if (path / "policy" / ENV_CONFIG).exists():
        path = path / "policy"
    if not (path / ENV_CONFIG).exists():
        raise ValueError(f"{path} is not a trained policy: no {ENV_CONFIG} (expected a train_ppo.py output "
                         "folder or one of its checkpoints)")
    return path


def load(path):
    """(deterministic policy fn obs -> action, MonopedConfig) of a saved policy."""
    path = resolve(path)
    config = monoped.MonopedConfig.from_dict(json.loads((path / ENV_CONFIG).read_text()))
    # brax 0.14.2's own load_policy cannot read back the null initialisers it saves, so the
    # network is rebuilt here from the options train_ppo.py sets.
    net = json.loads((path / NETWORK_CONFIG).read_text())
    kwargs = net["network_factory_kwargs"]
    network = ppo_networks.make_ppo_networks(
        net["observation_size"],
        net["action_size"],
        preprocess_observations_fn=running_statistics.normalize if net["normalize_observations"] else
        (lambda x, _: x),
        policy_hidden_layer_sizes=tuple(kwargs["policy_hidden_layer_sizes"]),
        value_hidden_layer_sizes=tuple(kwargs["value_hidden_layer_sizes"]),
        activation=brax_networks.ACTIVATION[kwargs["activation"]],
        distribution_type=kwargs["distribution_type"],
    )
    inference = ppo_networks.make_inference_fn(network)(ppo_checkpoint.load(path), deterministic=True)
    return (lambda obs: inference(obs, jax.random.PRNGKey(0))[0]), config


def default_command(config: monoped.MonopedConfig) -> jnp.ndarray:
    """Mid-range apex height, standing still."""
    return jnp.array([0.5 * sum(config.apex_range), 0.0, 0.0])


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class PolicyParams:
    """Per-instance command of a trained policy, (3,) per instance, (n, 3) batched."""

    command: jax.Array  # apex height of the base (m, above the floor), vx, vy (m/s)


def policy_params(robot: Robot, n: int, *, height: float, speed=(0.0, 0.0)) -> PolicyParams:
    """Commands from the Raibert controller's terms: `height` m of apex rise above the
    standing height (`Robot.standing_height`), `speed` (vx, vy) m/s."""
    if len(speed) != 2:
        raise ValueError(f"speed needs two values (vx, vy) in m/s, got {speed}")
    if not (math.isfinite(height) and height >= 0):
        raise ValueError(f"height must be a finite apex rise >= 0 m, got {height}")
    return PolicyParams(jnp.tile(jnp.array([robot.standing_height + height, *speed], dtype=jnp.float32), (n, 1)))


def policy_controller(mj_model: mujoco.MjModel, path) -> Controller:
    """The trained policy as a core `Controller`; params: per-instance (3,) commands or None."""
    policy, cfg = load(path)
    layout = Layout.of(mj_model)
    every = monoped.decimation(layout, cfg)  # raises if the policy rate does not divide the physics rate
    stance = jnp.asarray(monoped.stance_qpos(mj_model)[list(layout.joint_qpos)])

    def init(obs, params: PolicyParams | None):
        command = default_command(cfg) if params is None else jnp.asarray(params.command, dtype=jnp.float32)
        return PolicyState(command, stance, jnp.zeros(3), jnp.zeros((), jnp.int32), jnp.zeros(()))

    def act(cs: PolicyState, obs: Observation, gravity):
        features = monoped.observe(layout, cfg, obs, gravity, cs.command, cs.last_action)
        decide = cs.tick % every == 0
        action = jnp.where(decide, policy(features), cs.last_action)
        target = jnp.where(decide, monoped.joint_targets(layout, cfg, stance, action), cs.target)
        torque = monoped.pd_torque(layout, cfg, target, obs)
        power = jnp.abs(torque * joint_state(layout, obs)[1]).sum()
        work = cs.work + power * layout.timestep
        return to_ctrl(layout, torque), PolicyState(cs.command, target, action, cs.tick + 1, work)

    return Controller(name=f"policy:{path}", init=init, act=act)
