"""The chain's stored stages (`engine.chain.stage`): computed once, written by a few kernels, values unchanged."""

import jax
import jax.numpy as jnp
import numpy as np

from hopper_mjx.engine.chain.stage import BATCH_AXIS, PER_KERNEL, one_kernel, only_where, stored
from hopper_mjx.engine.xla import CPU_COMPILER_OPTIONS
from hopper_mjx.perf import kernels


def test_one_kernel_hands_back_every_value_bit_for_bit():
    """The identity each output is summed with leaves every value as it was: signed zeros, infinities, NaN,
    subnormals, the extremes of each type, integers and booleans."""
    f32 = np.array([0.0, -0.0, np.inf, -np.inf, np.nan, 1e-45, -1e-45, 3.4e38, -3.4e38, 1.0, -2.5, 7e-39], np.float32)
    f64 = np.array([-0.0, 0.0, np.nan, 5e-324, -1.7e308, np.inf, 1.0, -1.0, 0.1, 2.0, 3.0, 4.0])
    i32 = np.array([0, -1, 1, 2**31 - 1, -2**31, 7, 8, 9, 10, 11, 12, 13], np.int32)
    flags = np.array([True, False] * 6)
    inputs = [f32, f32[::-1].copy(), i32, flags, f32 * 2, i32[::-1].copy(), flags[::-1].copy()]
    with jax.enable_x64(True):
        out = jax.jit(jax.vmap(lambda *xs: one_kernel(list(xs))))(*inputs, f64)
        for x, y in zip([*inputs, f64], out, strict=True):
            y = np.asarray(y)
            assert y.dtype == x.dtype
            assert x.tobytes() == y.tobytes()


def _stage_kernels(outputs: int) -> tuple[int, np.ndarray]:
    """Kernels of a vmapped stored stage of `outputs` outputs that share a sine and a cosine, its values checked
    against NumPy's."""

    def stage(x):
        s, c = jnp.sin(x), jnp.cos(x)
        return [s * (k + 1.0) - c for k in range(outputs)]

    f = jax.jit(jax.vmap(lambda gate, x: stored(gate, stage, x), in_axes=(None, 0)),
                compiler_options=CPU_COMPILER_OPTIONS)
    x = jnp.linspace(-3.0, 3.0, 256)
    x64 = np.asarray(x, np.float64)
    want = np.array([np.sin(x64) * (k + 1.0) - np.cos(x64) for k in range(outputs)])
    np.testing.assert_allclose(np.asarray(f(jnp.array(True), x)), want, rtol=0, atol=1e-5 * outputs)
    return kernels.count(f.lower(jnp.array(True), x).compile().as_text())


def test_a_stored_stage_is_a_kernel_for_each_per_kernel_outputs_and_is_counted_so():
    """PER_KERNEL more outputs are one more kernel, where each output was a kernel of its own; the count leaves
    out the zeros of the branch never taken (a copy for each output)."""
    one, two, three = (_stage_kernels(k * PER_KERNEL) for k in (1, 2, 3))
    assert two - one == three - two == 1
    assert one <= 3  # the conditional, its predicate, the stage


def test_jacfwd_passes_through_one_kernel():
    """The packed outputs' derivatives are those of the values packed (JAX's own rule for a variadic reduction
    failed where a tangent is a symbolic zero: an integer output, or one that does not depend on the input)."""
    f = lambda x: one_kernel([jnp.sin(x), 2.0 * x, jnp.zeros_like(x) + 3.0, (x > 0).astype(jnp.int32)])[:3]
    jac = jax.jacfwd(lambda x: jnp.stack(f(x)))(jnp.float32(0.5))
    np.testing.assert_allclose(np.asarray(jac), [np.cos(0.5), 2.0, 0.0], rtol=1e-6)


def _needy(x, scale):
    """A per-instance stage with reductions and shared terms, whose `absent` value is what it gives an instance
    with x <= 0 (as a box far from the ground has no contact)."""
    s = jnp.sin(x * scale)
    out = jnp.where(x > 0, jnp.cumsum(s * jnp.arange(1.0, 6.0)) / (1.0 + x * x), 0.0)
    return out, jnp.sum(out) > 0.5


def test_only_where_gives_each_instance_its_own_values_however_many_need_the_stage():
    """Under the core's vmap, none, a few (gathered) or most instances of the chunk in need: each instance gets
    bit for bit what the stage computed for every instance gives it, with an unbatched argument beside a batched
    one."""
    absent = lambda x, scale: (jnp.zeros(5), jnp.array(False))
    most = 4

    def chunk(need, x, scale):
        return jax.vmap(lambda n, v: only_where(n, _needy, absent, (v, scale), most), axis_name=BATCH_AXIS)(need, x)

    whole = jax.jit(jax.vmap(_needy, in_axes=(0, None)))
    gathered = jax.jit(chunk)
    rng = np.random.default_rng(0)
    for count in (0, 1, most, most + 1, 16):
        x = rng.uniform(-1.0, 1.0, 16).astype(np.float32)
        need = np.zeros(16, bool)
        need[rng.permutation(16)[:count]] = True
        x = np.where(need, np.abs(x) + 0.1, -np.abs(x)).astype(np.float32)
        want, got = whole(x, jnp.float32(1.3)), gathered(need, x, jnp.float32(1.3))
        for w, g in zip(want, got):
            assert np.asarray(w).tobytes() == np.asarray(g).tobytes(), f"{count} in need"
