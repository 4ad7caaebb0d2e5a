"""The tasks: what each commands and what it rewards. Everything else is `MonopedEnv`'s.

| task | command (per episode) | task reward terms |
|---|---|---|
| `stand` | none: stay up in place, small hops allowed | alive, height band (crouch to a small apex), speed (to zero) |
| `hop` | apex height, zero speed | apex (ballistic), speed (to zero) |
| `hop_velocity` | apex height and (vx, vy) | apex (ballistic), speed (to the command) |
| `hop_terrain` | apex height and (vx, vy), on the training course | as `hop_velocity`; the height scan is observed |

Every task also pays `terms.posture_terms` (upright, effort, smoothness, spin, fall).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from hopper_mjx import registry
from hopper_mjx.envs.monoped import MonopedEnv
from hopper_mjx.envs.task_config import MonopedConfig
from hopper_mjx.envs.terms import closeness, outside, predicted_apex, speed_term
from hopper_mjx.envs.terms import observation_size as monoped_observation_size
from hopper_mjx.metrics import thresholds

# The gravity range every task draws from by default, m/s², log-uniform.
GRAVITY_RANGE = (0.5, 12.0)


class Stand(MonopedEnv):
    """Stay up, upright and in place under kicks; small hops allowed.

    Standing still on the ball foot is ill-posed under kicks (docs/control.md, "Standing balance":
    an LQR keeps none of 64 kicked robots up; Raibert hopping in place at 5 cm keeps all), so the
    task pays being up, not being still: the base anywhere from a crouch to a small hop's apex
    (`height_band`, up to `thresholds.STAND_MAX_RISE`), upright (the shared term), not drifting.
    Its reference is Raibert at a small apex (`registry.TASK_REFERENCES`)."""

    command_size = 0

    @classmethod
    def default_config(cls) -> MonopedConfig:
        # Effort weighed as in the hopping tasks: small hops are how this task is done.
        return MonopedConfig(task="stand", gravity_range=GRAVITY_RANGE, apex_range=(0.0, 0.0),
                             speed_range=(0.0, 0.0), w_alive=1.0, w_height=1.0,
                             height_band=(-0.15, thresholds.STAND_MAX_RISE), w_apex=0.0, w_speed=0.5,
                             w_effort=0.05)

    def sample_command(self, key: jax.Array) -> jax.Array:
        return jnp.zeros(0)

    def task_terms(self, d, g: jax.Array, command: jax.Array, apex=None) -> dict[str, jax.Array]:
        cfg = self.config
        # The ballistic apex, so a hop above the band loses from its take-off on, not only at its top.
        rise = predicted_apex(d, g) - self.standing_height
        return {
            "alive": jnp.float32(cfg.w_alive),
            "height": cfg.w_height * closeness(outside(rise, cfg.height_band), cfg.height_scale),
            "speed": speed_term(cfg, d, jnp.zeros(2)),
        }


class Hop(MonopedEnv):
    """Hop in place to a commanded apex height (today's environment; `speed_range` may be widened)."""

    command_size = 3  # apex height m, vx, vy m/s

    @classmethod
    def default_config(cls) -> MonopedConfig:
        # Apex 0.95-1.2 m: rises of 0.068-0.318 m, the sweep's default 0.10 m among them.
        return MonopedConfig(task="hop", gravity_range=GRAVITY_RANGE, apex_range=(0.95, 1.2), speed_range=(0.0, 0.0))

    def sample_command(self, key: jax.Array) -> jax.Array:
        """(apex height m, vx m/s, vy m/s), uniform over the configured ranges."""
        cfg = self.config
        k_apex, k_vx, k_vy = jax.random.split(key, 3)
        draw = lambda k, bounds: jax.random.uniform(k, (1,), minval=bounds[0], maxval=bounds[1])
        return jnp.concatenate([draw(k_apex, cfg.apex_range), draw(k_vx, cfg.speed_range),
                                draw(k_vy, cfg.vy_range)])

    def task_terms(self, d, g: jax.Array, command: jax.Array, apex=None) -> dict[str, jax.Array]:
        cfg = self.config
        apex = predicted_apex(d, g) if apex is None else apex
        return {
            "apex": cfg.w_apex * closeness(apex - command[0], cfg.apex_scale),
            "speed": speed_term(cfg, d, command[1:3]),
        }


class HopVelocity(Hop):
    """Hop while tracking a commanded (vx, vy) and apex height. The command box is one the
    Raibert controller tracks at every gravity of the range (docs/learning.md)."""

    @classmethod
    def default_config(cls) -> MonopedConfig:
        # Apex 0.93-1.03 m: a rise of 0.048-0.148 m over the 0.882 m standing height. The apex
        # kernel is narrower and weighs more than hop's: a hop's speed swings through every stance,
        # so shuffling forward on 1-2 cm hops earns more speed reward than hopping does, and with
        # hop's 0.1 m kernel that gain outweighed the apex reward it lost (docs/learning-notebook.md).
        return MonopedConfig(task="hop_velocity", gravity_range=GRAVITY_RANGE, apex_range=(0.93, 1.03),
                             speed_range=(-0.5, 0.5), lateral_speed_range=(-0.3, 0.3), w_speed=1.0,
                             w_apex=2.0, apex_scale=0.04)


# The training course (`terrain.generators.course`): five levels of rough ground, steps, gaps and blocks, the
# hardest 0.04 m rough, 0.08 m risers, 0.3 m gaps and 0.15 m blocks; episodes start on a tile of their level
# (`envs.curriculum`). Until 3 Dec 2026 it was one rough ground, now the first its policies are judged on
# (`curriculum.JUDGE_GROUNDS`).
HOP_TERRAIN = "course:seed=1"


class HopTerrain(HopVelocity):
    """`hop_velocity` over the training course, reading the ground's height around the base (the height scan,
    the config's `scan`), each episode on a tile of its curriculum level (`envs.curriculum`). The apex is the base's
    height in the world, as the evaluation measures it."""

    @classmethod
    def default_config(cls) -> MonopedConfig:
        return dataclasses.replace(HopVelocity.default_config(), task="hop_terrain", terrain=HOP_TERRAIN)


TASKS: dict[str, type[MonopedEnv]] = {"stand": Stand, "hop": Hop, "hop_velocity": HopVelocity,
                                      "hop_terrain": HopTerrain}


def names() -> list[str]:
    return list(registry.TASKS)


def task_class(name: str) -> type[MonopedEnv]:
    registry.check("task", registry.TASKS, name)
    return TASKS[name]


def observation_size(config: MonopedConfig) -> int:
    """The observations a policy of `config` takes (`terms.observation_size`)."""
    return monoped_observation_size(task_class(config.task).command_size, config.observe_gravity, config.scan_size)


def default_config(name: str) -> MonopedConfig:
    return task_class(name).default_config()


def make(name: str, mj_model=None, **overrides) -> MonopedEnv:
    """The task `name` with its `default_config()`, fields replaced by `overrides`."""
    cls = task_class(name)
    known = {f.name for f in dataclasses.fields(MonopedConfig)} - {"task"}
    unknown = set(overrides) - known
    if unknown:
        raise ValueError(f"unknown {name} config field(s): {sorted(unknown)}")
    return cls(dataclasses.replace(cls.default_config(), **overrides), mj_model)


def from_config(config: MonopedConfig, mj_model=None) -> MonopedEnv:
    """The env a saved config describes (a trained policy's `hopper_env.json`)."""
    return task_class(config.task)(config, mj_model)
