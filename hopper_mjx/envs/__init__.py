"""Reinforcement-learning environments over the monoped (Brax `Env` interface)."""

from hopper_mjx.envs.monoped import MonopedConfig, MonopedEnv, randomize_gravity

__all__ = ["MonopedConfig", "MonopedEnv", "randomize_gravity"]
