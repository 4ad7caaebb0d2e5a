"""Reinforcement-learning tasks over the monoped: `make(name, **overrides)` -> Brax `Env`.

    from hopper_mjx import envs
    envs.names()                                   # ['stand', 'hop', 'hop_velocity', 'hop_terrain']
    env = envs.make("hop_velocity", observe_gravity=True)
    envs.default_config("hop")                     # a task's defaults, in one place

The names below load on first use, so that a tool reading a task's configuration (`envs.task_config`)
does not import Brax's environments (about a second).
"""

from hopper_mjx.shell import lazy

_PUBLIC = {
    "MonopedConfig": "hopper_mjx.envs.task_config",
    "MonopedEnv": "hopper_mjx.envs.monoped",
    "default_config": "hopper_mjx.envs.tasks",
    "from_config": "hopper_mjx.envs.tasks",
    "make": "hopper_mjx.envs.tasks",
    "names": "hopper_mjx.envs.tasks",
}
__all__ = sorted(_PUBLIC)


__getattr__ = lazy.attributes(__name__, _PUBLIC, globals())
