"""One name per option across every command, and no command lists an option it refuses.

Every command's parser is read in-process (no subprocess, no JAX): `main` is called with `parse_args` replaced
by a capture, so a command that builds its parser inside `main` is covered too. The commands are found from the
source as tests/test_help.py finds them, so a new one is covered as well.

A quantity's name is its parser destination (`args.gravity`): the option that stores it must be spelled after it
(`--gravity`), an older name allowed beside it as an alias of the same option (`sweep gravity --values`); and one
option name stores one quantity in every command."""

import argparse
import importlib
import importlib.util
from pathlib import Path

import pytest
from test_help import ROOT, commands

# Options named otherwise than their destination, on purpose: `rostopic echo`'s own -n.
NAMED_OTHERWISE = {"count": "-n"}


# One value per shared physics option, each one a sweep of every kind takes unless its parser refuses the option.
SAMPLES = {"--terrain": "rough:amp=0.01,seed=1", "--motor": "dc", "--action-delay": "1", "--push": "1,0.1",
           "--randomize": "foot_friction=0.5..1.0", "--engine": "mjx"}
REQUIRED = {"gains": ["--param", "speed_gain", "--values", "0.1,0.2"],
            "param": ["--param", "speed_gain", "--values", "0.1,0.2"], "compare": ["--controllers", "raibert,balance"]}


class Captured(Exception):
    def __init__(self, parser):
        self.parser = parser


def _main(command: list[str]):
    if command[0] == "-m":  # a package runs its __main__
        module = importlib.import_module(command[1])
        return getattr(module, "main", None) or importlib.import_module(command[1] + ".__main__").main
    spec = importlib.util.spec_from_file_location(Path(command[0]).stem, command[0])
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.main


def _parser_of(command: list[str], monkeypatch) -> argparse.ArgumentParser:
    def capture(self, args=None, namespace=None):
        raise Captured(self)

    with monkeypatch.context() as patch:
        patch.setattr(argparse.ArgumentParser, "parse_args", capture)
        try:
            _main(command)([])
        except Captured as found:
            return found.parser
    raise AssertionError(f"{command} parsed no arguments")


@pytest.fixture(scope="module")
def parsers() -> dict[str, argparse.ArgumentParser]:
    """Every command's parser, and each subcommand's ("-m hopper_mjx.sweep gravity"), by name."""
    out = {}
    with pytest.MonkeyPatch.context() as monkeypatch:
        for command in commands():
            name = " ".join(command).replace(str(ROOT) + "/", "")
            p = out[name] = _parser_of(command, monkeypatch)
            for action in p._actions:
                if isinstance(action, argparse._SubParsersAction):
                    out.update({f"{name} {kind}": sub for kind, sub in action.choices.items()})
    return out


def _options(p: argparse.ArgumentParser, *, listed: bool = True):
    return [a for a in p._actions if a.option_strings and a.dest != "help"
            and (a.help != argparse.SUPPRESS) == listed]


def test_every_command_and_subcommand_is_read(parsers):
    for name in ("-m hopper_mjx.sweep gravity", "-m hopper_mjx.sweep obstacle", "-m hopper_mjx.model",
                 "-m hopper_mjx.perf.profile", "experiments/train.py", "experiments/leg_energy.py"):
        assert name in parsers
    assert sum(len(_options(p)) for p in parsers.values()) > 200


def test_an_option_is_named_for_the_quantity_it_stores(parsers):
    """`sweep gravity --values` once stored gravities where every other command takes --gravity: an option
    storing a quantity without that quantity's name fails here, unless the name is an alias beside it."""
    wrong = [f"{name}: {'/'.join(a.option_strings)} stores {a.dest}"
             for name, p in parsers.items() for a in _options(p)
             if NAMED_OTHERWISE.get(a.dest, "--" + a.dest.replace("_", "-")) not in a.option_strings]
    assert not wrong, "\n".join(wrong)


def test_one_name_stores_one_quantity_everywhere(parsers):
    stores: dict[str, dict[str, list[str]]] = {}
    for name, p in parsers.items():
        for a in _options(p):
            canonical = NAMED_OTHERWISE.get(a.dest, "--" + a.dest.replace("_", "-"))
            stores.setdefault(canonical, {}).setdefault(a.dest, []).append(name)
    assert not {k: v for k, v in stores.items() if len(v) > 1}
    # An alias stands for its option in the one command: never a quantity's name of its own there.
    for name, p in parsers.items():
        for a in _options(p):
            for alias in set(a.option_strings) - {NAMED_OTHERWISE.get(a.dest, "--" + a.dest.replace("_", "-"))}:
                assert p._option_string_actions[alias] is a, f"{name}: {alias}"


def test_an_old_name_still_works_beside_the_new(parsers):
    for name, extra in (("gravity", []), ("compare", ["--controllers", "raibert"])):
        p = parsers[f"-m hopper_mjx.sweep {name}"]
        assert p.parse_args(["--values", "9.81,1.62", *extra]).gravity \
            == p.parse_args(["--gravity", "9.81,1.62", *extra]).gravity == [9.81, 1.62]


