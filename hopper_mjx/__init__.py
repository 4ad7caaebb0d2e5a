"""hopper_mjx: batched MJX simulation of the seed monoped under per-instance gravity.

The few names a user needs; everything else lives in its module (see the README's module map).
They are loaded on first use, so that `python -m hopper_mjx.<command>` checks its arguments
before JAX and MuJoCo are imported (about 2 s).
Importing the package changes no JAX setting: the command-line entry points call
`hopper_mjx.shell.jaxsetup.configure()` themselves. It does choose MuJoCo's OpenGL backend
(EGL on Linux, unless MUJOCO_GL is set) and keeps MJX's import notices off stdout:
both must be settled before MuJoCo is first imported (see `hopper_mjx.shell.startup`).
"""

from hopper_mjx.shell import lazy, startup

startup.prepare()

_PUBLIC = {
    "Physics": "hopper_mjx.scenario",
    "Scenario": "hopper_mjx.scenario",
    "SensorConfig": "hopper_mjx.hardware.signals",
    "Sim": "hopper_mjx.sim",
    "State": "hopper_mjx.sim",
    "Trajectory": "hopper_mjx.sim",
    "URDFError": "hopper_mjx.model",
    "configure": "hopper_mjx.shell.jaxsetup",
    "gravity_vectors": "hopper_mjx.model.world",
    "load": "hopper_mjx.model",
}
__all__ = sorted(_PUBLIC)


__getattr__ = lazy.attributes(__name__, _PUBLIC, globals())
