"""MuJoCo's primal Newton solve over the chain's rows, in scalar arithmetic.

Minimises, over the joint accelerations a,
    0.5 (a - a0)' M (a - a0) + sum over active rows 0.5 D (J a - aref)^2,
a row being active when J a - aref < 0 (limits and pyramid edges are one-sided); a joint's
dry-friction row (`Rows.loss`: bound f) costs that quadratic only for |J a - aref| < f R and
f |J a - aref| - f^2 R / 2 beyond, where its force is the bound (MuJoCo's Huber cost). From the
better of the warm start and a0 = M^-1 qfrc_smooth, each iteration takes the Newton
direction of the current active set (the 9x9 Hessian M + J' D J, Cholesky-factorised
unrolled) and an exact line search along it. The cost along a line is a convex piecewise
quadratic, so its derivative is piecewise linear: the search brackets the root and steps
to the root of the bracketing pieces (Newton from either end, else the secant), which
lands on the exact minimiser once the bracket holds one piece.
Symmetric matrices are dicts {(i, j): value} over i <= j. The rows take one of two forms, the same
arithmetic either way: on the plane per-row scalars (`PerRow`, folding the Jacobian's constant zeros),
stacked only along the line search, whose evaluations run many times a step; on a heightfield, with
dozens of rows, stacked for the whole solve (`Stacked`): each stage is then a few array operations,
whatever the number of rows, where per-row code is traced and compiled once for each row.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from hopper_mjx.engine.chain import algebra as al
from hopper_mjx.engine.chain.constraint import MINVAL, Rows
from hopper_mjx.engine.chain.stage import batch_any, stored

FAR = 1e30  # the search's upper end before any point past the minimum is found
# The line search's derivative and the Newton loop's gradient count as zero within this many rounding units
# (float eps) of their terms' magnitudes.
ROUNDING = 16
UNROLLED_LINE_SEARCH = 8  # up to this many steps, each is its own stored stage (measured faster than a loop)


class Solution(NamedTuple):
    qacc: tuple
    force: tuple  # per row
    qfrc_constraint: tuple
    iterations: jax.Array  # () int32: Newton iterations run, MuJoCo's solver_niter


def _column(a: dict, b, low: dict, y, j: int):
    """Column j of the Cholesky factor of a, the inverse of its diagonal, and entry j of
    L^-1 b (the forward substitution rides along the factorisation)."""
    n = len(b)
    pivot = al.sub(a[j, j], al.total(al.mul(low[j, k], low[j, k]) for k in range(j)))
    inv = 1.0 / al.sqrt(pivot) if al.is_const(pivot) else 1 / jnp.sqrt(pivot)
    column = tuple(al.mul(al.sub(a[j, i], al.total(al.mul(low[i, k], low[j, k]) for k in range(j))), inv)
                   for i in range(j + 1, n))
    y_j = al.mul(al.sub(b[j], al.total(al.mul(low[j, k], y[k]) for k in range(j))), inv)
    return inv, column, y_j


def solve_spd(gate, a: dict, b) -> tuple:
    """x = a^-1 b for symmetric positive definite a (dict over i <= j): Cholesky, one stored
    stage per column and per back-substitution row (each depends on all before it)."""
    n = len(b)
    low, inv, y = {}, [], []
    for j in range(n):
        inv_j, column, y_j = stored(gate, lambda a_, b_, l_, y_, j=j: _column(a_, b_, l_, y_, j),
                                    a, tuple(b), dict(low), tuple(y))
        inv.append(inv_j)
        y.append(y_j)
        low.update({(i, j): v for i, v in zip(range(j + 1, n), column)})
    x = [0.0] * n
    for i in reversed(range(n)):
        later = tuple(x[i + 1:])
        x[i] = stored(gate, lambda y_i, l_, later, inv_i, i=i: al.mul(
            al.sub(y_i, al.total(al.mul(l_[k, i], later[k - i - 1]) for k in range(i + 1, n))), inv_i),
            y[i], dict(low), later, inv[i])
    return tuple(x)


def sym_matvec(a: dict, v, n: int) -> tuple:
    return tuple(al.total(al.mul(a[min(i, j), max(i, j)], v[j]) for j in range(n)) for i in range(n))


def _quadratic(r, loss):
    """Whether a row at residual r is in its quadratic piece (D counts in the Hessian)."""
    return r < 0 if loss is None else jnp.abs(r) < loss[1]


def _force(w, r, loss):
    """-D r in the quadratic piece; a friction row's bound -f sign(r) beyond it; 0 for an inactive one-sided row."""
    if loss is None:
        return jnp.where(r < 0, -w * r, 0.0)
    return jnp.where(_quadratic(r, loss), -w * r, jnp.where(r < 0, loss[0], -loss[0]))


