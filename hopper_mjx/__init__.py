"""hopper_mjx: batched MJX simulation of the seed monoped under per-instance gravity.

The few names a user needs; everything else lives in its module (see the README's module map).
Importing the package changes no JAX setting: the command-line entry points call
`hopper_mjx.runtime.configure()` themselves. It does choose MuJoCo's OpenGL backend
(EGL on Linux, unless MUJOCO_GL is set) and keeps MJX's import notices off stdout:
both must happen before MuJoCo is first imported (see `hopper_mjx.startup`).
"""

from hopper_mjx import startup

startup.prepare()

# The imports below must follow startup.prepare().

from hopper_mjx.model import URDFError, load
from hopper_mjx.signals import SensorConfig
from hopper_mjx.sim import Sim, State, Trajectory, gravity_vectors

__all__ = ["SensorConfig", "Sim", "State", "Trajectory", "URDFError", "gravity_vectors", "load"]
