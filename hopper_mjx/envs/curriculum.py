"""The terrain curriculum: on a `course` ground (`terrain.generators.course`), each episode starts on the pad of
a tile of its own level, and the level follows how the last episode went, as legged_gym's terrain curriculum does.

- An episode that lasts to its end and has hopped out of its tile (half a tile from its start) moves up a level;
  one that falls, or goes less than half as far as its commanded speed asked, moves down (not below 0); any other
  stays. So hopping in place on the pad earns no level: the robot must cross the tile's ground.
- Past the top level an episode goes to a random level, so the hardest ground does not crowd out the rest.
- The first episodes start on a random level of the lower half.
- The kind of ground (a column: rough, steps, gaps, blocks) is drawn per episode; the start is jittered on the pad.

The level lives in `State.info["level"]`; `wrappers.ResampleAutoReset` asks `next_level` for a finished episode's.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from hopper_mjx.terrain import generators, spec

JITTER = 0.1  # m: the start's spread about a tile's centre, well inside the pad
STREAM = 3  # folded into an episode's key for its level's and tile's draws (1 is the robot's, 2 the pushes')


class Curriculum(NamedTuple):
    centres: jax.Array  # (levels, kinds, 2) m, world (x, y) of each tile's centre
    tile: float  # m, a tile's side

    @classmethod
    def of(cls, ground) -> Curriculum | None:
        """The curriculum of a `course` ground; None on any other (every episode starts at the origin)."""
        if ground.name != "course":
            return None
        return cls(jnp.asarray(spec.tile_centres(ground), jnp.float32), float(dict(ground.values)["tile"]))

    @property
    def levels(self) -> int:
        return self.centres.shape[0]

    def first(self, key: jax.Array) -> jax.Array:
        """() int32: a first episode's level, uniform over the lower half (the middle one included)."""
        return jax.random.randint(jax.random.fold_in(key, STREAM), (), 0, (self.levels - 1) // 2 + 1)

    def next_level(self, level: jax.Array, survived: jax.Array, travelled: jax.Array, asked: jax.Array,
                   key: jax.Array) -> jax.Array:
        """The level of the episode after one at `level` that `survived` to its end or fell, its base `travelled`
        m from its start where its command `asked` for that many (speed times the episode's time)."""
        up = survived & (travelled >= self.tile / 2)
        down = ~survived | (travelled < asked / 2)
        moved = jnp.where(up, level + 1, jnp.where(down, jnp.maximum(level - 1, 0), level))
        anywhere = jax.random.randint(jax.random.fold_in(key, STREAM + 1), (), 0, self.levels)
        return jnp.where(moved >= self.levels, anywhere, moved).astype(jnp.int32)

    def start(self, level: jax.Array, key: jax.Array) -> jax.Array:
        """(2,) m: where an episode of `level` starts: a random kind's tile, jittered about its centre."""
        k_kind, k_jitter = jax.random.split(jax.random.fold_in(key, STREAM + 2))
        kind = jax.random.randint(k_kind, (), 0, len(generators.COURSE_KINDS))
        return self.centres[level, kind] + jax.random.uniform(k_jitter, (2,), minval=-JITTER, maxval=JITTER)


# A policy trained on the course is judged in the core, every robot from the origin, on each of these: the rough
# ground hop_terrain's policies trained on until the course (its amplitude the middle level's, 0.02 m), and a 0.10 m
# block ahead (the course's blocks at levels 2 and 3 are 0.075 and 0.1125 m). The first is the one its threshold is
# judged on.
JUDGE_GROUNDS = ("rough:amp=0.02,wavelength=0.4,seed=1,size=24x24", "obstacle:height=0.1,x=0.6,size=24x24")


def is_course(terrain: str) -> bool:
    """Is the --terrain spec `terrain` a training course (read as text: no JAX, nothing built)?"""
    return terrain.split(":")[0].strip() == "course"


def judge_grounds(terrain: str) -> tuple[str, ...]:
    """The --terrain specs a policy trained on `terrain` is judged on in the core: its own, but for a course."""
    return JUDGE_GROUNDS if is_course(terrain) else (terrain,)


def judged_on(terrain: str) -> str:
    """The ground a policy trained on `terrain` meets its threshold on (`judge_grounds`' first)."""
    return judge_grounds(terrain)[0]
