"""The package's imports run one way: each layer imports only layers below it, and no modules form a cycle.

Pure Python (the standard library's `ast`): every `import` in hopper_mjx/ and
experiments/, at module level or inside a function, counts.
"""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "hopper_mjx"
# Bottom to top, as the data flows: description -> compiled model -> engine -> signals ->
# controllers -> metrics -> the batched core -> environments -> command-line support -> live runs
# and ROS I/O -> tools.
LAYERS = (
    ("registry",),  # the names a user types
    ("shell",),  # the process around a command: argument checks, start-up, the runner, files, sizes, JAX settings
    ("terrain",),  # height grids, their spec and their MuJoCo hfield; the height scan
    ("model",),
    ("variation",),  # the --randomize spec and its draw into model fields
    ("engine",),
    ("hardware",),  # what the sensors read and add, what the motors make of a command, pushes
    ("control",),
    ("metrics",),  # hop metrics; each task's bar on them, and the ranking of checkpoints
    ("step",),  # the one physics step after a controller's output: the core's and the training env's
    ("sim",),
    ("envs",),
    ("scenario",),  # the typed description of a batch, built once: robot, worlds, engine, controller
    ("__init__",),  # the package's public surface
    ("cli",),
    ("live", "ros"),  # live runs of the batch, ROS messages and streams: used by several tools
)
# Tools sit on top and may not import one another; a part not listed above is a tool.
# The experiments (training scripts) sit above the tools and may use them.
TOOL_LAYER = len(LAYERS)
EXPERIMENTS = "experiments"


def layer_of(part: str) -> int:
    if part == EXPERIMENTS:
        return TOOL_LAYER + 1
    return next((i for i, parts in enumerate(LAYERS) if part in parts), TOOL_LAYER)


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__" and len(parts) > 1:
        parts.pop()
    return ".".join(parts)


def sources() -> dict[str, Path]:
    files = sorted((ROOT / PACKAGE).rglob("*.py")) + sorted((ROOT / "experiments").rglob("*.py"))
    return {module_name(p): p for p in files}


def imported(path: Path, modules: set[str]) -> list[tuple[int, str]]:
    """(line, module) of every import of a module of ours, resolved to the most specific module."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names if a.name.split(".")[0] == PACKAGE]
        elif isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == PACKAGE:
            for alias in node.names:
                sub = f"{node.module}.{alias.name}"
                out.append((node.lineno, sub if sub in modules else node.module))
    return out


def part_of(module: str) -> str:
    """The top-level part of the package a module belongs to ("__init__" for the package itself)."""
    if module == PACKAGE:
        return "__init__"
    head, _, rest = module.partition(".")
    return rest.split(".")[0] if head == PACKAGE else head


def upstream_imports(graph: dict[str, list[tuple[int, str]]], files: dict[str, Path]) -> list[str]:
    problems = []
    for module, targets in graph.items():
        here = part_of(module)
        for line, target in targets:
            there = part_of(target)
            if there == here:
                continue
            layer = layer_of(here)
            if layer_of(there) >= layer:
                problems.append(f"{files[module].relative_to(ROOT)}:{line}: {here} (layer {layer}) "
                                f"imports {there} (layer {layer_of(there)}), which is not below it")
    return problems


def cycles(graph: dict[str, list[tuple[int, str]]]) -> list[str]:
    """One cycle per strongly connected group of modules that import one another."""
    found, state = [], {}

    def visit(module, stack):
        state[module] = "open"
        stack.append(module)
        for _, target in graph.get(module, ()):
            if state.get(target) == "open":
                found.append(" -> ".join(stack[stack.index(target):] + [target]))
            elif target not in state:
                visit(target, stack)
        stack.pop()
        state[module] = "done"

    for module in sorted(graph):
        if module not in state:
            visit(module, [])
    return found


def import_graph():
    files = sources()
    return {m: imported(p, set(files)) for m, p in files.items()}, files


def test_no_module_imports_from_a_layer_above_it():
    graph, files = import_graph()
    assert len(graph) > 30  # the package and the experiments were found
    problems = upstream_imports(graph, files)
    assert not problems, "upstream imports:\n" + "\n".join(problems)


def test_no_import_cycles():
    graph, _ = import_graph()
    found = cycles({m: [(line, t) for line, t in targets if t != m] for m, targets in graph.items()})
    assert not found, "import cycles:\n" + "\n".join(found)


def test_the_check_sees_an_upstream_import_and_a_cycle():
    """The checker itself: a controller importing the core, and two modules importing each other."""
    files = {"hopper_mjx.control.raibert": ROOT / "hopper_mjx/control/raibert.py",
             "hopper_mjx.sim": ROOT / "hopper_mjx/sim.py"}
    graph = {"hopper_mjx.control.raibert": [(1, "hopper_mjx.sim")],
             "hopper_mjx.sim": [(2, "hopper_mjx.control.raibert")]}
    assert upstream_imports(graph, files) == [
        f"hopper_mjx/control/raibert.py:1: control (layer {layer_of('control')}) imports sim "
        f"(layer {layer_of('sim')}), which is not below it"]
    # A command's `__main__` is not exempt: the model's command importing the command line is refused.
    main = {"hopper_mjx.model.__main__": ROOT / "hopper_mjx/model/__main__.py"}
    assert upstream_imports({"hopper_mjx.model.__main__": [(3, "hopper_mjx.cli")]}, main) == [
        f"hopper_mjx/model/__main__.py:3: model (layer {layer_of('model')}) imports cli (layer {layer_of('cli')}), "
        "which is not below it"]
    assert cycles(graph) == ["hopper_mjx.control.raibert -> hopper_mjx.sim -> hopper_mjx.control.raibert"]
    assert layer_of("view") == layer_of("simulate") == layer_of("perf") == TOOL_LAYER
    assert layer_of("cli") < layer_of("ros") == layer_of("live") < TOOL_LAYER


MAX_TOP_LEVEL = 12  # modules directly in hopper_mjx/: the entry points, the core and the registry
MAX_LINES = 600  # one idea per file


def test_the_top_level_holds_few_modules_and_no_file_holds_several_ideas():
    top = sorted(p.name for p in (ROOT / PACKAGE).glob("*.py"))
    assert len(top) <= MAX_TOP_LEVEL, f"{len(top)} modules at hopper_mjx/'s top level: {top}"
    long = {str(p.relative_to(ROOT)): n for p in sources().values()
            if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert not long, f"files over {MAX_LINES} lines: {long}"


def test_only_the_engines_know_how_a_model_holds_its_ground():
    """The core never asks which engine it drives, and a model's heights are decoded in one place
    (`terrain.hfield`): any other reader of MuJoCo's hfield arrays would be a second decoder."""
    sim = (ROOT / PACKAGE / "sim.py").read_text()
    assert "engine.name" not in sim
    readers = sorted(str(p.relative_to(ROOT)) for p in sources().values() if "hfield_data[" in p.read_text())
    assert readers == ["hopper_mjx/terrain/hfield.py"], readers
