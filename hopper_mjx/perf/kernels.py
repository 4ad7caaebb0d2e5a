"""How many kernels one batched step launches: counted from the compiled program, not timed.

XLA:CPU runs a compiled program as a sequence of kernels (its "thunks"): each fusion, copy, sort,
custom call and un-fused operation of the program's top-level computations is one launch, with a
fixed cost of its own (docs/performance.md). Parameters, constants, tuples and their elements, and
bitcasts launch nothing; a fusion's inner operations are inside its one kernel. A conditional
runs one branch: the count takes its larger one among those that compute, leaving out a branch
that only copies or broadcasts (a stored stage's zeros, `chain.stage.stored`, which never run and
take a copy per output, more than the stage's own few kernels; or a state held as it is) unless
every branch does. A while loop's body and condition are counted once: one pass through the step,
where the Newton solve and the line search may run several.

    kernels.count(jax.jit(step).lower(*args).compile().as_text())
"""

from __future__ import annotations

import re

ONLY_MOVES = frozenset({"copy", "broadcast"})  # a branch of these computes nothing (the docstring)
NO_KERNEL = frozenset({"parameter", "constant", "get-tuple-element", "tuple", "bitcast", "after-all", "opt-barrier"})
# A computation's header ("%name (params) -> type {", "ENTRY %name ... {") and an instruction
# ("%x = type op(operands), attributes"; the type may be a tuple with spaces in it).
_HEAD = re.compile(r"^(ENTRY\s+)?%?([\w.\-]+)\s.*\{\s*$")
_INSTRUCTION = re.compile(r"^\s*(?:ROOT\s+)?%?[\w.\-]+ = .*? ([a-z][a-z0-9\-]*)\((.*)$")


def _computations(hlo: str) -> tuple[dict[str, list[tuple[str, str]]], str]:
    """{computation: [(opcode, the rest of its line)]} of an HLO module's text, and the entry's name."""
    found: dict[str, list[tuple[str, str]]] = {}
    entry = current = None
    for line in hlo.splitlines():
        if current is None:
            head = _HEAD.match(line)
            if head and "=" not in line.split("(")[0]:
                current = head.group(2)
                found[current] = []
                entry = current if head.group(1) else entry
        elif line.strip() == "}":
            current = None
        elif (inst := _INSTRUCTION.match(line)) is not None:
            found[current].append((inst.group(1), inst.group(2)))
    if entry is None:
        raise ValueError("not an HLO module's text: no ENTRY computation")
    return found, entry


def _called(attribute: str, rest: str) -> list[str]:
    """The computations an instruction names in `attribute` (one name, or a {list})."""
    m = re.search(attribute + r"=(\{[^}]*\}|[^,\s]+)", rest)
    return [] if m is None else [name.strip().lstrip("%") for name in m.group(1).strip("{}").split(",")]


def count(hlo: str) -> int:
    """Kernels one pass through the compiled program `hlo` (its `as_text()`) launches (the module's docstring)."""
    computations, entry = _computations(hlo)
    memo: dict[str, int] = {}

    def moves_only(name: str) -> bool:
        return all(op in ONLY_MOVES or op in NO_KERNEL for op, _ in computations[name])

    def launches(name: str) -> int:
        if name not in memo:
            total = 0
            for op, rest in computations[name]:
                if op in NO_KERNEL:
                    continue
                if op == "while":
                    total += 1 + sum(launches(c) for c in _called("body", rest) + _called("condition", rest))
                elif op == "conditional":
                    branches = (_called("branch_computations", rest)
                                or _called("true_computation", rest) + _called("false_computation", rest))
                    computing = [c for c in branches if not moves_only(c)] or branches
                    total += 1 + max(launches(c) for c in computing)
                elif op == "call":
                    total += sum(launches(c) for c in _called("to_apply", rest))
                else:
                    total += 1
            memo[name] = total
        return memo[name]

    return launches(entry)


def equations(engine, data, gravity) -> dict[str, int]:
    """The jaxpr equations of one step, traced as `per_step` compiles it, by the engine function that wrote each
    (`module.function`, the innermost frame in `hopper_mjx/engine/` other than its algebra and its stage wrapper;
    "other" outside the engine), the programs nested in conditionals and loops counted once each. The step's size
    before XLA: tracing, lowering and compiling it grow with it (docs/performance.md)."""
    import collections

    import jax

    counts: collections.Counter = collections.Counter()

    def walk(jaxpr):
        for eqn in jaxpr.eqns:
            counts[_writer(eqn)] += 1
            for param in eqn.params.values():
                for sub in param if isinstance(param, (tuple, list)) else (param,):
                    if hasattr(sub, "eqns"):
                        walk(sub)
                    elif hasattr(sub, "jaxpr") and hasattr(sub.jaxpr, "eqns"):  # a closed jaxpr
                        walk(sub.jaxpr)

    walk(jax.make_jaxpr(_batched_step(engine))(engine.model, data, gravity).jaxpr)
    return dict(counts.most_common())


def _writer(eqn) -> str:
    frames = eqn.source_info.traceback.frames if eqn.source_info.traceback is not None else []
    for frame in frames:  # innermost first
        path = frame.file_name.replace("\\", "/")
        if "/hopper_mjx/engine/" in path and not path.endswith(("/algebra.py", "/stage.py")):
            module = path.rsplit("/", 1)[1].removesuffix(".py")
            module = path.rsplit("/", 2)[1] if module == "__init__" else module
            return f"{module}.{frame.function_name.split('.')[0]}"
    return "other"  # no engine frame: JAX's own, such as a batched conditional's selects


def _batched_step(engine):
    """One step (forward, then integrate) vmapped over the instances, the model an argument, as the core runs it."""
    import jax

    from hopper_mjx.engine import BATCH_AXIS

    def step(m, d, g):
        return engine.integrate(m, engine.forward(m, d, g), g)

    return jax.vmap(step, in_axes=(None, 0, 0), axis_name=BATCH_AXIS)


def per_step(engine, data, gravity) -> int:
    """Kernels of one step (forward, then integrate) of `engine` over the batch `data` ((N, ...) leaves; its
    gravity (N, 3)), compiled as the core compiles its step: vmapped over the instances, the model an argument,
    the engine's XLA:CPU options."""
    import jax

    batched = jax.jit(_batched_step(engine), compiler_options=engine.compiler_options)
    return count(batched.lower(engine.model, data, gravity).compile().as_text())
