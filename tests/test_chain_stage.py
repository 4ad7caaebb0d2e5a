"""chain_stage.compacted_while: each instance's loop, whatever the batch, at a smaller batch's cost."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from hopper_mjx.engine.chain_stage import BATCH_AXIS, batch_any, compacted_while

LIMIT = 6  # iterations at most, as the solver's cap


def _loop(compact: bool, tail: int = 3):
    """A per-instance loop of uneven length (instance i runs n_i steps of a nonlinear map), with an env that
    mixes a batched array, an unbatched one and a constant, and a `batch_any` inside the body (as the line
    search's), vmapped as the core vmaps."""
    def running(c):
        return c[1] < c[2]

    def body(env, c):
        a, b, k = env
        x, count, n = c
        step = jnp.sin(x) * a + b * k
        first = count == 0  # the first step differs; skipped for the whole batch when no instance takes it
        x = jax.lax.cond(batch_any(first), lambda: jnp.where(first, step + 1e-3, step), lambda: step)
        return x, count + 1, n

    def one(a, b, x, n):
        carry = (x, jnp.zeros((), jnp.int32), n)
        if compact:
            return compacted_while(running, body, (a, b, 0.7), carry, tail=tail)
        return jax.lax.while_loop(running, lambda c: body((a, b, 0.7), c), carry)
    return jax.jit(jax.vmap(one, in_axes=(0, None, 0, 0), axis_name=BATCH_AXIS))


def test_compacted_loop_gives_each_instance_its_own_numbers():
    """Bitwise the plain vmapped loop's answer, with more instances to finish than the small batch holds
    (several rounds), none to finish, and all done at the start."""
    rng = np.random.default_rng(3)
    n = 40
    a = jnp.asarray(rng.uniform(0.5, 1.5, n), jnp.float32)
    x = jnp.asarray(rng.normal(size=n), jnp.float32)
    b = jnp.float32(0.3)
    plain, compact = _loop(False), _loop(True, tail=3)
    uneven = rng.integers(0, LIMIT + 1, n)
    assert np.sum(uneven > 1) > 3 * 3, "several rounds of the small batch"
    for steps in (uneven, np.ones(n, int), np.zeros(n, int)):
        steps = jnp.asarray(steps, jnp.int32)
        want, got = plain(a, b, x, steps), compact(a, b, x, steps)
        np.testing.assert_array_equal(got[1], steps)
        for w, g in zip(want, got):
            np.testing.assert_array_equal(np.asarray(g), np.asarray(w))


def test_compacted_loop_outside_a_vmap_is_the_plain_loop():
    a, b, x, n = jnp.float32(1.2), jnp.float32(0.3), jnp.float32(0.4), jnp.int32(5)

    def body(env, c):
        return jnp.sin(c[0]) * env[0] + env[1], c[1] + 1
    got = compacted_while(lambda c: c[1] < n, body, (a, b), (x, jnp.int32(0)))
    want = jax.lax.while_loop(lambda c: c[1] < n, lambda c: body((a, b), c), (x, jnp.int32(0)))
    assert int(got[1]) == 5
    np.testing.assert_array_equal(np.asarray(got[0]), np.asarray(want[0]))


def test_compacted_loop_differentiates_as_the_plain_loop():
    """A vmapped jacfwd through the loop (as balance.velocity_jacobians takes the step's): the plain loop's."""
    rng = np.random.default_rng(4)
    n = 12
    a = jnp.asarray(rng.uniform(0.5, 1.5, n), jnp.float32)
    x = jnp.asarray(rng.normal(size=n), jnp.float32)
    steps = jnp.asarray(rng.integers(0, LIMIT + 1, n), jnp.int32)

    def final(compact):
        def one(a, x, n):
            carry = (x, jnp.zeros((), jnp.int32), n)
            body = lambda env, c: (jnp.sin(c[0]) * env[0] + env[1], c[1] + 1, c[2])
            running = lambda c: c[1] < c[2]
            out = (compacted_while(running, body, (a, 0.3), carry, tail=2) if compact
                   else jax.lax.while_loop(running, lambda c: body((a, 0.3), c), carry))
            return out[0]
        return jax.jit(jax.vmap(jax.jacfwd(one, (0, 1)), axis_name=BATCH_AXIS))
    want, got = final(False)(a, x, steps), final(True)(a, x, steps)
    for w, g in zip(want, got):
        np.testing.assert_array_equal(np.asarray(g), np.asarray(w))
    assert np.ptp(np.asarray(got[1])) > 0.1, "a real derivative, uneven over the instances"
