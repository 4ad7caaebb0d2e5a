"""IMU, odometry and foot-contact signals of one monoped, and what a controller observes.

The functions here take one instance's engine data *after* the engine's `forward`
and before integration, so that positions, velocities, accelerations and contact
forces all belong to the same instant. The batched core vmaps them over all
instances. They compute from the state directly rather than through MuJoCo's
sensor stage, which MJX would otherwise evaluate every physics step; the native
sensors the loader adds give the same numbers and a test holds them equal.

Frames: world z is up; quaternions are [w, x, y, z] (MuJoCo's order).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from hopper_mjx.hardware import rotation
from hopper_mjx.terrain import scan as terrain_scan


class Imu(NamedTuple):
    """Like gazebo_ros_imu on the base: orientation in the world, rates in the body."""

    quat: jax.Array  # (4,) [w, x, y, z], body -> world
    gyro: jax.Array  # (3,) rad/s, body frame
    accel: jax.Array  # (3,) m/s², specific force (acceleration minus gravity), body frame


class Odometry(NamedTuple):
    """Like gazebo_ros_p3d on the base: everything in the world frame."""

    pos: jax.Array  # (3,) m
    quat: jax.Array  # (4,) [w, x, y, z]
    linvel: jax.Array  # (3,) m/s
    angvel: jax.Array  # (3,) rad/s


class Contact(NamedTuple):
    """The foot/lower-leg contact sensor."""

    flag: jax.Array  # () bool, foot penetrating the floor
    force: jax.Array  # (3,) N, floor on foot, world frame
    pos: jax.Array  # (3,) m, contact point, world frame (zeros when not in contact)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class SensedGround:
    """The terrain as one instance senses it (on a height field; the flat plane has none)."""

    heights: jax.Array  # (nrow, ncol) m, world z: the instance's grid, as its engine collides with it
    scan: jax.Array  # (K,) m, world z of the ground under the scan points (`SensorConfig.scan_points`)
    normal: jax.Array  # (3,) the ground's unit normal under the foot's contact point, world (zeros off contact)
    size: tuple[float, float] = dataclasses.field(metadata={"static": True})  # the grid's (hx, hy), m

    def height(self, x, y):
        """Ground height (m) at world (x, y), on the triangles the engine collides with."""
        return terrain_scan.height_at(self.heights, self.size, x, y)


class GroundTrace(NamedTuple):
    """The recorded terrain signals (on a height field)."""

    scan: jax.Array  # (K,) m, world z under the scan points
    normal: jax.Array  # (3,) the ground's normal under the foot's contact (zeros off contact)


class Signals(NamedTuple):
    imu: Imu
    odom: Odometry
    contact: Contact
    qpos: jax.Array
    qvel: jax.Array
    ground: GroundTrace | tuple = ()  # on a height field; () on the plane
    ctrl: jax.Array | tuple = ()  # (nu,) the controls the step applied (after the delay line and the motors)


class Observation(NamedTuple):
    """What a controller reads of one instance before it acts, whatever the engine.

    The contact is that of the previous physics step, as a real controller reads its
    sensors before it acts.
    """

    time: jax.Array  # () s
    qpos: jax.Array  # (nq,)
    qvel: jax.Array  # (nv,)
    contact: Contact
    ground: SensedGround | None = None  # on a height field; None on the flat plane (a controller's static branch)


def imu(d: Any, gravity: jax.Array) -> Imu:
    """The IMU at the origin of the free base, whose qpos/qvel come first."""
    rot = rotation.matrix(d.qpos[3:7])
    # qacc[:3] is the world acceleration of the base origin over this step.
    return Imu(quat=d.qpos[3:7], gyro=d.qvel[3:6], accel=rot.T @ (d.qacc[:3] - gravity))


def odometry(d: Any) -> Odometry:
    quat = d.qpos[3:7]
    return Odometry(pos=d.qpos[:3], quat=quat, linvel=d.qvel[:3], angvel=rotation.rotate(d.qvel[3:6], quat))


def contact(engine, model, d) -> Contact:
    """The foot contact of the engine's last forward (the one foot-contact test, `engine.foot_contact`)."""
    return Contact(*engine.foot_contact(model, d))


def ground(heights, size, points, d, touch: Contact) -> SensedGround:
    """The height scan around the base (its yaw frame) and the ground's normal under the foot's contact,
    read from the grid `heights` the engine steps on (half-extents `size`, scan `points` (K, 2))."""
    scan = terrain_scan.measured_heights(heights, size, d.qpos[:3], d.qpos[3:7], points)
    normal = terrain_scan.normal_at(heights, size, touch.pos[0], touch.pos[1])
    return SensedGround(heights, scan, jnp.where(touch.flag, normal, 0.0), size)


def measure(engine, model, d, gravity: jax.Array, terrain: tuple = (), ctrl: bool = False) -> Signals:
    """The signals; `terrain` (heights, size, points) adds the scan and the contact normal, `ctrl` the controls the
    step applied (static: without it the program is the one that records none)."""
    touch = contact(engine, model, d)
    sensed = ground(*terrain, d, touch) if terrain else None
    return Signals(
        imu=imu(d, gravity),
        odom=odometry(d),
        contact=touch,
        qpos=d.qpos,
        qvel=d.qvel,
        ground=GroundTrace(sensed.scan, sensed.normal) if sensed else (),
        ctrl=d.ctrl if ctrl else (),
    )


def observe(engine, model, d, terrain: tuple = ()) -> Observation:
    """What a controller reads; `terrain` (heights, size, points) adds the `SensedGround`."""
    touch = contact(engine, model, d)
    return Observation(time=d.time, qpos=d.qpos, qvel=d.qvel, contact=touch,
                       ground=ground(*terrain, d, touch) if terrain else None)


