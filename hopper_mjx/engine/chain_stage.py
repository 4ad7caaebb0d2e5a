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

from hopper_mjx.engine.chain_algebra import is_const


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



def compacted_while(running, body, env, carry, *, tail: int = 8):
    """`lax.while_loop(running, lambda c: body(env, c), carry)` per instance. Under the core's vmap a plain loop
    runs every instance until the batch's slowest is done; here every instance takes its first step together,
    then the few still running are gathered `tail` at a time, run to their end as a small batch and scattered back.
    Each instance's numbers are those of its own loop (a step reads only its instance's values); only the cost
    differs. `env`'s leaves may mix arrays and constants (the folded model numbers); `carry`'s are arrays."""
    env_leaves, env_tree = jax.tree_util.tree_flatten(env)
    traced_at = [i for i, x in enumerate(env_leaves) if not is_const(x)]
    carry_leaves, carry_tree = jax.tree_util.tree_flatten(jax.tree_util.tree_map(jnp.asarray, carry))
    n_env = len(traced_at)

    def split(args):
        leaves = list(env_leaves)
        for i, x in zip(traced_at, args[:n_env]):
            leaves[i] = x
        return (jax.tree_util.tree_unflatten(env_tree, leaves),
                jax.tree_util.tree_unflatten(carry_tree, list(args[n_env:])))

    def until_done(valid, *args):  # the instance's own loop; a `valid` false stops it before it starts
        env, carry = split(args)
        return jax.tree_util.tree_leaves(
            jax.lax.while_loop(lambda c: valid & running(c), lambda c: body(env, c), carry))

    def first_step(*args):
        env, carry = split(args)
        go = running(carry)
        return jax.tree_util.tree_leaves(
            jax.tree_util.tree_map(lambda n, o: jnp.where(go, n, o), body(env, carry), carry))

    loop = jax.custom_batching.custom_vmap(lambda *args: until_done(jnp.array(True), *args))

    @loop.def_vmap
    def _batched(size, in_batched, *args):
        axes = [0 if b else None for b in in_batched[:n_env]] + [0] * len(carry_leaves)
        env_args = list(args[:n_env])
        state = [x if b else jnp.broadcast_to(x, (size,) + x.shape) for x, b in zip(args[n_env:], in_batched[n_env:])]
        on = lambda f, *lead: jax.vmap(f, in_axes=[0] * len(lead) + axes, axis_name=BATCH_AXIS)
        runs = lambda s: jax.vmap(lambda *c: running(jax.tree_util.tree_unflatten(carry_tree, list(c))))(*s)
        state = jax.lax.cond(jnp.any(runs(state)), lambda s: on(first_step)(*env_args, *s), list, state)
        width = min(tail, size)

        def small_batch(loop_state):
            state, left = loop_state
            idx = jnp.nonzero(left, size=width, fill_value=0)[0]
            valid = jnp.arange(width) < jnp.sum(left)  # a slot past the last runner holds instance 0, stopped
            sub_env = [x if ax is None else x[idx] for x, ax in zip(env_args, axes)]
            out = on(until_done, valid)(valid, *sub_env, *[x[idx] for x in state])
            where = jnp.where(valid, idx, size)  # out of range: dropped
            state = [x.at[where].set(o, mode="drop") for x, o in zip(state, out)]
            return state, left.at[where].set(False, mode="drop")

        state, _ = jax.lax.while_loop(lambda s: jnp.any(s[1]), small_batch, (state, runs(state)))
        return state, [True] * len(state)

    # A derivative is the plain loop's: JAX's derivative of a custom_vmap function would batch with the rule above,
    # which it cannot differentiate (a vmapped jacfwd of the step fails to trace).
    differentiable = jax.custom_jvp(loop)
    differentiable.defjvp(lambda primals, tangents: jax.jvp(
        lambda *args: until_done(jnp.array(True), *args), primals, tangents))
    return jax.tree_util.tree_unflatten(carry_tree,
                                        differentiable(*[env_leaves[i] for i in traced_at], *carry_leaves))
