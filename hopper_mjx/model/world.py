"""Gazebo world files (SDF `.world`): the physics settings a seed user set there, for our batch.

The seed set gravity and the physics step in a Gazebo world file (its
`worlds/low_gravity.world`, shipped here as `hopper_mjx/model/low_gravity.world`).
What MuJoCo can honour is taken:

- `<world><gravity>x y z</gravity>` (SDF >= 1.5; `<physics><gravity>` in SDF 1.4): the
  full vector in m/s², e.g. `0 0 -9.8`;
- `<physics><max_step_size>`: the physics timestep, s;
- the ground's `<surface><friction><ode><mu>/<mu2>`: Gazebo's ODE combines two
  surfaces' coefficients by taking the smaller, so the foot-floor friction is
  min(ground, foot) per direction. Gazebo's stock `model://ground_plane` has
  mu = 100, mu2 = 50 (its model.sdf).
- a ground model whose collision is a `<heightmap>` (its `<uri>` a greyscale PNG, a
  path relative to the world file or `file://`; `<size>` x y z in m; `<pos>` at the
  origin): the terrain `heightmap:FILE,size=XxY,height=Z` (docs/terrain.md), as
  Gazebo lays it, black at z = 0 and white at z = Z, the image's top row at +y.

Every other element is ignored, and `parse` lists them, so that the caller can
name them all in one warning line. A batch compiles one MuJoCo model, so worlds
batched together must agree on the timestep and the friction; their gravities
may all differ (`batch`).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hopper_mjx.model.loader import read_text
from hopper_mjx.shell.checks import MAX_TIMESTEP

EARTH_GRAVITY = 9.81  # m/s², the standard reference g every g-scaled quantity is measured against
LOW_GRAVITY_WORLD = Path(__file__).with_name("low_gravity.world")  # the seed's, as an example
SDF_DEFAULT_GRAVITY = (0.0, 0.0, -9.8)  # m/s², SDF's default <gravity>
SDF_DEFAULT_MU = 1.0  # SDF's default <surface><friction><ode><mu> (and mu2)
GROUND_PLANE_URI = "model://ground_plane"
GROUND_PLANE_MU = (100.0, 50.0)  # mu, mu2 of Gazebo's stock ground_plane model
TOLERANCE = 1e-9  # worlds whose timesteps or friction differ by less are the same


class WorldError(ValueError):
    """A world file that cannot be read, or worlds that cannot share one batch."""


@dataclass(frozen=True)
class World:
    source: str  # the file, for messages
    name: str  # <world name=...>
    gravity: tuple[float, float, float]  # m/s², world frame (z up), the vector itself
    timestep: float | None  # s, <physics><max_step_size>, None when not given
    ground_friction: tuple[float, float] | None  # (mu, mu2) of the ground surface; None: no ground found
    terrain: str | None  # a <heightmap> ground as a --terrain spec; None: the ground is a plane
    ignored: tuple[str, ...]  # elements with no effect here, as paths like physics/real_time_factor


def gravity_vectors(magnitudes) -> np.ndarray:
    """(N,) magnitudes in m/s², pointing down -> (N, 3) vectors; rejects bad values."""
    g = np.asarray(magnitudes, dtype=float).reshape(-1)
    if g.size == 0:
        raise ValueError("no gravity values: need at least one instance")
    if not np.all(np.isfinite(g)):
        raise ValueError(f"gravity must be finite, got {g[~np.isfinite(g)][:3]}")
    if np.any(g < 0):
        raise ValueError(f"gravity magnitudes point down and must be >= 0, got {g[g < 0][:3]}")
    return np.stack([np.zeros_like(g), np.zeros_like(g), -g], axis=1)


def _vector(text: str | None, n: int, where: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in (text or "").split())
    except ValueError:
        raise WorldError(f"{where} must be {n} numbers, got {text!r}") from None
    if len(values) != n or not all(math.isfinite(v) for v in values):
        raise WorldError(f"{where} must be {n} finite numbers, got {text!r}")
    return values


def _positive(element: ET.Element, where: str) -> float:
    (value,) = _vector(element.text, 1, where)
    if not value > 0:
        raise WorldError(f"{where} must be > 0, got {value:g}")
    return value


def _friction(surface: ET.Element | None, where: str, ignored: list[str]) -> tuple[float, float]:
    """(mu, mu2) of a <surface>; the rest of the surface (bounce, contact stiffness) is ignored."""
    if surface is None:
        return (SDF_DEFAULT_MU, SDF_DEFAULT_MU)
    ode = surface.find("friction/ode")
    mu = [SDF_DEFAULT_MU, SDF_DEFAULT_MU]
    for k, tag in enumerate(("mu", "mu2")):
        element = None if ode is None else ode.find(tag)
        if element is not None:
            (mu[k],) = _vector(element.text, 1, f"{where}/friction/ode/{tag}")
            if mu[k] < 0:
                raise WorldError(f"{where}/friction/ode/{tag} must be >= 0, got {mu[k]:g}")
    for child in surface:
        if child.tag != "friction":
            ignored.append(f"{where}/{child.tag}")
    if ode is not None:
        ignored += [f"{where}/friction/ode/{c.tag}" for c in ode if c.tag not in ("mu", "mu2")]
    ignored += [f"{where}/friction/{c.tag}" for c in surface.findall("friction/*") if c.tag != "ode"]
    return (mu[0], mu[1])


def _ground(model: ET.Element, base: Path, ignored: list[str]) -> tuple[tuple[float, float], str | None] | None:
    """(friction, terrain spec or None) of an inline model that is a level plane or a heightmap (Gazebo's
    ground), else None."""
    name = model.get("name", "?")
    for collision in model.iter("collision"):
        surface = collision.find("surface")
        if collision.find("geometry/plane") is not None:
            normal = collision.findtext("geometry/plane/normal")
            if normal is not None and _vector(normal, 3, f"model '{name}' plane normal") != (0.0, 0.0, 1.0):
                raise WorldError(f"model '{name}': only a level ground plane (normal 0 0 1) is supported")
            return _friction(surface, f"model[{name}]/surface", ignored), None
        if (heightmap := collision.find("geometry/heightmap")) is not None:
            return _friction(surface, f"model[{name}]/surface", ignored), _heightmap(model, heightmap, base)
    return None


def _heightmap(model: ET.Element, heightmap: ET.Element, base: Path) -> str:
    """A <heightmap> as a --terrain spec; WorldError for what the terrain cannot lay as Gazebo does."""
    where = f"model '{model.get('name', '?')}' <heightmap>"
    uri = (heightmap.findtext("uri") or "").strip()
    if not uri:
        raise WorldError(f"{where} has no <uri>")
    if "://" in uri.removeprefix("file://"):
        raise WorldError(f"{where}: <uri> {uri} needs Gazebo's resource paths; give the PNG's path (relative to "
                         "the world file) or file://PATH")
    path = Path(uri.removeprefix("file://"))
    path = path if path.is_absolute() else base / path
    if "," in str(path):  # the terrain spec separates its items with commas
        raise WorldError(f"{where}: the image path {path} has a comma; rename it")
    size = _vector(heightmap.findtext("size") or "1 1 1", 3, f"{where} <size>")
    if not all(v > 0 for v in size):
        raise WorldError(f"{where} <size> must be 3 lengths > 0 in m, got {heightmap.findtext('size')!r}")
    # The terrain is centred at the origin with black at z = 0, where every instance starts.
    offsets = {"<pos>": heightmap.findtext("pos"), "the model's <pose>": model.findtext("pose")}
    for what, text in offsets.items():
        if text is not None and any(_vector(text, len(text.split()), f"{where} {what}")):
            raise WorldError(f"{where}: {what} {text.strip()} moves it off the origin; the terrain is centred there "
                             "with its black at z = 0")
    return f"heightmap:{path},size={size[0]:g}x{size[1]:g},height={size[2]:g}"


def _physics(physics: ET.Element, ignored: list[str]) -> tuple[float | None, tuple[float, ...] | None]:
    """(max_step_size, SDF 1.4 gravity) of a <physics> element."""
    timestep = gravity = None
    for child in physics:
        if child.tag == "max_step_size":
            timestep = _positive(child, "<physics><max_step_size>")
            if timestep > MAX_TIMESTEP:
                raise WorldError(f"<physics><max_step_size> {timestep:g} s is over the {MAX_TIMESTEP:g} s a step "
                                 "may take here")
        elif child.tag == "gravity":
            gravity = _vector(child.text, 3, "<physics><gravity>")
        else:
            ignored.append(f"physics/{child.tag}")
    return timestep, gravity


def parse(text: str, source: str = "<string>") -> World:
    """Reads one SDF world (see the module docstring for what is taken); a heightmap's image path is
    relative to the folder of `source`."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as err:
        raise WorldError(f"{source} is not well-formed XML: {err}") from None
    world = root.find("world") if root.tag == "sdf" else None
    if world is None:
        raise WorldError(f"{source}: expected <sdf><world>...</world></sdf>, found <{root.tag}>")
    ignored: list[str] = []
    gravity = timestep = ground = terrain = None
    base = Path(source).parent
    physics_seen = False
    for child in world:
        if child.tag == "gravity":
            gravity = _vector(child.text, 3, "<world><gravity>")
        elif child.tag == "physics" and not physics_seen:
            physics_seen = True
            timestep, old_gravity = _physics(child, ignored)
            gravity = gravity or old_gravity
        elif child.tag == "include" and (child.findtext("uri") or "").strip() == GROUND_PLANE_URI:
            ground = GROUND_PLANE_MU
        elif child.tag == "include":
            ignored.append(f"include {(child.findtext('uri') or '?').strip()}")
        elif child.tag == "model" and (found := _ground(child, base, ignored)) is not None:
            ground, terrain = found
        else:
            ignored.append(child.tag if child.tag != "model" else f"model[{child.get('name', '?')}]")
    return World(
        source=source,
        name=world.get("name", ""),
        gravity=tuple(float(v) for v in (gravity or SDF_DEFAULT_GRAVITY)),
        timestep=timestep,
        ground_friction=ground,
        terrain=terrain,
        ignored=tuple(ignored),
    )


