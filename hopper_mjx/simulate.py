"""python -m hopper_mjx.simulate: run a batch of monopeds and keep their signals.

    python -m hopper_mjx.simulate --gravity 9.81,3.71,1.62 --num 4 --duration 2 \
        --controller hold --rate 100 --out run.npz
    python -m hopper_mjx.simulate --controller raibert --duration 20 --rate 50 --foxglove   # live, ws://127.0.0.1:8765

Instances are laid out gravity-major: instance i has gravity value i // num. With --foxglove the
batch is played live (`hopper_mjx.live`, paced at --speed-factor x real time) and up to 16 of
its instances stream the ROS topics of `ros.record` at --rate; the .npz holds the same arrays.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys

import numpy as np

from hopper_mjx import cli
from hopper_mjx.metrics import hops
from hopper_mjx.scenario import Scenario
from hopper_mjx.shell import jaxsetup, process
from hopper_mjx.shell.files import atomic_write


def sensor_config(args):
    from hopper_mjx.hardware import signals

    counts, spacing = cli.parse_scan(args.scan)
    return dataclasses.replace(signals.SensorConfig.uniform(args.rate, torque=True, gyro_noise=args.gyro_noise,
                                                            accel_noise=args.accel_noise),
                               scan_counts=counts, scan_spacing=spacing)


def arrays(traj, gravity, diverged, drive=(), push=None, drawn: dict | None = None,
           controls: dict | None = None, sensors=None) -> dict[str, np.ndarray]:
    """The arrays saved to the .npz file, from a trajectory of the batch (and the final motors' `drive`,
    `hopper_mjx.hardware.actuators.Drive`: each instance's motor figures and the energy drawn; the pushes'
    (interval s, speed m/s); `drawn`: each instance's robot ({model field: (N, ...)}, `Scenario.draws`),
    saved as `model_<field>`; `controls`: its controller's, motors' and sensors' drawn parameters
    (`Scenario.controls`), saved under their names: `kp_scale`, `action_delay` (ms), ...); on a terrain,
    the height scan and the contact normal (at the contact stream's rate) and the scan's points (`sensors`' scan)."""
    out = {
        "time": traj.time["state"],
        "gravity": gravity,
        "qpos": traj.qpos,
        "qvel": traj.qvel,
        "torque": traj.torque,
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
        "diverged": diverged,
        **{f"model_{field}": values for field, values in (drawn or {}).items()},
        **(controls or {}),  # a dc motor's drawn figures are the drive's, below: one key each
    }
    if drive:
        motor = drive.motor
        out |= {"motor_stall_torque": motor.stall_torque, "motor_no_load_speed": motor.no_load_speed,
                "motor_torque_limit": motor.torque_limit, "action_delay_steps": motor.delay,
                "motor_energy": drive.energy}
    if push is not None:
        out |= {"push_interval": push[0], "push_speed": push[1]}
    if traj.ground:
        out |= {"scan": traj.ground.scan, "contact_normal": traj.ground.normal, "scan_time": traj.time["contact"],
                "scan_points": sensors.scan_points()}
    return {k: np.asarray(v) for k, v in out.items()}


def run(args, batch: Scenario | None = None) -> dict[str, np.ndarray]:
    """Simulates as the arguments say (`batch`: already checked) and returns the arrays saved to the .npz file."""
    batch = batch or cli.check_batch(args)
    sensors = sensor_config(args)
    sim, final, traj = batch.run(args.duration, sensors)
    return arrays(traj, batch.gravity, final.diverged, final.drive, batch.physics.push, batch.draws(sim.mj_model),
                  batch.controls(sim.mj_model), sensors)


def apex_note(batch: Scenario) -> str | None:
    """A line saying at which gravities the gait's commanded rise (--height) is more than the motors can give
    (`hardware.bound`: the model's robot, the knee's best push), so its robots hop lower or fall; None where
    every gravity's bound holds it, or the controller hops to no height."""
    from hopper_mjx import registry

    gravities = batch.magnitudes()
    if batch.controller not in registry.GAIT_CONTROLLERS or not gravities:
        return None
    from hopper_mjx.hardware import bound

    past = bound.apex_bounds(batch.physics.mj_model, batch.physics.motor, gravities, batch.height)
    over = ", ".join(f"{rise:.2f} m at g = {g:g} m/s²" for g, rise in past.items() if batch.height > rise)
    if not over:
        return None
    return (f"note: --height {batch.height:g} m is a higher rise than the {batch.physics.motor} motors can give: at "
            f"most {over} (their energy bound, docs/sweeps.md); its robots will hop lower, or fall")


def run_live(args, batch: Scenario, stream) -> dict[str, np.ndarray]:
    """The same batch played live at --speed-factor x real time and streamed to Foxglove as it
    plays; returns the arrays `run` saves, joined from the played chunks."""
    import time

    from hopper_mjx import live
    from hopper_mjx.sim import steps_for

    playing = live.LiveBatch.build(batch, sensor_config(args))
    stream.attach(playing)
    print(f"streaming instances {stream.instances} to Foxglove on ws://127.0.0.1:{stream.port}", flush=True)
    end = steps_for(args.duration, playing.sim.layout.timestep, playing.sensors) * playing.sim.layout.timestep
    played: list = []  # the chunks, in order

    def keep(chunk, t_from, t_to):
        if not played or played[-1] is not chunk:
            played.append(chunk)

    with live.LiveRun(playing, factor=args.speed_factor, sinks=[keep, stream]) as run_:
        while run_.played_until < end - 1e-9:
            run_.poll()
            time.sleep(run_.seconds_to_next())
    return arrays(live.joined(played, end), playing.gravity, played[-1].diverged, playing.state.drive,
                  batch.physics.push, batch.draws(playing.sim.mj_model), sensors=playing.sensors)


def parser() -> argparse.ArgumentParser:
    p = cli.parser("python -m hopper_mjx.simulate", __doc__)
    from hopper_mjx.live import SHOWN

    cli.add_batch_options(p)
    p.add_argument("--rate", type=float, default=100.0, help="Hz of the saved signals")
    p.add_argument("--out", default="simulation.npz", help="output .npz file")
    p.add_argument("--scan", default="5x5,0.1", help="on a --terrain, the height scan saved: NXxNY points (ahead, "
                   "left) at SPACING m (or DXxDY), centred under the base in its yaw frame (default 5x5,0.1)")
    cli.add_live_options(p, foxglove_help=f"run live and stream up to {SHOWN} instances' ROS topics "
                                          "(spread over the batch) at --rate")
    return p


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    from hopper_mjx import live
    from hopper_mjx.ros import foxglove

    try:
        cli.check_range("--rate", args.rate, low=0, open_low=True)
        cli.check_writable("--out", args.out, suffixes=(".npz", ""))  # a bare name: NumPy's file as named
        batch = cli.check_batch(args)
        cli.say(cli.check_rates("--rate", sensor_config(args), batch, args.duration), apex_note(batch),
                cli.speed_note(batch, args.duration))
        with foxglove.listening(args, live.spread(len(batch.gravity), live.SHOWN)) as stream:
            jaxsetup.configure()
            saved = run(args, batch) if stream is None else run_live(args, batch, stream)
    except ValueError as err:  # includes URDFError and a busy --foxglove port
        return cli.fail(err)
    # A file object, so numpy writes the exact name given (no ".npz" added); whole or not at all.
    atomic_write(args.out, lambda f: np.savez_compressed(f, **saved))
    cli.warn_diverged(saved["diverged"])
    down = hops.fallen(saved["qpos"]).any(axis=1)  # the sweeps' fall test, at the saved rate
    fell = (f"{down.sum()} fell (base below {hops.FALL_HEIGHT:g} m or tilted past {hops.FALL_ROLL_PITCH:g} "
            f"rad): {np.flatnonzero(down)[:10].tolist()}")
    print(f"wrote {args.out}: {cli.counted(saved['qpos'].shape[0], 'instance')} x {saved['time'].size} samples; "
          f"{fell if down.any() else 'all up to the end'}")
    return 0


if __name__ == "__main__":
    sys.exit(process.run(main))