def _row_cost(w, r, loss):
    if loss is None:
        return jnp.where(r < 0, 0.5 * w * r * r, 0.0)
    f, bound = loss
    return jnp.where(_quadratic(r, loss), 0.5 * w * r * r, f * jnp.abs(r) - 0.5 * f * bound)


class LineRows(NamedTuple):
    """The rows' constants along a line search, stacked: the search's evaluations are then a few array
    operations for all rows, where per-row scalars traced each row once per unrolled evaluation."""

    huber: np.ndarray  # (R,) bool, a constant of the model: the two-sided friction rows (`Rows.loss`)
    weight: jax.Array  # (R,) D, 0 for a row that does not exist
    f: jax.Array  # (R,) a friction row's force bound, 0 for a one-sided row
    bound: jax.Array  # (R,) a friction row's residual bound f R, 0 for a one-sided row


class PerRow:
    """The rows as per-row scalars: each row's expressions are traced on their own and fold the Jacobian's
    constant zeros. The plane's few rows are cheapest so; the line search stacks them (`line_rows`)."""

    def setup(self, gate, rows: Rows, dtype) -> Rows:
        if rows.block is not None:
            raise ValueError("stacked contact rows (a heightfield's) need the Stacked form")
        return rows

    def residuals(self, rows: Rows, qacc) -> tuple:
        return tuple(al.sub(al.dot(j, qacc), a) for j, a in zip(rows.jac, rows.aref))

    def active(self, rows: Rows, residual) -> tuple:
        return tuple(jnp.where(_quadratic(r, loss), w, 0.0) for w, r, loss in zip(rows.weight, residual, rows.loss))

    def forces(self, rows: Rows, residual):
        """Row forces (`_force`) and their joint-space sum J' f."""
        force = tuple(_force(w, r, loss) for w, r, loss in zip(rows.weight, residual, rows.loss))
        nv = len(rows.jac[0])
        return force, tuple(al.total(al.mul(j[i], f) for j, f in zip(rows.jac, force)) for i in range(nv))

    def cost(self, rows: Rows, residual):
        return al.total(_row_cost(w, r, loss) for w, r, loss in zip(rows.weight, residual, rows.loss))

    def hessian(self, mass: dict, active, rows: Rows) -> dict:
        """M + J' diag(active) J, its upper triangle."""
        n = len(rows.jac[0])
        return {(i, j): al.add(mass[i, j], al.total(al.mul(w, al.mul(jr[i], jr[j])) for w, jr in zip(active, rows.jac)))
                for i in range(n) for j in range(i, n)}

    def along(self, rows: Rows, residual, search, dtype):
        """The residuals and their slopes along `search`, as (R,) arrays."""
        return al.vector(residual, dtype), al.vector((al.dot(j, search) for j in rows.jac), dtype)

    def line_rows(self, gate, rows: Rows, dtype) -> LineRows:
        """The rows' weights and friction bounds stacked, once a solve."""
        weight, f, bound = stored(gate, lambda w, loss: (al.vector(w, dtype), _bounds(loss, 0, dtype),
                                                         _bounds(loss, 1, dtype)), rows.weight, rows.loss)
        return LineRows(_huber(rows), weight, f, bound)