def read(path: str | Path) -> World:
    """`parse` of a file, with a one-line error naming it when it cannot be read."""
    text = read_text(path, "world file", WorldError)
    try:
        return parse(text, str(path))
    except WorldError as err:  # name the file in every refusal, also those of its tags
        raise WorldError(str(err) if str(err).startswith(str(path)) else f"{path}: {err}") from None


def foot_friction(world_mu: tuple[float, float] | None, foot_mu: float) -> tuple[float, float] | None:
    """The foot-floor (mu, mu2) under Gazebo's rule min(ground, foot), None when the world has no ground."""
    return None if world_mu is None else (min(world_mu[0], foot_mu), min(world_mu[1], foot_mu))


@dataclass(frozen=True)
class WorldBatch:
    worlds: tuple[World, ...]
    gravity: np.ndarray  # (K, 3) m/s², one row per world
    timestep: float | None  # s, shared by every world that sets it
    ground_friction: tuple[float, float] | None  # shared (mu, mu2), None: no world named a ground
    terrain: str | None  # the shared <heightmap> ground as a --terrain spec, None: a plane

    def model_options(self, foot_mu: float) -> dict:
        """Keyword arguments of `model.load` that the worlds set (timestep, foot-floor friction)."""
        options = {} if self.timestep is None else {"timestep": self.timestep}
        if self.ground_friction is not None:
            options["friction"] = foot_friction(self.ground_friction, foot_mu)
        return options

    def warning(self) -> str | None:
        """One line naming every ignored element of every world, or None when nothing was ignored."""
        parts = [f"{Path(w.source).name}: {', '.join(w.ignored)}" for w in self.worlds if w.ignored]
        return f"warning: world settings with no effect here: {'; '.join(parts)}" if parts else None


