"""Motor models: what becomes of a controller's torque at the joint, applied by the core between the
controller and the engine, the same for every engine and controller.

- `ideal` (the default): the controller's torque, up to the URDF's effort limit (as it clips it);
- `dc`: a DC motor's torque-speed line. It gives its stall torque at rest and nothing beyond its no-load
  speed: the torque in the direction of motion falls linearly with the joint speed, and braking is bounded by
  the stall torque (Isaac Lab's `DCMotor` clip):

      high(w) = clip(stall * (1 - w / w0), 0, stall),  low(w) = clip(stall * (-1 - w / w0), -stall, 0)

  Stall torque and no-load speed default to the URDF's `<limit effort>` and `<limit velocity>` per joint, and
  are per-instance values of the batch state, (N, 3) each in joint order (haa, hfe, kfe).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from hopper_mjx.model.layout import Layout

STALL, NO_LOAD = "motor_stall_torque", "motor_no_load_speed"  # keys of the state's motor dict and the .npz


def dc_params(transmissions, layout: Layout, n: int) -> dict[str, np.ndarray]:
    """{stall torque N·m (n, 3), no-load speed rad/s (n, 3)} of `dc` motors at the URDF's limits, joint order;
    `transmissions`: the URDF's (`model.loader.describe(...).transmissions`)."""
    by_joint = {t.joint: t for t in transmissions}
    from hopper_mjx.model.loader import JOINTS

    stall = [by_joint[j].effort for j in JOINTS]
    speed = [by_joint[j].velocity for j in JOINTS]
    if not np.allclose(stall, layout.effort_limit):
        raise ValueError("the URDF's effort limits do not match the compiled model's")
    return {STALL: np.tile(np.asarray(stall, float), (n, 1)), NO_LOAD: np.tile(np.asarray(speed, float), (n, 1))}


def dc_of_urdf(urdf, layout: Layout, n: int) -> dict[str, np.ndarray]:
    """`dc_params` of a URDF file (None: the shipped monoped)."""
    from hopper_mjx.model import loader

    path = urdf or loader.DEFAULT_URDF
    leg = loader.describe(loader.read_text(path, "URDF file", loader.URDFError), str(path))
    return dc_params(leg.transmissions, layout, n)


def envelope(stall, no_load, speed):
    """(lowest, highest) joint torque N·m a DC motor gives at joint speed `speed` rad/s."""
    ratio = speed / no_load
    high = jnp.clip(stall * (1 - ratio), 0.0, stall)
    low = jnp.clip(stall * (-1 - ratio), -stall, 0.0)
    return low, high


def limit(layout: Layout, motor: dict, ctrl, qvel):
    """The actuator controls a `dc` motor lets through: the commanded joint torque (ctrl x the URDF's gear,
    as the controllers convert it) clipped to the envelope at each joint's speed."""
    act, dof, gear = (jnp.asarray(x) for x in (layout.actuator_of_joint, layout.joint_dof, layout.gear))
    low, high = envelope(motor[STALL], motor[NO_LOAD], qvel[dof])
    torque = jnp.clip(ctrl[act] * gear, low, high)
    return ctrl.at[act].set(torque / gear)