class Stack(NamedTuple):
    """The rows stacked along one axis (`Stacked`)."""

    jac: jax.Array  # (nv, R): the rows' Jacobians by dof
    aref: jax.Array  # (R,)
    line: LineRows  # weights and friction bounds, as the line search takes them


class Stacked:
    """The rows stacked once a step: every stage of the solve is then a few array operations whatever the number of
    rows, where per-row scalars are traced and compiled once for each. On a heightfield (dozens of rows) this halves
    the step's program and speeds it up; on the plane the stacking costs more than it saves (docs/performance.md)."""

    def __init__(self, rows: Rows):
        self.huber = _huber(rows)

    def setup(self, gate, rows: Rows, dtype) -> Stack:
        def stack(rows):
            parts = []  # (jac, aref, weight, f, bound) of the per-row rows, then of the block
            if rows.jac:
                col = lambda xs: al.vector(xs, dtype)
                jac = jnp.stack([col(j[i] for j in rows.jac) for i in range(len(rows.jac[0]))])
                parts.append((jac, col(rows.aref), col(rows.weight), _bounds(rows.loss, 0, dtype),
                              _bounds(rows.loss, 1, dtype)))
            if rows.block is not None:
                zeros = jnp.zeros_like(rows.block.weight)  # contact rows are one-sided
                parts.append((rows.block.jac, rows.block.aref, rows.block.weight, zeros, zeros))
            jac, aref, weight, f, bound = (jnp.concatenate(x, -1) for x in zip(*parts))
            return Stack(jac, aref, LineRows(None, weight, f, bound))
        return stored(gate, stack, rows)

    def residuals(self, s: Stack, qacc):
        return _jac_t(s, qacc) - s.aref

    def active(self, s: Stack, residual):
        return jnp.where(_on(self._lr(s), residual), s.line.weight, 0.0)

    def forces(self, s: Stack, residual):
        lr = self._lr(s)
        beyond = jnp.where(lr.huber, jnp.where(residual < 0, lr.f, -lr.f), 0.0)
        force = jnp.where(_on(lr, residual), -lr.weight * residual, beyond)  # `_force`
        total = _row_sum(s.jac * force)
        return force, tuple(total[i] for i in range(total.shape[0]))

    def cost(self, s: Stack, residual):
        lr = self._lr(s)
        return _row_sum(_costs(lr, residual, _on(lr, residual)))

    def hessian(self, mass: dict, active, s: Stack) -> dict:
        """M + J' diag(active) J, its upper triangle, every entry in one product over the rows."""
        n = s.jac.shape[0]
        upper = [(i, j) for i in range(n) for j in range(i, n)]
        left, right = (np.array(k) for k in zip(*upper))
        rows = _row_sum(s.jac[left] * s.jac[right] * active)
        return {(i, j): al.add(mass[i, j], rows[k]) for k, (i, j) in enumerate(upper)}

    def along(self, s: Stack, residual, search, dtype):
        return residual, _jac_t(s, search)

    def line_rows(self, gate, s: Stack, dtype) -> LineRows:
        return self._lr(s)

    def _lr(self, s: Stack) -> LineRows:
        return s.line._replace(huber=self.huber)  # the mask a constant, never a stage's input


def _jac_t(s: Stack, v):
    """(R,) each row's Jacobian times the dof vector `v` (scalars)."""
    return jnp.sum(s.jac * al.vector(v, s.jac.dtype)[:, None], axis=0)


def _bounds(loss: tuple, k: int, dtype) -> jax.Array:
    """(R,) each per-row row's friction force bound f (k = 0) or residual bound f R (k = 1), 0 for a one-sided
    row (`Rows.loss`)."""
    return al.vector(((v or (0.0, 0.0))[k] for v in loss), dtype)