def _shared(worlds: tuple[World, ...], field: str, what: str):
    values = {w.source: getattr(w, field) for w in worlds if getattr(w, field) is not None}
    distinct = list(values.values())
    if any(not np.allclose(v, distinct[0], rtol=0, atol=TOLERANCE) for v in distinct[1:]):
        listed = ", ".join(f"{Path(s).name}: {v}" for s, v in values.items())
        raise WorldError(f"worlds batched together must share {what} (one compiled model), got {listed}")
    return distinct[0] if distinct else None


def batch(worlds) -> WorldBatch:
    """Worlds run together: their gravities stack; timestep and ground friction must agree."""
    worlds = tuple(worlds)
    if not worlds:
        raise WorldError("no world files given")
    gravity = np.array([w.gravity for w in worlds], dtype=float)
    up = gravity[:, 2] > 0
    if up.any():
        bad = worlds[int(np.argmax(up))]
        raise WorldError(f"{bad.source}: gravity {bad.gravity} points up (z > 0); the floor is below the robot")
    return WorldBatch(
        worlds=worlds,
        gravity=gravity,
        timestep=_shared(worlds, "timestep", "<max_step_size>"),
        ground_friction=_shared(worlds, "ground_friction", "the ground's friction"),
        terrain=_same_terrain(worlds),
    )


def _same_terrain(worlds: tuple[World, ...]) -> str | None:
    terrains = {w.terrain for w in worlds}
    if len(terrains) > 1:
        listed = ", ".join(f"{Path(w.source).name}: {w.terrain or 'a plane'}" for w in worlds)
        raise WorldError(f"worlds batched together must share their ground (one compiled model), got {listed}")
    return terrains.pop()
