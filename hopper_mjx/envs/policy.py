"""`policy:PATH`: a policy trained on any task of `hopper_mjx.envs`, run inside the core's rollout.

A policy directory is a Brax PPO or SAC checkpoint (orbax params + ``ppo_network_config.json``
or ``sac_network_config.json``) with the task's ``hopper_env.json`` beside it
(`write_env_config`; experiments/train.py saves every checkpoint and the final ``policy/`` this way).

The controller replays the environment's control loop: every
``n_frames`` physics steps it builds the same observation (`envs.terms.observe`)
and asks the deterministic policy for new joint targets; at every physics step
the same PD law (`envs.terms.pd_torque`) turns them into torques. Only the physics
differs: the core's own timestep (1 ms) and full constraint solve instead of the
training's (its config's step, and its capped solve); the policy rate stays the same.
"""

from __future__ import annotations

import json
import logging
import math
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
from brax.training import checkpoint as brax_checkpoint
from brax.training import networks as brax_networks
from brax.training.acme import running_statistics
from brax.training.agents.ppo import networks as ppo_networks
from brax.training.agents.sac import networks as sac_networks

from hopper_mjx import registry, terrain
from hopper_mjx.control.base import Commands, Controller, PDScale, Servo, joint_state
from hopper_mjx.engine import batch_any
from hopper_mjx.envs import tasks
from hopper_mjx.envs.task_config import MonopedConfig, decimation
from hopper_mjx.envs.terms import joint_targets, observe, pd_torque
from hopper_mjx.hardware.signals import Observation
from hopper_mjx.model.layout import Layout
from hopper_mjx.model.robot import Robot, same_robot, standing_height, standing_qpos

ENV_CONFIG = "hopper_env.json"
# Brax writes one of these beside the params: which agent's networks to rebuild.
NETWORK_CONFIGS = {"ppo": "ppo_network_config.json", "sac": "sac_network_config.json"}


class PolicyState(NamedTuple):
    command: jax.Array  # the task's command: (3,) apex height m, vx, vy m/s; (0,) for stand
    target: jax.Array  # (3,) joint targets, rad
    last_action: jax.Array  # (3,)
    tick: jax.Array  # () physics steps since the start
    work: jax.Array  # J, ∫ Σ|τ·q̇| dt of the three motors (for the cost of transport)
    pd: PDScale | None = None  # factors on the PD law's gains; None: as trained


def write_env_config(path, env_config: MonopedConfig) -> Path:
    """Puts the task's config beside a Brax checkpoint at `path`: it makes the folder a policy."""
    path = Path(path)
    (path / ENV_CONFIG).write_text(json.dumps(env_config.to_dict(), indent=1))
    return path


def resolve(path) -> Path:
    """A checkpoint directory, or a training output folder (its final ``policy/``)."""
    path = Path(path).resolve()  # orbax reads absolute paths only
    if (path / "policy" / ENV_CONFIG).exists():
        path = path / "policy"
    if not (path / ENV_CONFIG).exists():
        raise ValueError(f"{path} is not a trained policy: no {ENV_CONFIG} (expected an experiments/train.py "
                         "output folder or one of its checkpoints)")
    return path


def algorithm_of(path: Path) -> str:
    found = [algo for algo, name in NETWORK_CONFIGS.items() if (path / name).exists()]
    if len(found) != 1:
        raise ValueError(f"{path} holds no Brax PPO or SAC network config ({', '.join(NETWORK_CONFIGS.values())})")
    return found[0]


# What rebuilding the networks reads from Brax's network config, checked before it is used.
NETWORK_KEYS = ("observation_size", "action_size", "normalize_observations", "network_factory_kwargs")
FACTORY_KEYS = {"ppo": ("policy_hidden_layer_sizes", "value_hidden_layer_sizes", "activation", "distribution_type"),
                "sac": ("hidden_layer_sizes", "activation", "distribution_type")}


