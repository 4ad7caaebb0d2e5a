"""Reinforcement-learning tasks over the monoped: `make(name, **overrides)` -> Brax `Env`.

    from hopper_mjx import envs
    envs.names()                                   # ['stand', 'hop', 'hop_velocity']
    env = envs.make("hop_velocity", observe_gravity=True)
    envs.default_config("hop")                     # a task's defaults, in one place
"""

from hopper_mjx.envs.monoped import MonopedEnv
from hopper_mjx.envs.task_config import MonopedConfig
from hopper_mjx.envs.tasks import default_config, from_config, make, names

__all__ = ["MonopedConfig", "MonopedEnv", "default_config", "from_config", "make", "names"]
