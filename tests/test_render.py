"""Pictures rendered headless (EGL, software Mesa): not blank, and the robot stands out.

MuJoCo chooses its OpenGL backend once, when it is first imported, and other test
modules import it before this one; so rendering runs in fresh processes (the CLI,
or a spawned worker). The CLI runs as a user on a headless machine runs it: no
MUJOCO_GL, no DISPLAY, so importing `hopper_mjx` must choose the backend itself.
"""

import os
import subprocess
import sys
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context

import imageio.v3 as iio
import numpy as np
import pytest

WIDTH, HEIGHT = 320, 240
HEADLESS = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM", "DISPLAY")}


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "hopper_mjx.render", *args],
                          capture_output=True, text=True, timeout=300, env=HEADLESS)


def _in_fresh_process(fn, *args, **kwargs):
    with ProcessPoolExecutor(1, mp_context=get_context("spawn")) as pool:
        return pool.submit(fn, *args, **kwargs).result(timeout=300)


def _still_and_robot_mask(width, height):
    from hopper_mjx import (
        model,
        render,  # first: it picks the GL backend
    )
    from hopper_mjx.model import robot

    m = render.scene_model()
    qpos = robot.stance_qpos(model.load())
    return render.still(m, qpos, width=width, height=height), render.robot_pixels(m, qpos, width=width, height=height)


def _write_video(path, heights, fps):
    """A video of the stance pose lifted to each base height (the simulated poses of `--video`
    come from `cli.run_batch`, tested elsewhere; compiling a rollout here would add ~30 s)."""
    from hopper_mjx import (
        model,
        render,  # first: it picks the GL backend
    )
    from hopper_mjx.model import robot

    m = render.scene_model()
    poses = [robot.stance_qpos(model.load()) + np.r_[0, 0, dz, np.zeros(m.nq - 3)] for dz in heights]
    render.write_video(path, render.frames(m, poses, width=160, height=120), fps=fps)


def test_still_png_cli_is_not_blank(tmp_path):
    path = tmp_path / "still.png"
    done = run_cli("--still", str(path), "--size", f"{WIDTH}x{HEIGHT}")
    assert done.returncode == 0, done.stderr[-3000:]
    image = iio.imread(path)
    assert image.shape[:2] == (HEIGHT, WIDTH)
    assert image[..., :3].std() > 20  # sky, floor and robot, not one flat colour
    assert len(np.unique(image[..., :3].reshape(-1, 3), axis=0)) > 100
    assert done.stdout == f"wrote {path}\n"  # nothing else on stdout (no library import notices)


def test_a_still_on_a_terrain_draws_the_ground(tmp_path):
    """The same view of a 0.3 m block and of the level grid it stands on: the block shows (the pictures'
    model is the simulated one, height field included), and where it stands, ahead of the robot."""
    images = []
    for height in (0.3, 0.0):
        path = tmp_path / f"block{height}.png"
        done = run_cli("--still", str(path), "--size", f"{WIDTH}x{HEIGHT}", "--terrain", f"obstacle:height={height}")
        assert done.returncode == 0, done.stderr[-3000:]
        images.append(iio.imread(path)[..., :3].astype(int))
    changed = np.abs(images[0] - images[1]).max(axis=-1) > 30
    assert changed.mean() > 0.01
    cols = np.nonzero(changed)[1]
    # +x is to the right: the camera looks at the middle of the robot (x = 0) and the block's far end (x = 0.7),
    # so the block is drawn right of the middle, well inside the picture, and the robot left of it.
    assert 0.5 * WIDTH < np.median(cols) < 0.75 * WIDTH
    assert cols.min() > 0.05 * WIDTH and cols.max() < 0.95 * WIDTH


def test_video_cli_without_display_or_gl_variable(tmp_path):
    """The whole `--video` path (simulate, then render) on a headless machine; a Moon drop
    under `none` keeps the compiled rollout small. The falling robot moves down the frame."""
    path = tmp_path / "drop.gif"
    done = run_cli("--video", str(path), "--gravity", "1.62", "--controller", "none", "--duration", "0.4",
                   "--fps", "10", "--size", "160x120")
    assert done.returncode == 0, done.stderr[-3000:]
    frames = np.stack(list(iio.imiter(path)))[..., :3]
    assert len(frames) == 4  # 0.4 s at 10 fps
    assert np.abs(frames[-1].astype(int) - frames[0].astype(int)).mean() > 0.5
    # The caption (time and gravity) sits in a white band in the top-left corner, and its time changes.
    corner = frames[:, 2:14, 3:60].astype(int)
    assert (corner.min(axis=-1) > 235).mean() > 0.4
    assert np.abs(corner[-1] - corner[0]).max() > 100


def test_robot_pixels_differ_from_the_background():
    image, robot = _in_fresh_process(_still_and_robot_mask, WIDTH, HEIGHT)
    assert robot.mean() > 0.02  # the robot fills a visible part of the frame
    robot_colour = image[robot].mean(axis=0)
    background_colour = image[~robot].mean(axis=0)
    assert np.abs(robot_colour - background_colour).max() > 30
    rows, cols = np.nonzero(robot)
    # The camera tracks the robot: it sits near the middle of the picture.
    assert abs(cols.mean() - WIDTH / 2) < WIDTH / 4 and abs(rows.mean() - HEIGHT / 2) < HEIGHT / 3


@pytest.mark.parametrize("suffix", [".gif", ".mp4"])
def test_video_frames_follow_the_poses(tmp_path, suffix):
    path = tmp_path / f"lift{suffix}"
    heights = [0.0, 0.05, 0.1, 0.15, 0.2]
    _in_fresh_process(_write_video, path, heights, 10)
    frames = np.stack(list(iio.imiter(path)))[..., :3]
    assert len(frames) == len(heights)
    assert frames.std() > 20
    # The camera follows the base horizontally only, so the lifted robot moves up the frame.
    assert np.abs(frames[-1].astype(int) - frames[0].astype(int)).mean() > 0.5


def test_bad_requests_name_the_problem(tmp_path, capsys):
    from hopper_mjx import render  # nothing below renders, so the backend this process has does not matter

    for argv, message in (
        (["--video", str(tmp_path / "x.avi")], "--video must end in .mp4 or .gif"),
        (["--still", str(tmp_path / "x.png"), "--size", "5000x480"], "image size"),
        (["--video", str(tmp_path / "x.gif"), "--gravity", "9.81,1.62", "--instance", "2"], "out of range"),
    ):
        assert render.main(argv) == 2
        assert message in capsys.readouterr().err
    assert not list(tmp_path.iterdir())
    with pytest.raises(SystemExit):
        render.main([])  # nothing to do


def test_simulate_options_reach_the_controller_unchanged():
    """render builds on simulate's parser: a controller option added there (e.g. raibert's --height)
    must arrive as simulate parses it, not be taken by an image option."""
    from hopper_mjx import render, simulate

    defaults = vars(simulate.parser().parse_args([]))
    ours = vars(render.parser().parse_args([]))
    for name, value in defaults.items():
        if name not in ("gravity", "default_gravity", "rate", "out", "scan", "foxglove", "speed_factor"):  # not live
            assert ours[name] == value, name
    assert render.parser().parse_args(["--size", "320x240"]).size == (320, 240)