def _huber(rows: Rows) -> np.ndarray:
    """(R,) bool, a constant of the model: which rows are two-sided friction rows (`Rows.loss`; a `Block`'s are
    one-sided)."""
    stacked = 0 if rows.block is None else rows.block.weight.shape[0]
    return np.array([loss is not None for loss in rows.loss] + [False] * stacked, bool)


def _cost(gate, form, mass, qfrc_smooth, qacc_smooth, rows, qacc):
    residual, ma = stored(gate, lambda r, x: (form.residuals(r, x), sym_matvec(mass, x, len(x))), rows, qacc)
    gauss = 0.5 * al.dot(al.vsub(ma, qfrc_smooth), al.vsub(qacc, qacc_smooth))
    return gauss + form.cost(rows, residual)


def _row_sum(x):
    """x summed over its last (row) axis as a product with ones: under vmap a matrix-vector product, measured
    about 3x faster on XLA:CPU than a reduction along the rows, the minor axis of each instance."""
    return x @ jnp.ones(x.shape[-1], x.dtype)


def _on(lr: LineRows, x):
    """(R,) whether each stacked row at residual x is in its quadratic piece (`_quadratic`)."""
    return jnp.where(lr.huber, jnp.abs(x) < lr.bound, x < 0)


def _costs(lr: LineRows, x, on):
    """(R,) each stacked row's cost at residual x (`_row_cost`), `on` its `_on`."""
    return jnp.where(on, 0.5 * lr.weight * x * x, jnp.where(lr.huber, lr.f * jnp.abs(x) - 0.5 * lr.f * lr.bound, 0.0))


def _line(lr: LineRows, residual, slope, g1, g2, alpha):
    """(alpha, cost up to a constant, derivative, curvature, the derivative's terms' sum of magnitudes: its
    rounding scale) along the search direction; `residual` and `slope` (R,) arrays."""
    x = residual + alpha * slope
    on = _on(lr, x)
    beyond = jnp.where(lr.huber, jnp.where(x < 0, -lr.f * slope, lr.f * slope), 0.0)  # the slope of f |x|
    term = jnp.where(on, lr.weight * slope * x, beyond)
    sums = _row_sum(jnp.stack([term, jnp.abs(term), jnp.where(on, lr.weight * slope * slope, 0.0), _costs(lr, x, on)]))
    d1, size = g1 + alpha * g2 + sums[0], jnp.abs(g1) + jnp.abs(alpha * g2) + sums[1]
    return alpha, alpha * (g1 + 0.5 * alpha * g2) + sums[3], d1, jnp.maximum(g2 + sums[2], MINVAL), size


def _pick(c, p, q):
    return tuple(jnp.where(c, x, y) for x, y in zip(p, q))


def _bracket(line, gtol, bracket):
    """One line-search step: evaluate the candidate, keep it as the lower or upper end, and
    choose the next candidate (Newton from either end inside the bracket, else the secant); done
    at a point whose derivative is below `gtol` (MuJoCo C's test)."""
    lo, hi, found_hi, candidate, searching = bracket
    p = line(candidate)
    # The derivative is zero to within its rounding (float32 cannot reach C's float64 gtol) or below gtol.
    done = jnp.abs(p[2]) < jnp.maximum(gtol, ROUNDING * jnp.finfo(p[2].dtype).eps * p[4])
    below = p[2] < 0
    lo, hi = _pick(below, p, lo), _pick(below, hi, p)
    found_hi = found_hi | ~below
    from_lo, from_hi = lo[0] - lo[2] / lo[3], hi[0] - hi[2] / hi[3]
    secant = lo[0] - lo[2] * (hi[0] - lo[0]) / jnp.maximum(hi[2] - lo[2], MINVAL)
    inside = lambda a: (a > lo[0]) & (a < hi[0])
    candidate = jnp.where(~found_hi | inside(from_lo), from_lo, jnp.where(inside(from_hi), from_hi, secant))
    # Converged: keep the point (its ends may not bracket it) and propose it again, for `best` to take;
    # a search that converged before holds, whether or not others of its chunk still search.
    lo, hi = _pick(done, p, lo), _pick(done, p, hi)
    new = (lo, hi, found_hi | done, jnp.where(done, p[0], candidate), ~done)
    return jax.tree_util.tree_map(lambda n, o: jnp.where(searching, n, o), new, bracket)


