"""The README's tour, command by command, as a new user runs it: each keeps its robots up, or its own output says
why not (a delay past what Raibert takes, an obstacle no robot reached).

The commands are read from README.md, so a line added there is covered (or fails here until it is). Every line
must parse as written: an option renamed or refused fails. The sweeps, `simulate` and `model` then run scaled down
(fewer robots, 1-2 s instead of 10-20) but otherwise as written, in this process (one JAX runtime, one compile
cache), in a temporary folder. Lines whose run a test elsewhere makes end to end, or that cannot run in a test,
say which or why (`ELSEWHERE`): a compile costs 15-30 s, and the suite's time matters.
"""

import json
import re
import shlex
from pathlib import Path

import pytest
from test_options import _main, _parser_of

ROOT = Path(__file__).resolve().parents[1]
# How a tour line's values shrink for a test: replaced where given, added where the command takes them. Every sweep
# runs chunks of 16 and 2 s, and both simulate lines 3 robots for 1 s, so that equal physics compile once.
SCALED = {
    "hopper_mjx.sweep": {"--num": "6", "--duration": "2", "--chunk": "16"},
    "hopper_mjx.simulate": {"--num": "1", "--duration": "1"},
}
ELSEWHERE = {
    "hopper_mjx.view": "opens MuJoCo's viewer window: tests/test_live.py drives it under Xvfb with key presses",
    "experiments/train.py": "a PPO run compiles for minutes: tests/test_train.py trains each task end to end at test "
                            "sizes",
    "hopper_mjx.render": "runs in a fresh process (MuJoCo picks its GL backend once): tests/test_render.py runs "
                         "render --video headless, end to end, and checks its frames",
    "hopper_mjx.ros.record": "tests/test_record.py records a batch into ROS 1 and ROS 2 bags and reads them back",
    "hopper_mjx.perf.bench": "tests/test_bench.py runs the bench's main at test sizes",
    "experiments/export_onnx.py": "needs a trained policy: tests/test_export_onnx.py exports a PPO and a SAC policy "
                                  "and checks ONNX Runtime's actions against the core's on rollouts",
}
# The tour's trained policy does not exist in a test (tests/test_policy.py compares one it trains): the comparison
# runs Raibert alone, through the same path (a folder per controller, one table). `balance` would fall: docs/control.md.
REPLACED = {"raibert,policy:runs/hop-ppo": "raibert"}
# The tour's `--scenario moon.yaml`, as a user writes it: 3 robots, as the other simulate line's.
MOON = "gravity: [1.62]\ncontroller: raibert\nnum: 3\n"


def tour() -> list[list[str]]:
    """The README's tour commands, as words (comments dropped)."""
    text = (ROOT / "README.md").read_text()
    block = re.search(r"## A tour\n\n```bash\n(.*?)```", text, re.S).group(1)
    return [shlex.split(line, comments=True)[1:] for line in block.splitlines() if line.strip()]


def name(words: list[str]) -> str:
    return words[1] if words[0] == "-m" else words[0]


def scaled(words: list[str]) -> list[str]:
    """A tour line's arguments, scaled down by SCALED, with REPLACED's values swapped in."""
    args = words[2 if words[0] == "-m" else 1:]
    for old, new in REPLACED.items():
        args = [w.replace(old, new) for w in args]
    for flag, value in SCALED.get(name(words), {}).items():
        if flag in args:
            args[args.index(flag) + 1] = value
        elif flag != "--num" or "--scenario" not in args:  # a scenario file sets its own size
            args += [flag, value]
    if name(words) == "hopper_mjx.sweep":
        args += ["--no-progress", "--out", f"sweep-{tour().index(words)}"]
    return args


def test_the_tour_is_read_and_every_kind_of_line_is_run_or_says_why_not():
    lines = tour()
    assert len(lines) >= 16
    for words in lines:
        assert name(words) in SCALED or name(words) in ELSEWHERE or name(words) == "hopper_mjx.model", words


@pytest.mark.parametrize("words", tour(), ids=lambda w: " ".join(w)[:60])
def test_every_tour_line_parses_as_written(words, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "moon.yaml").write_text(MOON)
    parser = _parser_of(words[:2] if words[0] == "-m" else [str(ROOT / words[0])], monkeypatch)
    assert parser.parse_args(words[2 if words[0] == "-m" else 1:]) is not None


def _sweep_says_why(folder: Path, out: str) -> None:
    """Every grid point keeps all up, or a note in the output says why; a block no robot reached is a warning
    (its 'cleared 0 %' means nothing; falls at a block it reached are what an obstacle sweep measures). Read from
    each sweep's summary.json (a comparison: one per controller)."""
    lines = out.splitlines()
    summaries = sorted(folder.rglob("summary.json"))
    assert summaries, out
    for path in summaries:
        summary = json.loads(path.read_text())
        groups = summary["groups"]
        if summary["arguments"]["kind"] != "obstacle" and any(g["survival"] < 1 for g in groups):
            assert any(line.startswith("note: ") and "docs/" in line for line in lines), out
        if any(g.get("reached") == 0 for g in groups):
            assert any(line.startswith("warning: no replicate reached the block") for line in lines), out


@pytest.mark.slow
def test_every_tour_line_runs_scaled_down_and_keeps_its_robots_up_or_says_why(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "moon.yaml").write_text(MOON)
    ran = []
    for words in tour():
        module, args = name(words), scaled(words)
        if module in ELSEWHERE:
            continue
        assert _main(words[:2])(args) == 0, (words, capsys.readouterr().err[-3000:])
        out = capsys.readouterr().out
        ran.append(module)
        if module == "hopper_mjx.sweep":
            _sweep_says_why(tmp_path / args[args.index("--out") + 1], out)
        elif module == "hopper_mjx.simulate":
            assert out.rstrip().endswith("all up to the end"), (words, out)
        else:
            assert out.startswith("wrote m.xml"), (words, out)
    assert ran.count("hopper_mjx.sweep") >= 6 and ran.count("hopper_mjx.simulate") >= 3
