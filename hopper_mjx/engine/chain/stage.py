"""Store a stage's outputs once, in a few kernels: `stored(gate, fn, *args)`.

XLA:CPU fusion recomputes a shared subexpression inside every fused consumer (the chain's
sines and cosines were evaluated over a hundred times per step). A `lax.cond` whose
predicate is only known at run time (`gate`, a boolean of the engine's model pytree, true
in practice) is a boundary fusion cannot cross, so the stage's outputs are computed once
and stored. `optimization_barrier` would say the same but XLA:CPU drops it before fusion.

XLA:CPU then writes each output in a kernel of its own (it has no sibling multi-output
fusion), and a step was over a thousand small kernels, each with a fixed cost. A variadic
reduction is one kernel with many outputs: each output, given a trailing axis of 2 (itself,
then the combiner's identity) and summed over it, comes back unchanged, and XLA fuses the
outputs' computations into that one reduction, a shared subexpression computed once per
element (`one_kernel`; docs/performance.md, lever c31). Up to PER_KERNEL outputs share a
kernel: LLVM vectorises such a kernel over the instances, a larger one it leaves scalar.

Constant leaves (Python floats: the model numbers the algebra folds) pass around the
conditional untouched, so folding keeps working across stages.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from hopper_mjx.engine.chain.algebra import is_const

# Outputs computed by one kernel. The flat step at 256 instances (one device), alternated with the code before:
# 8 a kernel 522 kernels a step and 1.19-1.24 µs an instance-step, 12 482 and 1.10, 16 457 and 1.93 (its largest
# kernels no longer vectorised), one each (as before) 1,120 and 1.61-1.78 (docs/performance.md, c31).
PER_KERNEL = 12


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
        return one_kernel([x for x in out_leaves if not is_const(x)])

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


def _identity(dtype):
    """The element a reduction's combiner leaves every value as it is: -0.0 for floats (-0.0 + x is x, -0.0
    included), 0 for integers, False for booleans (with `or`)."""
    if dtype == jnp.bool_:
        return jnp.array(False)
    return jnp.array(-0.0 if jnp.issubdtype(dtype, jnp.floating) else 0, dtype)


def one_kernel(outputs: list) -> list:
    """`outputs`, each unchanged, computed by one XLA:CPU kernel for each PER_KERNEL of a shape and float precision
    (the integers and booleans of a shape together; the module's docstring)."""
    groups: dict = {}  # a reduction takes operands of one shape and one float precision: integers and booleans apart
    for i, x in enumerate(outputs):
        dtype = jnp.result_type(x)
        groups.setdefault((jnp.shape(x), dtype if jnp.issubdtype(dtype, jnp.floating) else None), []).append(i)
    packed = list(outputs)
    for (shape, _), members in groups.items():
        for start in range(0, len(members), PER_KERNEL):
            some = members[start:start + PER_KERNEL]
            if len(some) > 1:
                for i, y in zip(some, _through_one_reduction([outputs[i] for i in some], shape)):
                    packed[i] = y
    return packed


@functools.partial(jax.custom_jvp, nondiff_argnums=(1,))
def _through_one_reduction(xs: list, shape) -> list:
    """xs (of `shape`), each summed with the identity of its type over a new trailing axis: the same values."""
    xs = [jnp.asarray(x) for x in xs]
    inits = [_identity(x.dtype) for x in xs]
    operands = [jnp.stack([x, jnp.broadcast_to(init, shape)], -1) for x, init in zip(xs, inits)]
    combine = lambda a, b: [u | v if u.dtype == jnp.bool_ else u + v for u, v in zip(a, b)]
    return jax.lax.reduce(operands, inits, combine, (len(shape),))


# The values pass through unchanged, so do their tangents (JAX's own rule for a variadic reduction fails on an
# operand whose tangent is a symbolic zero, and `jax.jacfwd` of a step on a heightfield has such operands).
_through_one_reduction.defjvp(lambda shape, primals, tangents: (_through_one_reduction(*primals, shape),
                                                               tangents[0]))


# The name the core gives its vmap over instances (`jax.vmap(..., axis_name=BATCH_AXIS)`).
BATCH_AXIS = "instances"


def batch_any(flag: jax.Array) -> jax.Array:
    """Whether `flag` holds for any instance of the vmapped batch (unbatched, so a `lax.cond` on it stays a
    conditional and a stage few instances need is skipped for the whole chunk); the flag itself outside it."""
    try:
        return jax.lax.pmax(flag.astype(jnp.int32), BATCH_AXIS) > 0
    except NameError:  # not under the core's vmap: per instance (a select under another vmap)
        return flag


def only_where(need, fn, absent, args: tuple, most: int):
    """fn(*args) where the instance's `need` holds, absent(*args) elsewhere (which must be what fn gives an
    instance that does not need it). Under the core's vmap the chunk's instances in need, when there are at most
    `most` of them, are gathered and only they run fn: a stage few instances need (a leg's box against the
    ground while a few robots of the chunk flail) costs a few instances' work, not the chunk's. With none in need
    the chunk runs `absent` alone; with more than `most`, fn for the whole chunk. Each instance's values are
    what it would get on its own."""

    @jax.custom_batching.custom_vmap
    def one(need, args):
        return jax.lax.cond(need, fn, absent, *args)

    @one.def_vmap
    def _chunk(size, batched, need, args):
        need_batched, args_batched = batched
        need = need if need_batched else jnp.broadcast_to(need, (size,))
        axes = jax.tree_util.tree_map(lambda b: 0 if b else None, args_batched)
        over = lambda f: (lambda a: jax.vmap(lambda x: f(*x), in_axes=(axes,))(a))
        nobody = lambda: over(absent)(args)

        def few():
            (picked,) = jnp.nonzero(need, size=most, fill_value=size)  # `size`: no instance, dropped below
            at = jnp.minimum(picked, size - 1)
            gathered = jax.tree_util.tree_map(lambda x, b: x[at] if b else x, args, args_batched)
            return jax.tree_util.tree_map(lambda o, g: o.at[picked].set(g, mode="drop"), nobody(),
                                          over(fn)(gathered))

        count = jnp.sum(need.astype(jnp.int32))
        branches = [nobody, lambda: over(fn)(args)] if size <= most else [nobody, few, lambda: over(fn)(args)]
        which = jnp.minimum(count, 1) if size <= most else jnp.where(count == 0, 0, jnp.where(count <= most, 1, 2))
        out = jax.lax.switch(which, branches)
        return out, jax.tree_util.tree_map(lambda _: True, out)

    return one(need, args)
