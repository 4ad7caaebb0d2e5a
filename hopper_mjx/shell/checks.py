"""Argument checks shared by every command: one line on stderr, `error: ...`, exit code 2.

The bottom layer of the command line: values, paths and names are checked here before any
model is built or compiled (and before JAX or MuJoCo is imported); nothing here imports a
module of the package but `registry` and `files`. `ArgumentParser` gives argparse's own refusals the
same one-line form.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

import numpy as np

from hopper_mjx import registry
from hopper_mjx.shell.files import OutputError, is_device  # noqa: F401 (OutputError: the checks' name too)

MAX_TIMESTEP = 0.01  # s, the longest physics step model.load and a world file may set
DEFAULT_TIMESTEP = 1e-3  # s, model.DEFAULT_TIMESTEP (checked equal by a test; importing model loads MuJoCo)


PLOT_SUFFIXES = (".png", ".pdf", ".svg")  # what a plot is saved as (matplotlib, by the name's suffix)
SCENARIO_BYTES = 1 << 20  # a scenario file is a page of settings; more is not one
MAX_YAML_VALUES = 100_000  # values a YAML file of settings (a scenario, gains) may expand to


class ArgumentParser(argparse.ArgumentParser):
    """argparse, refusing in one line: `error: <what>` on stderr and exit code 2 (no usage block).

    A parser with a `--scenario FILE.yaml` option takes its options' values from that file too:
    its keys are the options' names (`gravity`, `num`, `controller`, ...), and an option given
    on the command line wins over the file."""

    def error(self, message: str):
        # argparse puts "argument --x: " before a type's own message, which names the option already.
        names, sep, rest = message.partition(": ")
        names = names.removeprefix("argument ")
        named = [n for n in names.split("/") if rest.startswith(n + " ")] if sep and message.startswith("argument ") \
            else []
        if named:
            message = names + rest[len(named[0]):]
        if message.startswith("unrecognized arguments: "):
            message += self._suggestion(message.removeprefix("unrecognized arguments: ").split())
        if message.startswith("the following arguments are required: "):  # a subcommand missing: name them
            missing = message.removeprefix("the following arguments are required: ").split(", ")
            message += "".join(f"; {a.dest} is one of {', '.join(a.choices)}" for a in self._actions
                               if isinstance(a, argparse._SubParsersAction) and a.dest in missing)
        self.exit(2, f"error: {message} (see {self.prog} --help)\n")

    def _suggestion(self, unknown: list[str]) -> str:
        """'; did you mean --x?' for the first mistyped option that is close to one this command (or one of its
        subcommands) takes."""
        import difflib

        options = set(self._option_string_actions)
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction):
                for sub in action.choices.values():
                    options |= set(sub._option_string_actions)
        for word in unknown:
            if word.startswith("--"):
                close = difflib.get_close_matches(word.split("=")[0], sorted(options), n=1, cutoff=0.75)
                if close:
                    return f"; did you mean {close[0]}?"
        return ""

    def refuse(self, flag: str, why: str) -> None:
        """An option of a shared set (`cli.add_physics_options`) that this command cannot honour: left out of
        --help, so that the help lists only what the command takes, and refused in one line, `flag: why`,
        when given (on the command line or by a scenario file)."""
        action = self._option_string_actions[flag]
        action.help = argparse.SUPPRESS
        self.refused = {**getattr(self, "refused", {}), action.dest: (flag, action.default, why)}

    def parse_known_args(self, args=None, namespace=None):
        known, rest = super().parse_known_args(args, namespace)
        path = getattr(known, "scenario", None)
        if path is not None and namespace is None:
            try:
                self.set_defaults(**read_scenario(path, self))
            except ValueError as err:
                self.error(str(err))
            known, rest = super().parse_known_args(args, namespace)
        for dest, (flag, default, why) in getattr(self, "refused", {}).items():
            if getattr(known, dest, default) != default:
                self.error(f"{flag}: {why}")
        return known, rest


def read_scenario(path, p: argparse.ArgumentParser) -> dict:
    """The option values a scenario file sets, typed as the command line would type them."""
    import yaml

    path = check_readable_file("--scenario", path)
    with open(path, "rb") as f:
        text = f.read(SCENARIO_BYTES + 1)
    if len(text) > SCENARIO_BYTES:
        raise ValueError(f"--scenario {path}: over {SCENARIO_BYTES // 1024} KiB, not a scenario file")
    try:
        values = load_yaml(text)
    except yaml.YAMLError as err:
        raise ValueError(f"--scenario {path}: not YAML ({str(err).splitlines()[0]})") from None
    if not isinstance(values, dict):
        raise ValueError(f"--scenario {path}: must be a mapping of option names to values")
    actions = {a.dest: a for a in p._actions if a.option_strings and a.dest not in ("help", "scenario")}
    unknown = [str(k) for k in values if str(k).replace("-", "_") not in actions]
    if unknown:
        raise ValueError(f"--scenario {path}: unknown option(s) {', '.join(unknown)}; "
                         f"known: {', '.join(sorted(actions))}")
    typed = {}
    for key, value in values.items():
        action = actions[str(key).replace("-", "_")]
        typed[action.dest] = _typed(action, value, path, key)
    return typed


def load_yaml(text):
    """`yaml.safe_load`, refusing a mapping that gives a key twice (PyYAML would keep the last one silently:
    a joint's gains given twice, an option set twice). Raises yaml.YAMLError."""
    import yaml

    class Loader(yaml.SafeLoader):
        def construct_mapping(self, node, deep=False):
            seen = {}
            for key_node, _ in node.value:
                key = self.construct_object(key_node, deep=True)
                try:
                    hash(key)
                except TypeError:
                    continue  # PyYAML refuses an unhashable key itself
                if key in seen:
                    raise yaml.constructor.ConstructorError(
                        None, None, f"the key {key!r} is given twice (lines {seen[key] + 1} and "
                        f"{key_node.start_mark.line + 1})", key_node.start_mark)
                seen[key] = key_node.start_mark.line
            return super().construct_mapping(node, deep=deep)

    value = yaml.load(text, Loader=Loader)  # aliases share one object: loading never expands them
    count, todo = 0, [value]
    while todo:  # ... but whatever reads the values would ("billion laughs"): counted here, as they would expand
        item = todo.pop()
        count += 1
        if count > MAX_YAML_VALUES:
            raise yaml.YAMLError(f"it expands to over {MAX_YAML_VALUES:,} values (anchors & repeated by aliases * "
                                 "within each other); a settings file holds a few hundred")
        if isinstance(item, dict):
            todo += [*item.keys(), *item.values()]
        elif isinstance(item, list):
            todo += item
    return value


def _typed(action: argparse.Action, value, path, key):
    """A file's value converted as argparse converts the option's text (relative paths: from the file)."""
    convert = action.type or (lambda text: text)
    if isinstance(action, (argparse._StoreTrueAction, argparse._StoreFalseAction)):
        if not isinstance(value, bool):
            raise ValueError(f"--scenario {path}: {key} must be true or false, got {value!r}")
        return value
    if isinstance(value, dict):  # a block of NAME: VALUE lines (randomize:), as the option's NAME=VALUE,...
        value = ",".join(f"{k}={v}" for k, v in value.items())
    try:
        if action.nargs in ("+", "*"):
            items = value if isinstance(value, list) else [value]
            return [convert(_relative(path, str(v), action)) for v in items]
        text = ",".join(map(str, value)) if isinstance(value, list) else _relative(path, str(value), action)
        return convert(text)
    except (ValueError, TypeError, argparse.ArgumentTypeError) as err:
        raise ValueError(f"--scenario {path}: {key}: {err}") from None


def _relative(path: Path, text: str, action: argparse.Action) -> str:
    """Paths in a scenario file are read from the file's folder (urdf, world, gains, a heightmap's PNG)."""
    if action.dest in ("urdf", "world", "gains") and not Path(text).is_absolute():
        return str(Path(path).parent / text)
    name, _, rest = text.partition(":")
    if action.dest == "terrain" and name.strip() == "heightmap" and rest:
        first, *others = rest.split(",")
        if "=" not in first and not Path(first.strip()).is_absolute():
            return ",".join([f"{name}:{Path(path).parent / first.strip()}", *others])
    return text


def parser(prog: str, doc: str | None) -> ArgumentParser:
    return ArgumentParser(prog=prog, description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)


def parse_floats(text: str, what: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{what} must be comma-separated numbers, got {text!r}") from None
    if not values:
        raise argparse.ArgumentTypeError(f"{what} is empty")
    return values


def floats(what: str):
    """An argparse `type` for a comma-separated list of numbers."""
    return lambda text: parse_floats(text, what)


def parse_scan(text: str) -> tuple[tuple[int, int], tuple[float, float]]:
    """--scan NXxNY,SPACING (or ,DXxDY): the height scan's point counts (ahead, left) and spacing, m."""
    counts, _, spacing = text.partition(",")
    try:
        n = tuple(int(c) for c in counts.lower().split("x"))
        d = tuple(float(v) for v in spacing.lower().split("x"))
    except ValueError:
        raise ValueError(f"--scan {text!r} must be NXxNY,SPACING (e.g. 5x5,0.1 or 7x3,0.1x0.05)") from None
    d = d * 2 if len(d) == 1 else d
    if len(n) != 2 or len(d) != 2 or not all(1 <= c <= 64 for c in n):
        raise ValueError(f"--scan {text!r} must be NXxNY,SPACING with 1..64 points per axis")
    if not all(math.isfinite(v) and v > 0 for v in d):
        raise ValueError(f"--scan {text!r}: the spacing must be > 0 m")
    return n, d


def parse_indices(text: str, what: str = "--instances") -> list[int]:
    try:
        return [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{what} must be comma-separated integers, got {text!r}") from None


def check_range(name: str, value: float, *, low: float | None = None, high: float | None = None,
                open_low: bool = False) -> None:
    """`value` finite and within [low, high] (or (low, high] with `open_low`)."""
    too_low = low is not None and (value <= low if open_low else value < low)
    if not math.isfinite(value) or too_low or (high is not None and value > high):
        lower = "" if low is None else f"{'>' if open_low else '>='} {low:g}"
        upper = "" if high is None else f"<= {high:g}"
        bounds = " and ".join(b for b in (lower, upper) if b)
        raise ValueError(f"{name} must be finite{' and ' + bounds if bounds else ''}, got {value:g}")


def check_writable(name: str, path: str | Path, *, folder: bool = False, may_exist: bool = True,
                   make_parents: bool = False, suffixes: tuple[str, ...] = ()) -> Path:
    """An output path that can be written, checked without leaving anything: its parent exists and is a
    folder (with `make_parents`, its nearest existing ancestor) that takes a new file; a file output is not a
    folder (a folder output not a file); with `may_exist` False it must be new; with `suffixes`, a file's name
    ends in one of them (the formats the tool writes; a device such as /dev/null is taken as it is)."""
    path = Path(path)
    try:
        return _check_writable(name, path, folder, may_exist, make_parents, suffixes)
    except OSError as err:  # a name the file system cannot hold (ENAMETOOLONG), a loop of links, ...
        raise ValueError(f"{name} {path}: {err.strerror or err}") from None


def _check_writable(name: str, path: Path, folder: bool, may_exist: bool, make_parents: bool,
                    suffixes: tuple[str, ...]) -> Path:
    parent = path.parent
    while make_parents and not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        why = "does not exist" if not parent.exists() else "is not a folder"
        raise ValueError(f"{name} {path}: its folder {parent} {why}")
    if path.exists() and not may_exist:
        raise ValueError(f"{name} {path} exists; remove it or choose another")
    if path.exists() and path.is_dir() != folder:
        wanted, found = ("folder", "file") if folder else ("file", "folder")
        raise ValueError(f"{name} {path} is a {found}; give a {wanted}")
    if suffixes and not is_device(path) and path.suffix.lower() not in suffixes:
        shown = [s for s in suffixes if s]  # "": a name without a suffix is written as given
        raise ValueError(f"{name} {path}: this tool writes {' or '.join(shown)} files; give a name ending in "
                         f"{shown[0]}")
    if not os.access(parent, os.W_OK) or not (is_device(path) or _takes_files(parent)):
        raise ValueError(f"{name} {path}: cannot write in {parent}")
    return path


def _takes_files(folder: Path) -> bool:
    """Whether a file can be made in `folder`, tried with a nameless one that is gone when closed. Root passes
    `os.access` on a pseudo-filesystem such as /proc, where no file can be made: the run would end in a traceback
    when it writes its output."""
    import tempfile

    try:
        with tempfile.TemporaryFile(dir=folder):
            return True
    except OSError:
        return False


def make_folder(name: str, path: str | Path) -> Path:
    """Creates the output folder `path` (and its parents); a path the checks let through but the system
    refuses (a pseudo-filesystem such as /proc, where root passes `os.access`) is one line, not a traceback."""
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise OutputError(f"{name} {path}: cannot create it ({err.strerror or err})") from None
    return path


def check_readable_file(name: str, path: str | Path) -> Path:
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{name} {path}: {'is a folder, not a file' if path.is_dir() else 'no such file'}")
    return path


def check_indices(name: str, indices, n: int) -> None:
    """Instance indices of a batch of n: within 0..n-1, none twice, at least one."""
    indices = list(indices)
    if not indices:
        raise ValueError(f"{name}: no instance given")
    bad = [i for i in indices if not 0 <= i < n]
    if bad:
        raise ValueError(f"{name} {bad} out of range: the batch has {n} instance(s), 0..{n - 1}")
    if len(set(indices)) != len(indices):
        raise ValueError(f"{name} lists an instance twice: {indices}")


def fail(err: Exception | str) -> int:
    text = str(err)
    flag, sep, rest = text.partition(": ")
    if sep and flag.startswith("-") and rest.startswith(flag + " "):  # a wrapper naming the option its message names
        text = rest
    print(f"error: {text}", file=sys.stderr)
    return 2


def counted(n: int, noun: str) -> str:
    """'1 instance', '3 instances': a count and its noun in the number it takes."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


def say(*notes: str | None) -> None:
    """Prints each note a check returned (None: nothing to say), at once: the compile that follows takes seconds."""
    for note in notes:
        if note:
            print(note, flush=True)


def warn_diverged(diverged) -> None:
    bad = np.flatnonzero(diverged)
    if bad.size:
        print(f"warning: {bad.size} instance(s) diverged and were frozen: {bad[:20].tolist()}", file=sys.stderr)


MAX_SEED = 2**32 - 1  # JAX's PRNG keys take 32-bit seeds


def check_seed(seed: int) -> None:
    if not 0 <= seed <= MAX_SEED:
        raise ValueError(f"--seed must be in 0..{MAX_SEED}, got {seed}")


def check_engine(name: str) -> None:
    try:
        registry.check("engine", registry.ENGINES, name)
    except ValueError as err:
        raise ValueError(f"--engine: {err}") from None