def test_no_command_lists_an_option_it_refuses(parsers, capsys):
    """An option of a shared set a command cannot honour is hidden from its --help and refused in one line
    naming it; and every hidden option is such a refusal (or argparse's own --help)."""
    refusing = {name: p for name, p in parsers.items() if getattr(p, "refused", None)}
    assert {"-m hopper_mjx.sweep obstacle", "-m hopper_mjx.sweep gaps", "-m hopper_mjx.sweep terrain",
            "-m hopper_mjx.sweep param",
            "-m hopper_mjx.perf.bench"} <= set(refusing)
    for name, p in parsers.items():
        text = p.format_help()
        refused = getattr(p, "refused", {})
        assert {a.dest for a in _options(p, listed=False)} == set(refused), name
        for dest, (flag, default, why) in refused.items():
            assert f"{flag} " not in text and f"{flag}\n" not in text, f"{name} lists {flag}"
            required = [w for a in p._actions if a.required and a.option_strings for w in (a.option_strings[0], "1")]
            assert SAMPLES[flag] != default
            with pytest.raises(SystemExit) as exit_:
                p.parse_args([*required, flag, SAMPLES[flag]])
            assert exit_.value.code == 2
            err = capsys.readouterr().err
            assert err.startswith(f"error: {flag}: ") and err.count("\n") == 1, err


@pytest.mark.parametrize("kind", ["gravity", "gains", "param", "compare", "obstacle", "gaps", "terrain"])
def test_a_sweep_takes_every_physics_option_it_lists(parsers, kind, tmp_path):
    """The whole check (as the command runs it, no JAX) accepts each listed physics option: a refusal there
    would be an option listed, then refused."""
    from hopper_mjx.sweep import __main__ as sweep

    p = parsers[f"-m hopper_mjx.sweep {kind}"]
    listed = {s for a in _options(p) for s in a.option_strings}
    taken = [flag for flag in SAMPLES if flag in listed]
    assert len(taken) >= 5
    for flag in taken:
        args = sweep.parser().parse_args([kind, *REQUIRED.get(kind, []), flag, SAMPLES[flag], "--num", "2",
                                          "--duration", "1", "--out", str(tmp_path / "out")])
        sweep.check(args)  # raises ValueError on a refusal


def test_an_error_names_the_option_once(parsers, capsys):
    """argparse's "argument --values: --values must be ..." and a check's "--values: --values must ..." say the
    option once; an alias's type error names both of its names."""
    from hopper_mjx.shell import checks

    with pytest.raises(SystemExit):
        parsers["-m hopper_mjx.sweep param"].parse_args(["--param", "kp_scale", "--values", "1,y"])
    assert capsys.readouterr().err.startswith("error: --values must be comma-separated numbers, got '1,y' (see ")
    with pytest.raises(SystemExit):
        parsers["-m hopper_mjx.sweep gravity"].parse_args(["--values", "1,y"])
    assert capsys.readouterr().err.startswith("error: --gravity/--values must be comma-separated numbers")
    assert checks.fail(ValueError("--values: --values must be one or more finite numbers")) == 2
    assert capsys.readouterr().err == "error: --values must be one or more finite numbers\n"
    checks.fail(ValueError("--values: kp_scale drew a value of -1"))
    assert capsys.readouterr().err == "error: --values: kp_scale drew a value of -1\n"


def test_a_mistyped_option_is_answered_with_the_closest_one_the_command_takes(parsers, capsys):
    """Every command: an option one letter off from one it takes is named back ("did you mean"); a word like
    no option gets the plain refusal. Parsed whole: the top-level sweep parser knows its subcommands' options."""
    for name, p in parsers.items():
        flags = sorted(f for f in p._option_string_actions if f.startswith("--") and len(f) > 6 and f != "--help")
        if not flags:
            continue
        typo = flags[0][:-2] + flags[0][-1]  # its last but one letter dropped
        with pytest.raises(SystemExit):  # argparse's own words (a command's required options would come first)
            p.error(f"unrecognized arguments: {typo}")
        err = capsys.readouterr().err
        assert err.startswith(f"error: unrecognized arguments: {typo}; did you mean --"), (name, err)
        assert len(err.splitlines()) == 1
    with pytest.raises(SystemExit):
        parsers["-m hopper_mjx.sweep"].parse_args(["gravity", "--gravty", "9.81"])
    assert "; did you mean --gravity?" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        parsers["-m hopper_mjx.simulate"].parse_args(["--zzzzzz"])
    assert capsys.readouterr().err.startswith("error: unrecognized arguments: --zzzzzz (see ")


def test_a_count_takes_its_nouns_number():
    """One robot's run said '1 instances x 500 steps on 2 device(s)', and a sweep of --num 1 '1 replicates per g'."""
    from hopper_mjx import cli

    assert cli.counted(1, "instance") == "1 instance"
    assert cli.counted(2, "device") == "2 devices" and cli.counted(0, "replicate") == "0 replicates"
