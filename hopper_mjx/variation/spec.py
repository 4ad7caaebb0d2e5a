"""Per-instance robot variation, as a user writes it: which parameters, drawn from which distributions.

    spec = Spec.parse("foot_friction=uniform(0.4,1.0),base_mass=scale(0.9,1.1),dof_damping=0.1")
    spec = Spec.of({"foot_friction": "0.4..1.0", "base_mass": Dist("scale", 0.9, 1.1)})

The parameter names are `registry.PARAMETERS`; a distribution is a fixed value, `uniform(a,b)`
(or `a..b`), `loguniform(a,b)`, `normal(mu,sigma)` or `scale(a,b)` (the nominal value times
uniform(a, b)). Pure Python and NumPy, so that the command line refuses a bad spec before MuJoCo
or JAX is loaded; `variation.draw` resolves the names to model fields and draws per instance.
"""

from __future__ import annotations

import math
import re
import zlib
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from hopper_mjx import registry

KINDS = {
    "fixed": "the same value for every instance",
    "uniform": "uniform(a,b), also written a..b",
    "loguniform": "loguniform(a,b), 0 < a: uniform in log",
    "normal": "normal(mu,sigma)",
    "scale": "scale(a,b): the nominal value times uniform(a,b)",
}
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|[-+]?(?:inf|nan)"
_CALL = re.compile(rf"^(\w+)\(\s*({_NUMBER})\s*,\s*({_NUMBER})\s*\)$", re.IGNORECASE)
_RANGE = re.compile(rf"^({_NUMBER})\s*\.\.\s*({_NUMBER})$", re.IGNORECASE)
# Every name --randomize takes: the model fields', then the controller's, motors' and sensors'.
NAMES = {**registry.PARAMETERS, **registry.CONTROL_PARAMETERS}


# scale(a,b)'s factors: beyond these a drawn robot is no longer this robot (a mass 100 times the URDF's leaves its
# motors able to hold it standing only below 0.81 m/s², `model.robot.max_standing_gravity`).
MIN_SCALE, MAX_SCALE = 0.01, 100.0


class Dist(NamedTuple):
    """One distribution: `kind` (a KINDS name) and its two numbers (a fixed value uses `a` only)."""

    kind: str
    a: float
    b: float = 0.0

    def check(self) -> None:
        """Raises ValueError for a distribution that draws nothing sensible."""
        if self.kind not in KINDS:
            raise ValueError(f"unknown distribution {self.kind!r}; choose from: {', '.join(KINDS)}")
        numbers = (self.a,) if self.kind == "fixed" else (self.a, self.b)
        if not all(math.isfinite(v) for v in numbers):
            raise ValueError(f"{self} has a non-finite bound")
        if self.kind == "normal" and self.b < 0:
            raise ValueError(f"{self}: sigma must be >= 0")
        if self.kind in ("uniform", "loguniform", "scale") and self.a > self.b:
            raise ValueError(f"{self}: bounds reversed ({self.a:g} > {self.b:g})")
        if self.kind == "loguniform" and self.a <= 0:
            raise ValueError(f"{self}: loguniform needs bounds > 0")
        if self.kind == "scale" and not (MIN_SCALE <= self.a and self.b <= MAX_SCALE):
            raise ValueError(f"{self}: a factor outside {MIN_SCALE:g}..{MAX_SCALE:g} of the URDF's value builds no "
                             "robot of this kind (at 100 times its mass the motors hold it standing only below "
                             "0.81 m/s²); give factors within it, or a value with uniform(a,b)")

    def draw(self, rng: np.random.Generator, nominal: np.ndarray, n: int) -> np.ndarray:
        """(n, *nominal.shape) values: nominal broadcast over n instances, each element drawn independently."""
        shape = (n, *np.shape(nominal))
        if self.kind == "fixed":
            return np.full(shape, self.a)
        if self.kind == "uniform":
            return rng.uniform(self.a, self.b, shape)
        if self.kind == "loguniform":
            return np.exp(rng.uniform(math.log(self.a), math.log(self.b), shape))
        if self.kind == "normal":
            return rng.normal(self.a, self.b, shape)
        return np.asarray(nominal, dtype=float) * rng.uniform(self.a, self.b, shape)

    def bound(self, nominal: float = 1.0) -> float:
        """The largest value it can draw (inf for a normal), for what must be sized before the draws."""
        if self.kind == "fixed":
            return self.a
        if self.kind == "normal":
            return math.inf if self.b > 0 else self.a
        return self.b * nominal if self.kind == "scale" else self.b

    def ends(self, shape: tuple[int, ...]) -> np.ndarray | None:
        """(2, *shape): the least and the greatest draws, as `draw` gives n = 2 of them; None for a normal, which
        can draw any value."""
        if self.kind == "normal":
            return None
        low, high = (self.a, self.a) if self.kind == "fixed" else (self.a, self.b)
        return np.stack([np.full(shape, low), np.full(shape, high)])

    def __str__(self) -> str:
        return f"{self.a:g}" if self.kind == "fixed" else f"{self.kind}({self.a:g},{self.b:g})"


