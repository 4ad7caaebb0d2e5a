"""Store a stage's outputs once: `stored(gate, fn, *args)`.

XLA:CPU fusion recomputes a shared subexpression inside every fused consumer (the chain's
sines and cosines were evaluated over a hundred times per step). A `lax.cond` whose
predicate is only known at run time (`gate`, a boolean of the engine's model pytree, true
in practice) is a boundary fusion cannot cross, so the stage's outputs are computed once
and stored. `optimization_barrier` would say the same but XLA:CPU drops it before fusion.

Constant leaves (Python floats: the model numbers the algebra folds) pass around the
conditional untouched, so folding keeps working across stages.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from hopper_mjx.engine.chain.algebra import is_const


def stored(gate: jax.Array, fn, *args):
    """fn(*args), with its traced outputs materialised behind a run-time true conditional."""
    arg_leaves, arg_tree = jax.tree_util.tree_flatten(args)
    traced_at = [i for i, x in enumerate(arg_leaves) if not is_const(x)]
    box = {}

    def run(traced):
        leaves = list(arg_leaves)
        for i, x in zip(traced_at, traced):
            leaves[i] = x
        out_leaves, box["tree"] = jax.tree_util.tree_flatten(fn(*jax.tree_util.tree_unflatten(arg_tree, leaves)))
        box["leaves"] = out_leaves
        return [x for x in out_leaves if not is_const(x)]

    traced_in = [jnp.asarray(arg_leaves[i]) for i in traced_at]
    # Trace the Python once (for the outputs' shapes); the conditional's branch calls the same jit, whose trace
    # is cached. As a nested jit, vmap batches the stage once, where a plain branch is batched twice (JAX's
    # cond rule batches each branch once to learn which outputs are batched, then again to batch them).
    stage = jax.jit(run)
    shapes = stage.trace(traced_in).out_info
    zeros = lambda _: [jnp.zeros(s.shape, s.dtype) for s in shapes]
    outs = iter(jax.lax.cond(gate, stage, zeros, traced_in))
    leaves = [x if is_const(x) else next(outs) for x in box["leaves"]]
    return jax.tree_util.tree_unflatten(box["tree"], leaves)


# The name the core gives its vmap over instances (`jax.vmap(..., axis_name=BATCH_AXIS)`).
BATCH_AXIS = "instances"


def batch_any(flag: jax.Array) -> jax.Array:
    """Whether `flag` holds for any instance of the vmapped batch (unbatched, so a `lax.cond` on it stays a
    conditional and a stage few instances need is skipped for the whole chunk); the flag itself outside it."""
    try:
        return jax.lax.pmax(flag.astype(jnp.int32), BATCH_AXIS) > 0
    except NameError:  # not under the core's vmap: per instance (a select under another vmap)
        return flag
