"""python -m hopper_mjx.render: pictures of the monoped with MuJoCo's offscreen renderer.

    python -m hopper_mjx.render --still docs/img/monoped.png
    python -m hopper_mjx.render --video hop.mp4 --gravity 1.62 --controller hold --duration 2

The still shows the robot in its initial stance (on a --terrain, from the side, framing the robot and the
ground it faces: the first block, step or trench, else a metre of it); the video (MP4 or GIF, by the
file name) shows one instance simulated by the core, its time and gravity written in the corner (on a terrain,
from the side, with the ground ahead in view). Headless machines render
through EGL (software Mesa on a CPU-only box): importing `hopper_mjx` chooses it
before MuJoCo is loaded, unless MUJOCO_GL is set (see `hopper_mjx.shell.startup`).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import mujoco
import numpy as np

from hopper_mjx import cli
from hopper_mjx.model import robot, scene
from hopper_mjx.scenario import Physics, Scenario
from hopper_mjx.shell import files, jaxsetup, process, startup

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


def ahead(ground) -> float:
    """m along +x a picture of `ground` (a `terrain.Ground`) must show past the start: the far end of its first
    band (a block, a step, a trench), else a metre of ground."""
    bands = ground.obstacles()
    return float(min(bands[0, 1], ground.size[0] / 2)) if len(bands) else 1.0


def ground_camera(ground) -> mujoco.MjvCamera:
    """A still camera for a terrain: from the side (+x to the right), a little above, framing the robot at the
    start and the ground it faces (`ahead`) between them, neither at the picture's edge."""
    reach = ahead(ground)
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.lookat[:] = (reach / 2, 0.0, 0.35)  # the robot's base stands 0.7 m high: all of it in the picture
    # 45° of height at 4:3: about 1.1 x the distance wide; the span and 0.5 m either side fill two thirds.
    cam.distance, cam.azimuth, cam.elevation = max(2.7, (reach + 1.0) / 0.7), 90.0, -18.0
    return cam


def side_camera(base_pos, lead: float = 0.4) -> mujoco.MjvCamera:
    """A video's camera on a terrain: from the side, following the base with `lead` m of the ground ahead in
    view, so that what the robot faces enters the picture well before it reaches it."""
    cam = camera((base_pos[0] + lead, base_pos[1], base_pos[2]), distance=2.6, azimuth=90.0, elevation=-15.0)
    return cam


def _check_size(width: int, height: int) -> None:
    if not (16 <= width <= 1920 and 16 <= height <= 1080):
        raise ValueError(f"image size must be within 16x16..1920x1080 pixels, got {width}x{height}")


def frames(m: mujoco.MjModel, qpos_sequence, *, width: int = 640, height: int = 480, segmentation: bool = False,
           fixed: mujoco.MjvCamera | None = None, follow=camera, captions=None):
    """Yields one (height, width, 3) uint8 image per qpos (nq,), the camera following the base (`follow`, given
    the base position) or `fixed`; `captions`: a line of text per image, written in its top-left corner.

    With `segmentation`, each image is instead (height, width, 2) int32 of (object id, object type)
    per pixel, as MuJoCo's segmentation rendering gives it (-1 where nothing is drawn).
    """
    _check_size(width, height)
    d = mujoco.MjData(m)
    renderer = mujoco.Renderer(m, height, width)
    try:
        if segmentation:
            renderer.enable_segmentation_rendering()
        for k, qpos in enumerate(qpos_sequence):
            d.qpos[:] = qpos
            mujoco.mj_kinematics(m, d)
            renderer.update_scene(d, camera=fixed or follow(d.qpos[:3]))
            image = renderer.render().copy()
            yield image if captions is None else caption(image, captions[k])
    finally:
        renderer.close()  # free the GL context now, not in a destructor at interpreter exit