def check_engine_varies(engine: str, fields: frozenset[str]) -> None:
    """Raises ValueError when engine `engine` cannot take these model fields per instance at run time
    ("auto" can: it falls back to mjx)."""
    if engine == "chain" and not fields <= registry.CHAIN_VARIES:
        raise ValueError(f"the chain engine cannot vary {', '.join(sorted(fields - registry.CHAIN_VARIES))} "
                         "per instance yet")


def parse_dist(text: str) -> Dist:
    text = text.strip()
    if (call := _CALL.match(text)) is not None:
        kind, a, b = call.group(1).lower(), float(call.group(2)), float(call.group(3))
        if kind == "fixed":
            raise ValueError(f"a fixed value is written as a number, got {text!r}")
        dist = Dist(kind, a, b)
    elif (span := _RANGE.match(text)) is not None:
        dist = Dist("uniform", float(span.group(1)), float(span.group(2)))
    else:
        try:
            dist = Dist("fixed", float(text))
        except ValueError:
            raise ValueError(f"cannot read {text!r}: give a number, a..b, or one of "
                             f"{', '.join(k for k in KINDS if k != 'fixed')}(a,b)") from None
    dist.check()
    return dist


def _items(text: str) -> list[str]:
    """Splits 'a=f(1,2),b=3' at the commas outside parentheses."""
    items, depth, start = [], 0, 0
    for i, c in enumerate(text):
        depth += (c == "(") - (c == ")")
        if c == "," and depth == 0:
            items.append(text[start:i])
            start = i + 1
    return [s for s in [*items, text[start:]] if s.strip()]


@dataclass(frozen=True)
class Spec:
    """Which parameters vary, in the order given (a later one wins where two set the same element)."""

    items: tuple[tuple[str, Dist], ...] = ()

    @classmethod
    def parse(cls, text: str) -> "Spec":
        """'name=dist,name=dist', or a preset's name among them (`registry.RANDOMIZE_PRESETS`); raises
        ValueError naming the first bad item."""
        items = []
        for item in _items(text):
            name, eq, dist = item.partition("=")
            name = name.strip()
            if not eq and name in registry.RANDOMIZE_PRESETS:
                items += [(n, d) for n, _, d in (i.partition("=") for i in _items(registry.RANDOMIZE_PRESETS[name]))]
                continue
            if not eq:
                raise ValueError(f"{item.strip()!r} is not NAME=DISTRIBUTION (nor a preset: "
                                 f"{', '.join(registry.RANDOMIZE_PRESETS)})")
            items.append((name, dist))
        return cls.of(dict(_unique(items)))

    @classmethod
    def of(cls, mapping: dict) -> "Spec":
        """From Python or a YAML block: name -> Dist, a number, or a distribution's text."""
        items = []
        for name, value in mapping.items():
            registry.check("parameter", NAMES, str(name))
            try:
                if isinstance(value, Dist):
                    value.check()
                    dist = value
                elif isinstance(value, (int, float)) and not isinstance(value, bool):
                    dist = parse_dist(repr(float(value)))
                elif isinstance(value, str):
                    dist = parse_dist(value)
                else:
                    raise ValueError(f"cannot read {value!r}")
            except ValueError as err:
                raise ValueError(f"{name}: {err}") from None
            if dist.kind == "scale" and NAMES[str(name)].offset:
                raise ValueError(f"{name} is an offset from the nominal value; scale(a,b) does not apply, "
                                 "give uniform or normal")
            items.append((str(name), dist))
        return cls(tuple(items))

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(name for name, _ in self.items)

    @property
    def fields(self) -> frozenset[str]:
        """The model fields the spec sets."""
        return frozenset(registry.PARAMETERS[name].field for name in self.names if name in registry.PARAMETERS)

    @property
    def controls(self) -> dict[str, Dist]:
        """The controller, motor and sensor parameters it draws (`registry.CONTROL_PARAMETERS`), by name."""
        return {name: dist for name, dist in self.items if name in registry.CONTROL_PARAMETERS}

    @property
    def model(self) -> "Spec":
        """The spec of its model fields alone."""
        return Spec(tuple((name, dist) for name, dist in self.items if name in registry.PARAMETERS))

    def rng(self, seed: int, name: str) -> np.random.Generator:
        """Each parameter draws from its own stream of the seed: adding one leaves the others' draws as they were."""
        return np.random.default_rng([seed, zlib.crc32(name.encode())])

    def __str__(self) -> str:
        return ",".join(f"{name}={dist}" for name, dist in self.items)

    def __bool__(self) -> bool:
        return bool(self.items)


def _unique(items: list[tuple[str, str]]) -> list[tuple[str, str]]:
    seen = [name for name, _ in items]
    twice = sorted({name for name in seen if seen.count(name) > 1})
    if twice:
        raise ValueError(f"{', '.join(twice)} given twice")
    return items