@dataclasses.dataclass(frozen=True)
class SensorConfig:
    """Rates (Hz) and Gaussian noise standard deviations (SI units) of the streams.

    Every rate must divide the physics rate. Defaults follow the seed: its
    gazebo_ros_imu plugin ran at 50 Hz with zero noise.
    """

    imu_rate: float = 50.0
    gyro_noise: float = 0.0  # rad/s
    accel_noise: float = 0.0  # m/s²
    orientation_noise: float = 0.0  # rad, as a small random rotation
    odom_rate: float = 50.0
    odom_pos_noise: float = 0.0  # m
    odom_vel_noise: float = 0.0  # m/s and rad/s
    contact_rate: float = 50.0
    state_rate: float = 50.0  # qpos/qvel
    # Each joint's applied torque at the state samples (`Trajectory.torque`), for what reads it (simulate's .npz,
    # the bags, the band sweeps). Off, the step's program is the one without it: the extra output cost the bench's
    # core ~10 % and moves XLA's fusion, and so a long hopping run's last digits.
    torque: bool = False
    # The height scan on a terrain (legged_gym's measured_heights): a grid of counts (ahead, left) at
    # spacing (m) centred under the base in its yaw frame; recorded at the contact rate with the normal.
    scan_counts: tuple[int, int] = (5, 5)
    scan_spacing: tuple[float, float] = (0.1, 0.1)

    def key(self) -> tuple:
        """The configuration as a stored program's key (`shell.programs`): equal configurations, one key. Its repr
        would not do: a rate of 100 and one of 100.0 are one rate, and trace to one program."""
        number = lambda v: float(v) if type(v) is int else v  # not a bool: `torque` stays a flag
        return tuple((f.name, number(getattr(self, f.name))) for f in dataclasses.fields(self))

    def scan_points(self):
        """(K, 2) m, the scan's points in the base's yaw frame (x ahead, y left)."""
        return terrain_scan.scan_points(self.scan_counts, self.scan_spacing)

    @classmethod
    def uniform(cls, rate: float, **noise) -> "SensorConfig":
        return cls(imu_rate=rate, odom_rate=rate, contact_rate=rate, state_rate=rate, **noise)

    def whole(self, timestep: float) -> int:
        """Physics steps that hold a whole number of every stream's period."""
        return math.lcm(*self.periods(timestep).values())

    def periods(self, timestep: float) -> dict[str, int]:
        """Each stream's period in physics steps."""
        out = {}
        for name in ("imu", "odom", "contact", "state"):
            rate = getattr(self, f"{name}_rate")
            steps = 1.0 / (rate * timestep) if rate > 0 else 0.0
            if not (rate > 0 and steps >= 1 and abs(steps - round(steps)) < 1e-6):
                raise ValueError(
                    f"{name}_rate={rate} Hz must divide the physics rate {1 / timestep:g} Hz"
                )
            out[name] = int(round(steps))
        terrain_scan.check_grid(self.scan_counts, self.scan_spacing)
        for field in dataclasses.fields(self):
            if field.name.endswith("noise") and not getattr(self, field.name) >= 0:
                raise ValueError(f"{field.name} must be a non-negative standard deviation")
        return out


def _gauss(key, x, std):
    return x if std == 0 else x + std * jax.random.normal(key, x.shape, x.dtype)


def _perturb_quat(key, quat, std):
    if std == 0:
        return quat
    angle = std * jax.random.normal(key, quat.shape[:-1] + (3,), quat.dtype)
    small = jnp.concatenate([jnp.ones_like(angle[..., :1]), 0.5 * angle], axis=-1)
    noisy = jax.vmap(rotation.multiply)(quat.reshape(-1, 4), small.reshape(-1, 4)).reshape(quat.shape)
    return noisy / jnp.linalg.norm(noisy, axis=-1, keepdims=True)


def noise_keys(key: jax.Array) -> jax.Array:
    """(6, 2) the keys `add_noise` draws from: orientation, gyro, accel, odometry position,
    linear and angular velocity."""
    return jax.random.split(key, 6)


def add_noise(cfg: SensorConfig, key: jax.Array, imu_: Imu, odom: Odometry, own=None) -> tuple[Imu, Odometry]:
    """Measurement noise for one instance's recorded streams, in one pass: the streams' stds (`cfg`) and, with
    `own` (its `sensor_noise.SensorState`), the instance's own sensors' std and gyro bias. The two are independent
    Gaussians, so each reading draws once, with their combined std; exact when every std is 0."""
    k = noise_keys(key)
    if own is None:  # static: the streams' stds alone, each skipped where 0
        gauss = lambda k, x, std, _: _gauss(k, x, std)
        pick = lambda name: 0.0
    else:
        gauss = lambda k, x, std, own_std: x + jnp.sqrt(std**2 + own_std**2) * jax.random.normal(k, x.shape, x.dtype)
        pick = lambda name: getattr(own, name)
    imu_ = Imu(
        quat=_perturb_quat(k[0], imu_.quat, cfg.orientation_noise),
        gyro=gauss(k[1], imu_.gyro, cfg.gyro_noise, pick("gyro_noise")),
        accel=gauss(k[2], imu_.accel, cfg.accel_noise, pick("accel_noise")),
    )
    odom = odom._replace(
        pos=gauss(k[3], odom.pos, cfg.odom_pos_noise, pick("odom_pos_noise")),
        linvel=gauss(k[4], odom.linvel, cfg.odom_vel_noise, pick("odom_vel_noise")),
        angvel=gauss(k[5], odom.angvel, cfg.odom_vel_noise, pick("odom_vel_noise")),
    )
    if own is not None:  # the instance's gyro is biased
        imu_ = imu_._replace(gyro=imu_.gyro + own.gyro_bias)
    return imu_, odom
