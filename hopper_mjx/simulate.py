"""python -m hopper_mjx.simulate: run a batch of monopeds and keep their signals.

    python -m hopper_mjx.simulate --gravity 9.81,3.71,1.62 --num 4 --duration 2 \
        --controller hold --rate 100 --out run.npz

Instances are laid out gravity-major: instance i has gravity value i // num.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from hopper_mjx import cli, runtime


def sensor_config(args):
    from hopper_mjx import signals

    return signals.SensorConfig.uniform(args.rate, gyro_noise=args.gyro_noise, accel_noise=args.accel_noise)


def run(args, batch: cli.Batch | None = None) -> dict[str, np.ndarray]:
    """Simulates as the arguments say and returns the arrays saved to the .npz file."""
    sensors = sensor_config(args)
    batch = batch or cli.check_batch(args)
    _, final, traj = cli.run_batch(args, batch, sensors)
    out = {
        "time": traj.time["state"],
        "gravity": batch.gravity,
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


def parser() -> argparse.ArgumentParser:
    p = cli.parser("python -m hopper_mjx.simulate", __doc__)
    cli.add_batch_options(p)
    p.add_argument("--rate", type=float, default=100.0, help="Hz of the saved signals")
    p.add_argument("--out", default="simulation.npz", help="output .npz file")
    return p


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    try:
        cli.check_range("--rate", args.rate, low=0, open_low=True)
        cli.check_writable("--out", args.out)
        batch = cli.check_batch(args)
        cli.check_rates("--rate", sensor_config(args), batch)
        runtime.configure()
        arrays = run(args, batch)
    except ValueError as err:  # includes URDFError
        return cli.fail(err)
    np.savez_compressed(args.out, **arrays)
    cli.warn_diverged(arrays["diverged"])
    print(f"wrote {args.out}: {arrays['qpos'].shape[0]} instances x {arrays['time'].size} samples")
    return 0


if __name__ == "__main__":
    sys.exit(main())