def _line_search(gate, lr: LineRows, residual, slope, g1, g2, iterations: int, gtol):
    """The step along the search direction that minimises the cost (see the module doc), and
    the cost's decrease. Like MuJoCo C, the search stops at a point where the derivative is below
    `gtol`; a step runs while any instance of the core's chunk is still searching (`batch_any`)."""
    line = lambda a, args: _line(LineRows(lr.huber, *args[:3]), *args[3:], a)  # the mask stays a constant
    args = (lr.weight, lr.f, lr.bound, residual, slope, g1, g2)
    lo = stored(gate, line, jnp.zeros_like(g1), args)
    hi = (jnp.full_like(g1, FAR), jnp.full_like(g1, FAR), jnp.full_like(g1, FAR), jnp.ones_like(g1), jnp.zeros_like(g1))
    bracket = (lo, hi, jnp.zeros_like(g1, dtype=bool), -lo[2] / lo[3], jnp.ones_like(g1, dtype=bool))
    # One jit for every step: its Python is traced once and vmap batches it once (see `stored`).
    step = jax.jit(lambda b, args, gtol: _bracket(lambda x: line(x, args), gtol, b))
    if iterations <= UNROLLED_LINE_SEARCH:
        for _ in range(iterations):
            searching = batch_any(bracket[4])  # outside `stored`, whose trace has no batch axis
            bracket = stored(gate, lambda b, go, args, gtol: jax.lax.cond(go, lambda b: step(b, args, gtol),
                                                                          lambda x: x, b),
                             bracket, searching, args, gtol)
    else:  # a long search (a converged reference) as a loop: one trace, a smaller program
        bracket = jax.lax.fori_loop(0, iterations, lambda _, b: step(b, args, gtol), bracket)

    def best(bracket, args, start_cost):
        lo, hi, found_hi, candidate, _ = bracket
        last = line(candidate, args)
        out = _pick(last[1] < lo[1], last, lo)
        out = _pick(found_hi & (hi[1] < out[1]), hi, out)
        return out[0], start_cost - out[1]
    return stored(gate, best, bracket, args, lo[1])


class _Iterate(NamedTuple):
    """The solver's state at one point: the rows' residuals, forces and the cost's gradient."""

    qacc: tuple
    residual: tuple
    active: tuple  # D of the active rows, 0 elsewhere
    ma: tuple  # M qacc
    force: tuple
    qfrc_constraint: tuple
    grad: tuple


def _evaluate(gate, form, mass, qfrc_smooth, rows, qacc) -> _Iterate:
    def residuals(rows, qacc):
        residual = form.residuals(rows, qacc)
        return residual, form.active(rows, residual), sym_matvec(mass, qacc, len(qacc))
    residual, active, ma = stored(gate, residuals, rows, qacc)
    force, qfrc_c = stored(gate, form.forces, rows, residual)
    grad = stored(gate, lambda *a: tuple(al.sub(al.sub(m, s), c) for m, s, c in zip(*a)), ma, qfrc_smooth, qfrc_c)
    return _Iterate(tuple(qacc), residual, active, ma, force, qfrc_c, grad)


def _newton_step(gate, form, mass, qfrc_smooth, rows, lr: LineRows, ls_iterations: int, it: _Iterate,
                 ls_tol: float):
    """The next point along the Newton direction of the current active set, and the cost's decrease."""
    n = len(it.qacc)
    hessian = stored(gate, lambda act, rows: form.hessian(mass, act, rows), it.active, rows)
    search = tuple(-x for x in solve_spd(gate, hessian, it.grad))

    def along(search, ma, residual, rows):
        return (*form.along(rows, residual, search, lr.weight.dtype), al.dot(search, al.vsub(ma, qfrc_smooth)),
                al.dot(search, sym_matvec(mass, search, n)))
    residual, slope, g1, g2 = stored(gate, along, search, it.ma, it.residual, rows)
    gtol = ls_tol * jnp.sqrt(al.dot(search, search))  # MuJoCo's tolerance ls_tolerance |search| / scale
    alpha, decrease = _line_search(gate, lr, residual, slope, g1, g2, ls_iterations, gtol)
    return tuple(al.add(a, al.mul(alpha, s)) for a, s in zip(it.qacc, search)), decrease


