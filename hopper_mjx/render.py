"""python -m hopper_mjx.render: pictures of the monoped with MuJoCo's offscreen renderer.

    python -m hopper_mjx.render --still docs/img/monoped.png
    python -m hopper_mjx.render --video hop.mp4 --gravity 1.62 --controller hold --duration 2

The still shows the robot in its initial stance (on a --terrain, from further, with the ground
ahead); the video (MP4 or GIF, by the
file name) shows one instance simulated by the core. Headless machines render
through EGL (software Mesa on a CPU-only box): importing `hopper_mjx` chooses it
before MuJoCo is loaded, unless MUJOCO_GL is set (see `hopper_mjx.startup`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import mujoco
import numpy as np

from hopper_mjx import cli, command, files, runtime
from hopper_mjx.model import robot, scene
from hopper_mjx.scenario import Physics, Scenario

VIDEO_SUFFIXES = (".mp4", ".gif")
TRACK_HEIGHT = 0.45  # m: the camera looks at the leg's middle, not at the base


def scene_model(physics: Physics = Physics()) -> mujoco.MjModel:
    """The simulated monoped of `physics` (on its ground: the plane or a terrain's height field) plus what
    only pictures need: a checkered floor, a sky, link colours."""
    return scene.dress(physics.spec()).compile()


def camera(base_pos, distance: float = 2.0, azimuth: float = 135.0, elevation: float = -12.0) -> mujoco.MjvCamera:
    """A free camera following the base horizontally, looking at the leg's middle."""
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.lookat[:] = (base_pos[0], base_pos[1], TRACK_HEIGHT)
    cam.distance, cam.azimuth, cam.elevation = distance, azimuth, elevation
    return cam


def ground_camera() -> mujoco.MjvCamera:
    """A still camera for a terrain: from the side (+x to the right), above, over the ground ahead."""
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.lookat[:] = (0.8, 0.0, 0.1)
    cam.distance, cam.azimuth, cam.elevation = 3.2, 90.0, -24.0
    return cam


def _check_size(width: int, height: int) -> None:
    if not (16 <= width <= 1920 and 16 <= height <= 1080):
        raise ValueError(f"image size must be within 16x16..1920x1080 pixels, got {width}x{height}")


def frames(m: mujoco.MjModel, qpos_sequence, *, width: int = 640, height: int = 480, segmentation: bool = False,
           fixed: mujoco.MjvCamera | None = None):
    """Yields one (height, width, 3) uint8 image per qpos (nq,), the camera following the base (or `fixed`).

    With `segmentation`, each image is instead (height, width, 2) int32 of (object id, object type)
    per pixel, as MuJoCo's segmentation rendering gives it (-1 where nothing is drawn).
    """
    _check_size(width, height)
    d = mujoco.MjData(m)
    renderer = mujoco.Renderer(m, height, width)
    try:
        if segmentation:
            renderer.enable_segmentation_rendering()
        for qpos in qpos_sequence:
            d.qpos[:] = qpos
            mujoco.mj_kinematics(m, d)
            renderer.update_scene(d, camera=fixed or camera(d.qpos[:3]))
            yield renderer.render().copy()
    finally:
        renderer.close()  # free the GL context now, not in a destructor at interpreter exit


def still(m: mujoco.MjModel, qpos, **options) -> np.ndarray:
    """One picture of the robot at `qpos` (`frames`' options)."""
    return next(frames(m, [qpos], **options))


def robot_pixels(m: mujoco.MjModel, qpos, **size) -> np.ndarray:
    """(height, width) bool: the pixels that show a robot geom (any geom not on the world body)."""
    seg = still(m, qpos, segmentation=True, **size)
    geom = (seg[..., 1] == mujoco.mjtObj.mjOBJ_GEOM) & (seg[..., 0] >= 0)
    robot_geom = m.geom_bodyid != 0
    return geom & robot_geom[np.where(geom, seg[..., 0], 0)]


def video_sensors(args):
    from hopper_mjx import signals

    return signals.SensorConfig.uniform(args.fps)


def simulate_qpos(args, batch: Scenario | None = None) -> np.ndarray:
    """(T, nq) poses of instance --instance, simulated on the one batch-run path, at --fps.

    The core runs the simulation model (`model.load`); the pictures' model adds only visuals."""
    batch = batch or check_video(args)
    _, _, traj = batch.run(args.duration, video_sensors(args))
    return traj.qpos[args.instance]


def check_video(args) -> Scenario:
    """--video and the batch it shows, checked before anything is built."""
    if args.video.suffix.lower() not in VIDEO_SUFFIXES:
        raise ValueError(f"--video must end in {' or '.join(VIDEO_SUFFIXES)}, got {args.video}")
    cli.check_writable("--video", args.video)
    cli.check_range("--fps", args.fps, low=0, open_low=True)
    return check_batch(args)


def check_batch(args) -> Scenario:
    """The batch's options, checked even for a still alone (a bad --world is refused, not ignored)."""
    batch = cli.check_batch(args)
    cli.refuse_each(batch.physics.ground, "render (it draws the model's ground)")
    if args.video is None:
        return batch
    cli.check_indices("--instance", [args.instance], len(batch.gravity))
    cli.check_rates("--fps", video_sensors(args), batch, args.duration)
    return batch


def write_video(path: Path, images, fps: float) -> None:
    import imageio.v2 as imageio

    if path.suffix.lower() == ".gif":
        # GIF frame times are whole centiseconds; loop=0 repeats forever.
        writer = imageio.get_writer(path, mode="I", duration=1000.0 / fps, loop=0)
    else:
        writer = imageio.get_writer(path, fps=fps, codec="libx264", quality=7, macro_block_size=8)
    with writer:
        for image in images:
            writer.append_data(image)


def parse_size(text: str) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--size must be WIDTHxHEIGHT, e.g. 640x480, got {text!r}") from None
    return width, height


def parser() -> argparse.ArgumentParser:
    p = cli.parser("python -m hopper_mjx.render", __doc__)
    cli.add_batch_options(p, gravity=(9.81,))
    p.add_argument("--still", type=Path, default=None, help="PNG of the robot in its initial stance")
    p.add_argument("--video", type=Path, default=None, help="MP4 or GIF of one simulated instance")
    p.add_argument("--instance", type=int, default=0, help="which instance of the batch the video shows")
    p.add_argument("--fps", type=float, default=25.0,
                   help="video frames per simulated second; must divide the physics rate (1000 Hz)")
    p.add_argument("--size", type=parse_size, default=(640, 480), help="image WIDTHxHEIGHT in pixels")
    return p


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    if args.still is None and args.video is None:
        parser().error("nothing to do: give --still PATH and/or --video PATH")
    size = dict(zip(("width", "height"), args.size))
    try:
        _check_size(**size)
        if args.still is not None:
            cli.check_writable("--still", args.still, suffixes=(".png", ".jpg", ".jpeg"))
        batch = check_video(args) if args.video is not None else check_batch(args)
        physics = batch.physics
        runtime.configure()
        m = scene_model(physics)
        if args.still is not None:
            import imageio.v2 as imageio

            view = None if physics.ground.is_flat else ground_camera()  # on a terrain, the still shows the ground
            with files.partial(args.still):  # a stopped run leaves no half-written image
                imageio.imwrite(args.still, still(m, robot.stance_qpos(physics.mj_model), fixed=view, **size))
            print(f"wrote {args.still}")
        if args.video is not None:
            qpos = simulate_qpos(args, batch)
            with files.partial(args.video):
                write_video(args.video, frames(m, qpos, **size), args.fps)
            print(f"wrote {args.video}: {len(qpos)} frames at {args.fps:g} fps")
    except ValueError as err:
        return cli.fail(err)
    return 0


if __name__ == "__main__":
    sys.exit(command.run(main))