def caption(image: np.ndarray, text: str) -> np.ndarray:
    """`image` with `text` in its top-left corner, dark on a pale band (legible over sky and floor alike)."""
    from PIL import Image, ImageDraw, ImageFont

    picture = Image.fromarray(image)
    draw = ImageDraw.Draw(picture)
    from matplotlib import get_data_path  # its DejaVu Sans has the ² that Pillow's own font lacks

    font = ImageFont.truetype(str(Path(get_data_path()) / "fonts/ttf/DejaVuSans.ttf"), max(10, image.shape[0] // 24))
    left, top, right, bottom = draw.textbbox((6, 4), text, font=font)
    draw.rectangle((left - 4, top - 3, right + 4, bottom + 3), fill=(255, 255, 255))
    draw.text((6, 4), text, fill=(20, 20, 20), font=font)
    return np.asarray(picture)


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
    from hopper_mjx.hardware import signals

    return signals.SensorConfig.uniform(args.fps)


def simulate_qpos(args, batch: Scenario | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(T, nq) poses of instance --instance, simulated on the one batch-run path, at --fps, and (T,) their
    times, s.

    The core runs the simulation model (`model.load`); the pictures' model adds only visuals."""
    batch = batch or check_video(args)
    _, _, traj = batch.run(args.duration, video_sensors(args))
    return traj.qpos[args.instance], np.asarray(traj.time["state"], dtype=float)


def check_video(args) -> Scenario:
    """--video and the batch it shows, checked before anything is built."""
    if args.video.suffix.lower() not in VIDEO_SUFFIXES:
        raise ValueError(f"--video must end in {' or '.join(VIDEO_SUFFIXES)}, got {args.video}")
    cli.check_writable("--video", args.video)
    cli.check_range("--fps", args.fps, low=0, open_low=True)
    return check_batch(args)


def check_gl() -> None:
    """The OpenGL settings `render` draws with, before anything is built: MUJOCO_GL=glfw needs a display, and EGL or
    OSMesa a PYOPENGL_PLATFORM that agrees (MuJoCo ended in a FatalError's traceback, or without its Renderer) and
    its library installed."""
    backend = os.environ.get("MUJOCO_GL", "").lower().strip()
    if backend == "glfw" and sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                                       or os.environ.get("WAYLAND_DISPLAY")):
        raise ValueError("MUJOCO_GL=glfw needs a display, and DISPLAY is unset: unset MUJOCO_GL to render headless "
                         "with EGL")
    platform_ = os.environ.get("PYOPENGL_PLATFORM", "")
    if backend in ("egl", "osmesa") and platform_ and platform_.lower() != backend:
        raise ValueError(f"PYOPENGL_PLATFORM={platform_} disagrees with MUJOCO_GL={backend}: unset "
                         f"PYOPENGL_PLATFORM, or set it to {backend}")
    missing = startup.missing_gl_library(backend)  # EGL's absence leaves mujoco without its Renderer
    if missing:
        raise ValueError(missing)


def check_batch(args) -> Scenario:
    """The batch's options, checked even for a still alone (a bad --world is refused, not ignored)."""
    batch = cli.check_batch(args)
    cli.refuse_each(batch.physics.ground, "render (it draws the model's ground)")
    cli.check_indices("--instance", [args.instance], len(batch.gravity))
    if args.video is None:
        return batch
    cli.say(cli.check_rates("--fps", video_sensors(args), batch, args.duration), cli.speed_note(batch, args.duration))
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
        check_gl()
        _check_size(**size)
        if args.still is not None:
            cli.check_writable("--still", args.still, suffixes=(".png", ".jpg", ".jpeg"))
        batch = check_video(args) if args.video is not None else check_batch(args)
        physics = batch.physics
        jaxsetup.configure()
        m = scene_model(physics)
        if args.still is not None:
            import imageio.v2 as imageio

            view = None if physics.ground.is_flat else ground_camera(physics.ground)  # the ground it faces too
            with files.partial(args.still):  # a stopped run leaves no half-written image
                imageio.imwrite(args.still, still(m, robot.stance_qpos(physics.mj_model), fixed=view, **size))
            print(f"wrote {args.still}")
        if args.video is not None:
            qpos, times = simulate_qpos(args, batch)
            g = np.linalg.norm(batch.gravity[args.instance])
            captions = [f"t = {t:.2f} s   g = {g:.2f} m/s²" for t in times]
            follow = camera if physics.ground.is_flat else side_camera
            with files.partial(args.video):
                write_video(args.video, frames(m, qpos, follow=follow, captions=captions, **size), args.fps)
            print(f"wrote {args.video}: {len(qpos)} frames at {args.fps:g} fps")
    except ValueError as err:
        return cli.fail(err)
    return 0


if __name__ == "__main__":
    sys.exit(process.run(main))