def solve(gate, mass: dict, qfrc_smooth, qacc_smooth, qacc_warmstart, rows: Rows, *, iterations: int,
          ls_iterations: int, tolerance: float, cost_scale: float, ls_tolerance: float,
          warmstart: bool = True, stacked: bool = False) -> Solution:
    """The constrained accelerations, the rows' forces and the Newton iterations run. Like MuJoCo, an
    instance stops iterating once the scaled cost decrease or gradient falls below the tolerance, or
    (float32) once the gradient is zero to within its rounding, and runs none from a start already there.
    `stacked`: the rows as arrays (`Stacked`, for many rows) rather than per-row scalars (`PerRow`)."""
    form = Stacked(rows) if stacked else PerRow()
    dtype = jnp.result_type(*(x for x in qacc_smooth if not al.is_const(x)))
    rows = form.setup(gate, rows, dtype)
    qacc = qacc_smooth
    if warmstart:
        better = _cost(gate, form, mass, qfrc_smooth, qacc_smooth, rows, qacc_warmstart) < _cost(
            gate, form, mass, qfrc_smooth, qacc_smooth, rows, qacc_smooth)
        qacc = stored(gate, lambda w, s: tuple(jnp.where(better, a, b) for a, b in zip(w, s)),
                      qacc_warmstart, qacc_smooth)
    start = _evaluate(gate, form, mass, qfrc_smooth, rows, tuple(jnp.asarray(x) for x in qacc))
    lr = form.line_rows(gate, rows, dtype)

    def body(carry):
        it, _, count = carry
        qacc, decrease = _newton_step(gate, form, mass, qfrc_smooth, rows, lr, ls_iterations, it,
                                      tolerance * ls_tolerance / cost_scale)
        it = _evaluate(gate, form, mass, qfrc_smooth, rows, qacc)
        gradient = jnp.sqrt(al.dot(it.grad, it.grad))
        return it, ((cost_scale * decrease < tolerance) | (cost_scale * gradient < tolerance)
                    | _within_rounding(it, qfrc_smooth)), count + 1

    # Under vmap the loop runs until every instance is done; finished ones are held. An instance whose start
    # is not finite (a diverged state) has nothing to solve and is done at once, so it cannot hold its chunk
    # to the iteration cap. A start already at the minimum (no row active at the smooth acceleration: C's line
    # search then finds no step and counts no iteration) is done too. The flag and the count derive from the
    # instance's numbers: batched from the start, vmap batches the loop's body once (JAX re-batches a while
    # body for each carry it finds batched later).
    done = ~jnp.isfinite(al.dot(start.grad, start.grad)) | _within_rounding(start, qfrc_smooth)
    it, _, count = jax.lax.while_loop(lambda c: ~c[1] & (c[2] < iterations), body,
                                      (start, done, jnp.where(done, 0, 0)))
    return Solution(it.qacc, it.force, it.qfrc_constraint, count)


def _within_rounding(it: _Iterate, qfrc_smooth):
    """The gradient is zero to within the rounding of its terms (M a, qfrc_smooth, J' f): in float32 C's float64
    tolerance may be out of reach, and more iterations would only stir the rounding."""
    norm = lambda v: jnp.sqrt(al.dot(v, v))
    gradient = norm(it.grad)
    terms = norm(it.ma) + norm(qfrc_smooth) + norm(it.qfrc_constraint)
    return gradient < ROUNDING * jnp.finfo(gradient.dtype).eps * terms
