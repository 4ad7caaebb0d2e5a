"""python -m hopper_mjx.simulate: run a batch of monopeds and keep their signals.

    python -m hopper_mjx.simulate --gravity 9.81,3.71,1.62 --num 4 --duration 2 \
        --controller hold --rate 100 --out run.npz

Instances are laid out gravity-major: instance i has gravity value i // num.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from hopper_mjx import runtime


def parse_floats(text: str, what: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{what} must be comma-separated numbers, got {text!r}") from None
    if not values:
        raise argparse.ArgumentTypeError(f"{what} is empty")
    return values


def build_controller(name: str, layout, args):
    """(controller, per-instance params or None) for a --controller value."""
    from hopper_mjx.control import base, pid, raibert

    if name == "none":
        return base.zero_torque(layout), None
    if name == "hold":
        return base.hold(layout), None
    if name == "pid":
        return pid.pid(layout), None  # seed gains (monoped.yaml), holding the initial joint angles
    if name == "raibert":
        from hopper_mjx import model
        from hopper_mjx.control.kinematics import LegGeometry

        leg = LegGeometry.of(model.load(args.urdf, timestep=args.timestep)) if args.urdf else None
        if len(args.speed) != 2:
            raise ValueError(f"--speed needs two values VX,VY in m/s, got {args.speed}")
        n = args.num * len(args.gravity)
        params = raibert.raibert_params(n, height=args.height, speed=args.speed)
        return raibert.raibert(layout, leg=leg), params
    if name.startswith("policy:"):
        from hopper_mjx import model
        from hopper_mjx.control import policy

        mj_model = model.load(args.urdf, timestep=args.timestep)
        params = policy.policy_params(mj_model, args.num * len(args.gravity), height=args.height, speed=args.speed)
        return policy.policy_controller(mj_model, name.removeprefix("policy:")), params
    raise ValueError(f"unknown controller {name!r}; choose from: none, hold, pid, raibert, policy:PATH")


def run(args) -> dict[str, np.ndarray]:
    """Simulates as the arguments say and returns the arrays saved to the .npz file."""
    import jax

    from hopper_mjx import model, signals
    from hopper_mjx.sim import Sim, gravity_vectors

    if args.num < 1:
        raise ValueError(f"--num must be >= 1, got {args.num}")
    gravity = gravity_vectors(np.repeat(args.gravity, args.num))
    mj_model = model.load(args.urdf, timestep=args.timestep)
    sim = Sim(mj_model, chunk=args.chunk)
    controller, params = build_controller(args.controller, sim.layout, args)
    sensors = signals.SensorConfig.uniform(args.rate, gyro_noise=args.gyro_noise, accel_noise=args.accel_noise)
    period = sensors.periods(sim.layout.timestep)["state"]
    steps = max(period, int(round(args.duration / sim.layout.timestep / period)) * period)
    state = sim.reset(gravity, key=args.seed, controller=controller, params=params)
    start = time.perf_counter()
    final, traj = sim.rollout(state, controller, steps=steps, sensors=sensors)
    jax.block_until_ready(traj)
    wall = time.perf_counter() - start
    n = len(gravity)
    print(f"{n} instances x {steps} steps on {len(sim.devices)} device(s): {wall:.1f} s "
          f"incl. compile, {n * steps / wall:,.0f} steps/s", file=sys.stderr)
    out = {
        "time": np.asarray(traj.time["state"]),
        "gravity": gravity,
        "qpos": traj.qpos,
        "qvel": traj.qvel,
        "imu_quat": traj.imu.quat,
        "imu_gyro": traj.imu.gyro,
        "imu_accel": traj.imu.accel,
        "odom_pos": traj.odom.pos,
        "odom_quat": traj.odom.quat,
        "odom_linvel": traj.odom.linvel,
        "odom_angvel": traj.odom.angvel,
        "contact": traj.contact.flag,
        "contact_force": traj.contact.force,
        "contact_pos": traj.contact.pos,
        "diverged": final.diverged,
    }
    return {k: np.asarray(v) for k, v in out.items()}


def warn_diverged(diverged) -> None:
    bad = np.flatnonzero(diverged)
    if bad.size:
        print(f"warning: {bad.size} instance(s) diverged and were frozen: {bad[:20].tolist()}", file=sys.stderr)


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m hopper_mjx.simulate", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--gravity", type=lambda s: parse_floats(s, "--gravity"), default=[9.81, 3.71, 1.62],
                   help="gravity magnitudes in m/s², pointing down (default: Earth, Mars, Moon)")
    p.add_argument("--num", type=int, default=1, help="instances per gravity value")
    p.add_argument("--duration", type=float, default=2.0, help="simulated time, s")
    p.add_argument("--controller", default="hold",
                   help="none (limp), hold (keep initial joint angles), pid (the seed's joint position "
                        "controllers, holding them), raibert (hop) or policy:PATH (a trained PPO policy)")
    p.add_argument("--height", type=float, default=0.10,
                   help="raibert: commanded apex rise of the base above its standing height, m")
    p.add_argument("--speed", type=lambda s: parse_floats(s, "--speed"), default=[0.0, 0.0],
                   help="raibert: commanded horizontal speed VX,VY in m/s")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--rate", type=float, default=100.0, help="Hz of the saved signals")
    p.add_argument("--gyro-noise", type=float, default=0.0, help="IMU angular-rate noise std, rad/s")
    p.add_argument("--accel-noise", type=float, default=0.0, help="IMU specific-force noise std, m/s²")
    p.add_argument("--urdf", default=None, help="monoped URDF (default: the shipped one)")
    p.add_argument("--timestep", type=float, default=1e-3, help="physics step, s")
    p.add_argument("--chunk", type=int, default=256, help="instances per vmapped chunk on a device")
    p.add_argument("--out", default="simulation.npz", help="output .npz file")
    return p


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    runtime.configure()
    try:
        arrays = run(args)
    except ValueError as err:  # includes URDFError
        print(f"error: {err}", file=sys.stderr)
        return 2
    np.savez_compressed(args.out, **arrays)
    warn_diverged(arrays["diverged"])
    print(f"wrote {args.out}: {arrays['qpos'].shape[0]} instances x {arrays['time'].size} samples")
    return 0


if __name__ == "__main__":
    sys.exit(main())