def _json_object(file: Path) -> dict:
    """A policy folder's JSON file as a mapping; a file a user edited or a copy cut short: one line naming it."""
    try:
        value = json.loads(file.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise ValueError(f"{file} is not valid JSON ({err.__class__.__name__}: {str(err).splitlines()[0]})") from None
    if not isinstance(value, dict):
        raise ValueError(f"{file} must hold a JSON object, not a {type(value).__name__}")
    return value


def read(path) -> tuple[Path, str, dict, MonopedConfig]:
    """(checkpoint path, algorithm, network config, task config) of a saved policy, checked: the
    network's input size must be the observation size of the task it names. Reads JSON only."""
    path = resolve(path)
    try:
        config = MonopedConfig.from_dict(_json_object(path / ENV_CONFIG))
        expected = tasks.observation_size(config)
    except (TypeError, ValueError) as err:  # an unknown task or field, a value of the wrong type
        raise ValueError(f"{path / ENV_CONFIG}: {err}" if str(path) not in str(err) else str(err)) from None
    algo = algorithm_of(path)
    net_file = path / NETWORK_CONFIGS[algo]
    net = _json_object(net_file)
    missing = [k for k in NETWORK_KEYS if k not in net]
    kwargs = net.get("network_factory_kwargs")
    missing += [f"network_factory_kwargs.{k}" for k in FACTORY_KEYS[algo]
                if not isinstance(kwargs, dict) or k not in kwargs]
    if missing:
        raise ValueError(f"{net_file} lacks {', '.join(missing)}")
    if net["observation_size"] != expected:
        raise ValueError(f"{path}: the policy takes {net['observation_size']} observations but task "
                         f"{config.task!r} (observe_gravity={config.observe_gravity}"
                         f"{', terrain ' + config.terrain if config.terrain else ''}) gives {expected}")
    return path, algo, net, config


def _network(algo: str, net: dict):
    """The Brax networks a checkpoint was trained with, rebuilt from its config (brax 0.14.2's own
    `load_policy` cannot read back the null initialisers it saves)."""
    kwargs = net["network_factory_kwargs"]
    normalize = running_statistics.normalize if net["normalize_observations"] else (lambda x, _: x)
    shared = dict(preprocess_observations_fn=normalize, activation=brax_networks.ACTIVATION[kwargs["activation"]],
                  distribution_type=kwargs["distribution_type"])
    if algo == "ppo":
        network = ppo_networks.make_ppo_networks(
            net["observation_size"], net["action_size"],
            policy_hidden_layer_sizes=tuple(kwargs["policy_hidden_layer_sizes"]),
            value_hidden_layer_sizes=tuple(kwargs["value_hidden_layer_sizes"]), **shared)
        return ppo_networks.make_inference_fn(network)
    network = sac_networks.make_sac_networks(net["observation_size"], net["action_size"],
                                             hidden_layer_sizes=tuple(kwargs["hidden_layer_sizes"]), **shared)
    return sac_networks.make_inference_fn(network)


def check_stored(path: Path) -> None:
    """Reads every entry of the checkpoint's OCDBT store synchronously (tensorstore, as orbax stores it), so that a
    file cut short or missing is refused here: orbax would fail on it inside its asyncio loop, and its reads still
    in flight then print dozens of "Event loop is closed" tracebacks as the process ends."""
    import tensorstore as ts

    if not (path / "manifest.ocdbt").is_file():
        return  # not an OCDBT checkpoint: orbax reads it (and refuses it) alone
    try:
        store = ts.KvStore.open({"driver": "ocdbt", "base": f"file://{path}/"}).result()
        for key in store.list().result():
            store.read(key).result()
    except Exception as err:  # tensorstore's ValueError (OUT_OF_RANGE, DATA_LOSS, NOT_FOUND, ...)
        why = str(err).split(":")[0] if str(err) else type(err).__name__
        raise ValueError(f"{path}: its parameters cannot be read ({why}; a copy cut short?)") from None


def load_network(path):
    """(apply(weights, obs) -> deterministic action, weights, MonopedConfig) of a saved PPO or SAC policy, checked:
    the saved parameters must be readable and fit the network its config describes (traced, not compiled)."""
    path, algo, net, config = read(path)
    check_stored(path)
    absl = logging.getLogger("absl")  # orbax logs (even at error level) what it finds damaged, then goes on or fails
    level = absl.level
    absl.setLevel(logging.CRITICAL)
    try:
        with warnings.catch_warnings():  # orbax warns that it reads the sharding from the checkpoint itself
            warnings.simplefilter("ignore")
            params = brax_checkpoint.load(path)
    except Exception as err:  # orbax's many ways of failing on a damaged checkpoint
        raise ValueError(f"{path}: its parameters cannot be read ({type(err).__name__}; a copy cut short?)") from None
    finally:
        absl.setLevel(level)
    weights = tuple(params[:2])  # the observation normaliser and the policy network
    make_inference = _network(algo, net)

    def apply(weights, obs):
        return make_inference(weights, deterministic=True)(obs, jax.random.PRNGKey(0))[0]

    try:
        jax.eval_shape(apply, weights, jax.ShapeDtypeStruct((net["observation_size"],), jnp.float32))
    except Exception as err:  # flax's shape errors, a layer list that is not numbers, ...
        first = str(err).splitlines()[0] if str(err) else ""
        raise ValueError(f"{path}: its parameters do not fit its network config ({type(err).__name__}: "
                         f"{first[:200]})") from None
    return apply, weights, config


def load(path):
    """(deterministic policy fn obs -> action, MonopedConfig) of a saved PPO or SAC policy (`load_network`)."""
    apply, weights, config = load_network(path)
    return (lambda obs: apply(weights, obs)), config


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class PolicyParams:
    """Per-instance command of a trained policy, (k,) per instance, (n, k) batched: k = 3
    (apex height of the base m above the floor, vx, vy m/s) for the hopping tasks, 0 for stand."""

    command: jax.Array
    pd: PDScale | None = None  # (n, 3) factors on the PD law's kp and kd (`base.pd_scale`); None: as trained


def default_command(config: MonopedConfig) -> jnp.ndarray:
    """Mid-range apex height, standing still (nothing for stand)."""
    if tasks.task_class(config.task).command_size == 0:
        return jnp.zeros(0)
    return jnp.array([0.5 * sum(config.apex_range), 0.0, 0.0])


def check_command(config: MonopedConfig, standing_height: float, height: float, speed) -> None:
    """Raises ValueError if (apex rise, speed) lies outside what the policy was trained on."""
    if tasks.task_class(config.task).command_size == 0:
        return
    apex = standing_height + height
    boxes = (("--height", apex, config.apex_range, standing_height),
             ("--speed VX", speed[0], config.speed_range, 0.0), ("--speed VY", speed[1], config.vy_range, 0.0))
    for flag, value, (lo, hi), offset in boxes:
        if not lo - 1e-6 <= value <= hi + 1e-6:
            raise ValueError(f"{flag} {value - offset:g} is outside the {config.task} policy's trained range "
                             f"[{lo - offset:g}, {hi - offset:g}]")


def policy_params(robot: Robot, n: int, *, height: float, speed=(0.0, 0.0), config=None,
                  pd: PDScale | None = None) -> PolicyParams:
    """Commands from the Raibert controller's terms: `height` m of apex rise above the
    standing height (`Robot.standing_height`), `speed` (vx, vy) m/s; none for a stand policy."""
    if len(speed) != 2:
        raise ValueError(f"speed needs two values (vx, vy) in m/s, got {speed}")
    if not (math.isfinite(height) and height >= 0):
        raise ValueError(f"height must be a finite apex rise >= 0 m, got {height}")
    if config is not None and tasks.task_class(config.task).command_size == 0:
        return PolicyParams(jnp.zeros((n, 0), jnp.float32), pd)
    return PolicyParams(jnp.tile(jnp.array([robot.standing_height + height, *speed], dtype=jnp.float32), (n, 1)), pd)


def policy_controller(mj_model: mujoco.MjModel, path) -> Controller:
    """The trained policy as a core `Controller`; params: per-instance (3,) commands or None."""
    _, algo, net, cfg = read(path)  # JSON only: its robot and ground are checked before the network is built
    same_robot(cfg.robot, mj_model, f"the policy {path}")
    if cfg.terrain and terrain.from_model(mj_model) is None:
        raise ValueError(f"the policy {path} reads a height scan (trained on --terrain {cfg.terrain}): run it on a "
                         "--terrain other than flat")
    apply, weights, cfg = load_network(path)
    layout = Layout.of(mj_model)
    every = decimation(layout, cfg)  # raises if the policy rate does not divide the physics rate
    stance = jnp.asarray(standing_qpos(mj_model)[list(layout.joint_qpos)], jnp.float32)

    def init(obs, params: PolicyParams | None):
        command = default_command(cfg) if params is None else jnp.asarray(params.command, dtype=jnp.float32)
        return PolicyState(command, stance, jnp.zeros(3), jnp.zeros((), jnp.int32), jnp.zeros(()),
                           None if params is None else params.pd)

    def act_with(weights):
        def act(cs: PolicyState, obs: Observation, gravity):
            """The joint targets: new ones every `every` physics steps (the policy rate), held between."""
            features = observe(layout, cfg, obs, gravity, cs.command, cs.last_action)
            decide = cs.tick % every == 0
            # The network only on the steps some instance of the core's chunk decides (a real branch there, not a
            # select): at a 1 kHz core and a 50 Hz policy it would otherwise run 20 times per decision.
            action = jax.lax.cond(batch_any(decide), lambda f: jnp.where(decide, apply(weights, f), cs.last_action),
                                  lambda f: cs.last_action, features)
            target = jnp.where(decide, joint_targets(layout, cfg, stance, action), cs.target)
            return target, cs._replace(target=target, last_action=action, tick=cs.tick + 1)
        return act

    def track(cs: PolicyState, target, obs: Observation):
        """The drivers' PD law on `target` (late by the action delay) and the joints as they are now."""
        torque = pd_torque(layout, cfg, target, obs, cs.pd)
        power = jnp.abs(torque * joint_state(layout, obs)[1]).sum()
        return torque, cs._replace(work=cs.work + power * layout.timestep)

    commands = None
    if tasks.task_class(cfg.task).command_size:  # the hopping tasks: (apex height above the floor, vx, vy)
        standing = standing_height(mj_model)

        def read_command(cs: PolicyState):
            return cs.command[:, 1:], cs.command[:, 0] - standing

        def write_command(cs: PolicyState, speed, rise: float) -> PolicyState:
            row = jnp.array([standing + rise, *speed], jnp.float32)
            return cs._replace(command=jnp.broadcast_to(row, cs.command.shape))

        commands = Commands(read=read_command, write=write_command)
    # What the functions above fold in: the network's form and the task's config (the weights are an argument).
    key = f"policy|{algo}|{json.dumps(net, sort_keys=True)}|{json.dumps(cfg.to_dict(), sort_keys=True)}|{layout!r}"
    return Controller(name=f"{registry.POLICY_PREFIX}{path}", init=init, act=act_with(weights), commands=commands,
                      servo=Servo(track=track, first=lambda cs: cs.target), weights=weights, act_with=act_with,
                      key=key)
