"""python -m hopper_mjx.view: MuJoCo's interactive viewer on a live batch of the core.

    python -m hopper_mjx.view --gravity 9.81,3.71,1.62 --num 1 --controller raibert
    python -m hopper_mjx.view --num 342 --show 16 --speed-factor 0.5 --foxglove

The core advances the whole batch in compiled chunks (`hopper_mjx.live`); up to 16 of its
instances are drawn side by side in a display-only scene, each labelled with its gravity
and its hops or state. Keys (also listed in the window; MuJoCo's viewer keeps its own letter,
digit and F1-F7 shortcuts, e.g. 2 hides the robots' geom group):

    Space      pause / run             Enter      one recorded instant (20 ms) while paused
    Backspace  reset the batch         Page Down  select the next shown instance (or double-click one)
    Insert     kick the selected instance sideways (+0.5 m/s)
    Up / Down  commanded speed +- 0.1 m/s     Right / Left  commanded apex rise +- 0.02 m
    = / -      speed factor x2 / /2    F8         print the live status as one JSON line on stdout

`--foxglove [PORT]` also streams the shown instances' ROS topics (docs/recording.md).
Closing the window ends the program. Without a display, use `python -m hopper_mjx.render`.
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "glfw")  # the viewer's own backend; before mujoco is imported

import argparse
import json
import math
import sys
import threading
import time
from contextlib import contextmanager

import mujoco
import numpy as np

from hopper_mjx import cli
from hopper_mjx.live import CHUNK_TIME, HEIGHT_STEP, SHOWN, SPEED_STEP, LiveBatch, LiveRun, spread
from hopper_mjx.shell import jaxsetup, process

SPACING = 1.5  # m between neighbouring robots on the display grid
GROUND_GAP = 0.5  # m between neighbouring copies of a terrain on the display grid
LABEL_ABOVE = 0.45  # m above the base centre
ROBOT_GROUP = 2  # geom group of the robots: MuJoCo's key 2 hides and shows them
FRAME_TIME = 1 / 60  # s: the shortest time between two frames
RENDER_NICE = 10  # niceness added to the window's render threads: on a busy machine the simulation comes first
KEYS_HELP = ("Space\nEnter\nBackspace\nPage Down\nInsert\nUp, Down\nRight, Left\n=, -\nF8",
             ("pause / run\nstep one instant\nreset\nselect a robot\nkick it +0.5 m/s\nspeed +-0.1 m/s\n"
              "apex rise +-0.02 m\nspeed factor x2, /2\nprint status"))
# GLFW key codes. Letters are all MuJoCo viewer shortcuts; these keys are free in its passive mode.
KEY_SPACE, KEY_EQUAL, KEY_MINUS = 32, 61, 45
KEY_ENTER, KEY_BACKSPACE, KEY_INSERT = 257, 259, 260
KEY_RIGHT, KEY_LEFT, KEY_DOWN, KEY_UP, KEY_PAGE_DOWN = 262, 263, 264, 265, 267
KEY_F8 = 297


def grid_offsets(count: int, spacing: float = SPACING) -> np.ndarray:
    """(count, 2) m: a row-major grid centred on the origin, rows along x: one row up to 4
    robots (side by side in the default view), else as square as possible."""
    cols = count if count <= 4 else math.ceil(math.sqrt(count))
    rows = math.ceil(count / cols)
    k = np.arange(count)
    return np.stack([k % cols - (cols - 1) / 2, (rows - 1) / 2 - k // cols], axis=1) * spacing


def spacing(physics) -> float:
    """m between neighbouring robots on the display grid: on a terrain, its copies side by side with a gap."""
    ground = physics.ground
    return SPACING if ground.is_flat else max(ground.size) + GROUND_GAP


def display_model(physics, count: int):
    """(MjModel, qpos address of each copy's free joint, its first body id, bodies per copy):
    `count` copies of the robot of `physics` (a `scenario.Physics`) over the pictures' checkered
    floor, for display only. On a terrain every copy has its own copy of the ground under it, at its
    offset on the display grid (`grid_offsets` at `spacing`): each instance is drawn where it is, in its
    own world."""
    from hopper_mjx.model import FLOOR_GEOM, LEG_CONTACT_GROUP, scene

    def dressed():
        return scene.dress(physics.spec())

    display = dressed()  # floor, sky, lights and robot copy 0
    if not physics.ground.is_flat:
        floor = display.geom(FLOOR_GEOM)
        z = float(floor.pos[2])
        for k, (x, y) in enumerate(grid_offsets(count, spacing(physics))):
            ground = floor if k == 0 else display.worldbody.add_geom(
                type=mujoco.mjtGeom.mjGEOM_HFIELD, hfieldname=floor.hfieldname, material=floor.material,
                contype=0, conaffinity=0)
            ground.pos = [x, y, z]
    for k in range(1, count):
        source = dressed()  # a fresh spec per copy: attaching moves the body
        display.worldbody.add_frame().attach_body(source.worldbody.first_body(), f"monoped_{k}/", "")
    m = display.compile()
    m.geom_group[(m.geom_bodyid != 0) & (m.geom_group != LEG_CONTACT_GROUP)] = ROBOT_GROUP  # contact boxes hidden
    m.site_rgba[:, 3] = 0  # the IMU and foot sites are for the simulation, not for the eye
    m.light_castshadow[:] = 0  # shadows double the cost of a frame in software OpenGL
    free = np.flatnonzero(m.jnt_type == mujoco.mjtJoint.mjJNT_FREE)
    return m, m.jnt_qposadr[free], m.jnt_bodyid[free], (m.nbody - 1) // count


def needs_display() -> str | None:
    """Why no window can open here, or None."""
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        return "no display (DISPLAY is not set)"
    import glfw

    if not glfw.init():
        return f"cannot open the display {os.environ.get('DISPLAY') or os.environ.get('WAYLAND_DISPLAY')}"
    return None


class Display:
    """The viewer window: copies of the shown instances, labels, texts and keys."""

    def __init__(self, viewer, m, qpos_adr, first_body, bodies_per_copy, shown, gravity, spacing: float = SPACING):
        self.viewer, self.m = viewer, m
        self.d = viewer.d
        self.qpos_adr, self.first_body, self.bodies = qpos_adr, first_body, bodies_per_copy
        self.shown = shown
        self.gravity = np.linalg.norm(gravity, axis=1)
        self.offsets = grid_offsets(len(shown), spacing)
        self.selected = 0  # index into shown
        self.labels: list[str] = []
        width = np.ptp(self.offsets, axis=0).max()
        with viewer.lock():
            cam = viewer.cam
            cam.type = mujoco.mjtCamera.mjCAMERA_FREE
            cam.lookat[:] = (0.0, 0.0, 0.45)
            cam.distance = 2.5 + 1.3 * width
            cam.azimuth, cam.elevation = 90.0, -14.0

    def select_from_viewer(self) -> None:
        """A double-clicked robot becomes the selected one."""
        body = self.viewer.perturb.select
        copy = np.flatnonzero((self.first_body <= body) & (body < self.first_body + self.bodies))
        if body > 0 and copy.size:
            self.selected = int(copy[0])

    def draw(self, chunk, index: int) -> None:
        """Poses every copy at the chunk's recorded instant `index` and relabels them."""
        traj = chunk.traj
        state = max(int(np.searchsorted(traj.time["state"], chunk.clock[index], side="right")) - 1, 0)
        qpos = traj.qpos[self.shown, state]
        self.labels = [self.label(i, chunk) for i in range(len(self.shown))]
        with self.viewer.lock():
            for k, adr in enumerate(self.qpos_adr):
                self.d.qpos[adr:adr + qpos.shape[1]] = qpos[k]
                self.d.qpos[adr:adr + 2] += self.offsets[k]
            mujoco.mj_kinematics(self.m, self.d)
            scn = self.viewer.user_scn
            scn.ngeom = 0
            for k, text in enumerate(self.labels):
                pos = self.d.xpos[self.first_body[k]] + (0, 0, LABEL_ABOVE)
                geom = scn.geoms[scn.ngeom]
                mujoco.mjv_initGeom(geom, mujoco.mjtGeom.mjGEOM_LABEL, np.zeros(3), pos, np.eye(3).ravel(),
                                    np.ones(4, np.float32))
                geom.label = text
                scn.ngeom += 1

    def label(self, k: int, chunk) -> str:
        i = self.shown[k]
        status = chunk.status[i]
        state = f"{chunk.hops[i]} hops" if status in ("hopping", "standing") else status
        return f"{'> ' if k == self.selected else ''}g {self.gravity[i]:.2f}  {state}"

    def show_texts(self, texts: tuple[str, str]) -> None:
        self.viewer.set_texts([
            (mujoco.mjtFontScale.mjFONTSCALE_150, mujoco.mjtGridPos.mjGRID_TOPLEFT, *texts),
            (mujoco.mjtFontScale.mjFONTSCALE_100, mujoco.mjtGridPos.mjGRID_BOTTOMLEFT, *KEYS_HELP),
        ])


def status_texts(run, n: int, shown: int, frame_rate: float) -> tuple[str, str]:
    """The overlay's two columns: speed factor asked and reached, steps/s, frames/s, time, commands."""
    factor, steps = run.pacer.reached()
    chunk = run.chunk
    command = "none (this controller)" if chunk is None or chunk.command is None else (
        f"{chunk.command['speed'][0]:+.2f}, {chunk.command['speed'][1]:+.2f} m/s, "
        f"apex +{chunk.command['height']:.2f} m")
    reached = "paused" if run.paused else ("-" if math.isnan(factor) else f"x{factor:.2f}")
    return ("speed factor\nreached\nsteps/s\nframes/s\ntime\ninstances\ncommand",
            f"x{run.pacer.factor:g}\n{reached}\n{'-' if math.isnan(steps) else f'{steps:,.0f}'}\n"
            f"{'-' if math.isnan(frame_rate) else f'{frame_rate:.1f}'}\n"
            f"{run.time:.2f} s\n{n} ({shown} shown)\n{command}")


def status_line(run, display: Display) -> str:
    """One JSON line: what the window shows, for scripts and tests, and the Enter presses queued while paused
    (`steps_pending`: a press shows there at once, before its instant plays)."""
    chunk = run.chunk
    instances = []
    if chunk is not None:
        index = max(int(np.searchsorted(chunk.traj.time["odom"], run.time, side="right")) - 1, 0)
        for k, i in enumerate(display.shown):
            instances.append({
                "index": i, "label": display.labels[k] if display.labels else "",
                "gravity": float(display.gravity[i]), "hops": int(chunk.hops[i]), "status": chunk.status[i],
                "base_position": chunk.traj.odom.pos[i, index].round(4).tolist(),
                "base_velocity": chunk.traj.odom.linvel[i, index].round(4).tolist(),
            })
    factor, steps = run.pacer.reached()
    return json.dumps({
        "time": round(run.time, 6), "paused": run.paused, "steps_pending": run.steps_pending,
        "speed_factor": run.pacer.factor,
        "reached_factor": None if math.isnan(factor) else round(factor, 3),
        "steps_per_s": None if math.isnan(steps) else round(steps),
        "command": None if chunk is None else chunk.command,
        "selected": display.shown[display.selected], "instances": instances,
    })


def key_handler(run, display: Display, requests: set):
    """The viewer's key callback (runs on the viewer's thread: it only queues work)."""
    def on_key(key: int) -> None:
        if key == KEY_SPACE:
            run.toggle_pause()
        elif key == KEY_ENTER:
            run.step()
        elif key == KEY_BACKSPACE:
            run.reset()
        elif key == KEY_PAGE_DOWN:
            display.selected = (display.selected + 1) % len(display.shown)
        elif key == KEY_INSERT:
            display.select_from_viewer()
            instance = display.shown[display.selected]
            run.act(lambda batch: batch.kick(instance))
        elif key in (KEY_UP, KEY_DOWN):
            step = SPEED_STEP if key == KEY_UP else -SPEED_STEP
            run.act(lambda batch: batch.change_command(speed_step=(step, 0.0)))
        elif key in (KEY_RIGHT, KEY_LEFT):
            step = HEIGHT_STEP if key == KEY_RIGHT else -HEIGHT_STEP
            run.act(lambda batch: batch.change_command(height_step=step))
        elif key in (KEY_EQUAL, KEY_MINUS):
            run.set_factor(run.pacer.factor * (2.0 if key == KEY_EQUAL else 0.5))
        elif key == KEY_F8:
            requests.add("status")

    return on_key


def parser() -> argparse.ArgumentParser:
    p = cli.parser("python -m hopper_mjx.view", __doc__)
    cli.add_batch_options(p)
    p.set_defaults(controller="raibert", duration=None)
    cli.add_live_options(p, foxglove_help="also stream the shown instances' ROS topics")
    p.add_argument("--show", type=int, default=SHOWN,
                   help=f"instances drawn, spread over the batch (at most {SHOWN})")
    p.add_argument("--paused", action="store_true", help="start paused (Space runs)")
    return p


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    from hopper_mjx.ros import foxglove

    try:
        checked = cli.check_batch(args)
        cli.refuse_each(checked.physics.ground, "view")
        if not 1 <= args.show <= SHOWN:
            raise ValueError(f"--show must be in 1..{SHOWN}, got {args.show}")
        shown = spread(len(checked.gravity), args.show)
        with foxglove.listening(args, shown) as stream:
            why = needs_display()
            if why:
                return cli.fail(f"view needs a display: {why}; for pictures and videos without one use "
                                "python -m hopper_mjx.render")
            jaxsetup.configure()
            batch = LiveBatch.build(checked)
            if stream is not None:
                stream.attach(batch)
                print(f"streaming to Foxglove on ws://127.0.0.1:{stream.port}", flush=True)
            return watch(args, checked.physics, batch, shown, stream)
    except ValueError as err:  # includes URDFError and a busy --foxglove port
        return cli.fail(err)


class FrameStats:
    """Where the main thread's wall time goes, frame by frame, and the frame rate."""

    STAGES = ("poll", "draw", "sync", "renderer")  # renderer: waiting for the window to take the last frame

    def __init__(self):
        self.spent = dict.fromkeys(self.STAGES, 0.0)
        self.frames = 0
        self.recent: list[float] = []  # wall times of the frames of the last 2 s
        self.first: tuple[float, float] | None = None  # (wall, simulated time) of the first frame that played

    @contextmanager
    def stage(self, name: str):
        start = time.perf_counter()
        try:
            yield
        finally:
            self.spent[name] += time.perf_counter() - start

    def frame_done(self, run) -> None:
        now = time.perf_counter()
        if self.first is None and run.chunk is not None:  # play starts: count from here, not from the compile
            self.first = (now, run.played_until)
            self.spent, self.frames = dict.fromkeys(self.STAGES, 0.0), 0
        self.last = (now, run.played_until)
        self.frames += 1
        self.recent.append(now)
        while now - self.recent[0] > 2.0:
            self.recent.pop(0)

    def rate(self) -> float:
        """Frames per second over the last 2 s."""
        span = self.recent[-1] - self.recent[0] if len(self.recent) > 1 else 0.0
        return (len(self.recent) - 1) / span if span > 0 else math.nan

    def summary(self, run) -> str:
        """Two lines: the real-time factor over the run, then the frame rate and where a frame's time went."""
        per_frame = ", ".join(f"{k} {1e3 * v / max(self.frames, 1):.1f} ms" for k, v in self.spent.items())
        chunks = np.asarray(run.chunk_seconds[1:] or [math.nan])  # the first one includes the compile
        (w0, t0), (w1, t1) = self.first or self.last, self.last
        wall = max(w1 - w0, 1e-9)
        return (f"view: played {t1 - t0:.2f} s in {w1 - w0:.2f} s: real-time factor x{(t1 - t0) / wall:.2f} "
                f"(x{run.pacer.factor:g} asked, pauses included)\n"
                f"view: {self.frames} frames, {self.frames / wall:.1f} frames/s; per frame: {per_frame}; "
                f"a {CHUNK_TIME:g} s chunk took {1e3 * np.median(chunks):.0f} ms to compute "
                f"(median of {len(run.chunk_seconds)})")


def launch_viewer(m, key_callback):
    """MuJoCo's passive viewer, launched from a thread niced by RENDER_NICE (Linux niceness is per
    thread), so that its render thread and the GL driver's threads it starts inherit it."""
    import mujoco.viewer

    out = {}

    def launch():
        try:
            os.setpriority(os.PRIO_PROCESS, 0, min(os.getpriority(os.PRIO_PROCESS, 0) + RENDER_NICE, 19))
        except (AttributeError, OSError):  # no per-thread niceness here: the frames just compete
            pass
        out["viewer"] = mujoco.viewer.launch_passive(m, mujoco.MjData(m), show_left_ui=False,
                                                     show_right_ui=False, key_callback=key_callback)

    launcher = threading.Thread(target=launch, name="viewer-launch")
    launcher.start()
    launcher.join()
    return out["viewer"]


def show_frame(run, display: Display, stats: FrameStats, requests: set) -> None:
    """Plays what is due, poses and labels the robots, and hands the frame to the window."""
    with stats.stage("poll"):
        played = run.poll()
    texts = status_texts(run, run.batch.n, len(display.shown), stats.rate())
    with stats.stage("draw"):
        if played is not None:
            display.draw(*played)
    if "status" in requests:
        requests.discard("status")
        print(status_line(run, display), flush=True)
    with stats.stage("sync"):
        display.viewer.sync()
    with stats.stage("renderer"):
        display.show_texts(texts)  # returns once the window has drawn the previous texts
    stats.frame_done(run)


def watch(args, physics, batch, shown: list[int], stream) -> int:
    """Runs the window until it is closed (or --duration is played); prints the factor reached
    and where each frame's time went."""
    m, qpos_adr, first_body, bodies = display_model(physics, len(shown))
    requests: set = set()
    run = LiveRun(batch, factor=args.speed_factor, sinks=[stream] if stream else [], paused=args.paused)
    holder = {}
    before = set(threading.enumerate())
    viewer = launch_viewer(m, key_callback=lambda key: holder["on_key"](key) if holder else None)
    display = Display(viewer, m, qpos_adr, first_body, bodies, shown, batch.gravity, spacing(physics))
    holder["on_key"] = key_handler(run, display, requests)
    stats, announced = FrameStats(), False
    with run:
        while viewer.is_running() and (args.duration is None or run.time < args.duration - 1e-9):
            start = time.perf_counter()
            show_frame(run, display, stats, requests)
            if run.chunk is not None and not announced:
                print(f"view: running {cli.counted(batch.n, 'instance')}, {len(shown)} shown", flush=True)
                announced = True
            time.sleep(max(FRAME_TIME - (time.perf_counter() - start), 0.0))
    viewer.close()
    # The window's thread tears down its GL context after the close; exiting under it aborts the process. Only the
    # threads the window started: the process's signal watcher never ends, and waiting on it held every exit 10 s.
    for thread in set(threading.enumerate()) - before:  # this thread is among those before
        if thread.daemon:
            thread.join(timeout=10)
    print(stats.summary(run), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(process.run(main))
