"""MuJoCo's primal Newton solve over the chain's rows, in scalar arithmetic.

Minimises, over the joint accelerations a,
    0.5 (a - a0)' M (a - a0) + sum over active rows 0.5 D (J a - aref)^2,
a row being active when J a - aref < 0 (limits and pyramid edges are one-sided). From the
better of the warm start and a0 = M^-1 qfrc_smooth, each iteration takes the Newton
direction of the current active set (the 9x9 Hessian M + J' D J, Cholesky-factorised
unrolled) and an exact line search along it. The cost along a line is a convex piecewise
quadratic, so its derivative is piecewise linear: the search brackets the root and steps
to the root of the bracketing pieces (Newton from either end, else the secant), which
lands on the exact minimiser once the bracket holds one piece.
Symmetric matrices are dicts {(i, j): value} over i <= j.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from hopper_mjx.engine import chain_algebra as al
from hopper_mjx.engine.chain_constraint import MINVAL, Rows
from hopper_mjx.engine.chain_stage import stored

FAR = 1e30  # the search's upper end before any point past the minimum is found


class Solution(NamedTuple):
    qacc: tuple
    force: tuple  # per row
    qfrc_constraint: tuple


def cholesky(a: dict, n: int):
    """Lower factor L (dict over i >= j) and the inverses of its diagonal."""
    low, inv = {}, []
    for j in range(n):
        pivot = al.sub(a[j, j], al.total(al.mul(low[j, k], low[j, k]) for k in range(j)))
        diag = al.sqrt(pivot)
        inv.append(1.0 / diag if al.is_const(diag) else 1 / diag)
        for i in range(j + 1, n):
            off = al.sub(a[j, i], al.total(al.mul(low[i, k], low[j, k]) for k in range(j)))
            low[i, j] = al.mul(off, inv[j])
    return low, tuple(inv)


def cho_solve(factor, b) -> tuple:
    low, inv = factor
    n = len(b)
    y = []
    for i in range(n):
        y.append(al.mul(al.sub(b[i], al.total(al.mul(low[i, k], y[k]) for k in range(i))), inv[i]))
    x = [0.0] * n
    for i in reversed(range(n)):
        x[i] = al.mul(al.sub(y[i], al.total(al.mul(low[k, i], x[k]) for k in range(i + 1, n))), inv[i])
    return tuple(x)


def sym_matvec(a: dict, v, n: int) -> tuple:
    return tuple(al.total(al.mul(a[min(i, j), max(i, j)], v[j]) for j in range(n)) for i in range(n))


def _residuals(rows: Rows, qacc):
    return tuple(al.sub(al.dot(j, qacc), a) for j, a in zip(rows.jac, rows.aref))


def _cost(mass, qfrc_smooth, qacc_smooth, rows: Rows, qacc):
    ma = sym_matvec(mass, qacc, len(qacc))
    gauss = 0.5 * al.dot(al.vsub(ma, qfrc_smooth), al.vsub(qacc, qacc_smooth))
    return gauss + al.total(
        jnp.where(r < 0, 0.5 * w * r * r, 0.0) for w, r in zip(rows.weight, _residuals(rows, qacc)))


def _line(weight, residual, slope, g1, g2, alpha):
    """(alpha, cost up to a constant, derivative, curvature) along the search direction."""
    d1, d2, cost = g1 + alpha * g2, g2, alpha * (g1 + 0.5 * alpha * g2)
    for w, r, s in zip(weight, residual, slope):  # rows that do not exist have w = 0
        x = r + alpha * s
        on = x < 0
        d1 = d1 + jnp.where(on, w * s * x, 0.0)
        d2 = d2 + jnp.where(on, w * s * s, 0.0)
        cost = cost + jnp.where(on, 0.5 * w * x * x, 0.0)
    return alpha, cost, d1, jnp.maximum(d2, MINVAL)


def _line_search(weight, residual, slope, g1, g2, iterations: int):
    """The step along the search direction that minimises the cost (see the module doc)."""
    point = lambda a: _line(weight, residual, slope, g1, g2, a)
    pick = lambda c, p, q: tuple(jnp.where(c, x, y) for x, y in zip(p, q))
    lo = point(jnp.zeros_like(g1))
    hi = (jnp.full_like(g1, FAR), jnp.full_like(g1, FAR), jnp.full_like(g1, FAR), jnp.ones_like(g1))
    found_hi = jnp.zeros_like(g1, dtype=bool)
    candidate = -lo[2] / lo[3]
    for _ in range(iterations):
        p = point(candidate)
        below = p[2] < 0
        lo, hi = pick(below, p, lo), pick(below, hi, p)
        found_hi = found_hi | ~below
        from_lo, from_hi = lo[0] - lo[2] / lo[3], hi[0] - hi[2] / hi[3]
        secant = lo[0] - lo[2] * (hi[0] - lo[0]) / jnp.maximum(hi[2] - lo[2], MINVAL)
        inside = lambda a: (a > lo[0]) & (a < hi[0])
        candidate = jnp.where(~found_hi | inside(from_lo), from_lo, jnp.where(inside(from_hi), from_hi, secant))
    last = point(candidate)
    best = pick(last[1] < lo[1], last, lo)
    best = pick(found_hi & (hi[1] < best[1]), hi, best)
    return best[0]


def _newton_step(gate, mass, qfrc_smooth, rows: Rows, ls_iterations: int, qacc):
    n = len(qacc)
    residual = _residuals(rows, qacc)
    active = tuple(jnp.where(r < 0, w, 0.0) for w, r in zip(rows.weight, residual))
    force = tuple(-w * r for w, r in zip(active, residual))
    qfrc_c = tuple(al.total(al.mul(j[i], f) for j, f in zip(rows.jac, force)) for i in range(n))
    ma = sym_matvec(mass, qacc, n)
    grad = tuple(al.sub(al.sub(m, s), c) for m, s, c in zip(ma, qfrc_smooth, qfrc_c))

    def direction(active, grad):
        hessian = {(i, j): al.add(mass[i, j], al.total(al.mul(w, al.mul(jr[i], jr[j])) for w, jr in zip(active, rows.jac)))
                   for i in range(n) for j in range(i, n)}
        return tuple(-x for x in cho_solve(cholesky(hessian, n), grad))

    search = stored(gate, direction, active, grad)
    slope = tuple(al.dot(j, search) for j in rows.jac)
    g1 = al.dot(search, al.vsub(ma, qfrc_smooth))
    g2 = al.dot(search, sym_matvec(mass, search, n))
    alpha = _line_search(rows.weight, residual, slope, g1, g2, ls_iterations)
    return tuple(al.add(a, al.mul(alpha, s)) for a, s in zip(qacc, search))


def solve(gate, mass: dict, qfrc_smooth, qacc_smooth, qacc_warmstart, rows: Rows, *,
          iterations: int, ls_iterations: int, warmstart: bool = True) -> Solution:
    """The constrained accelerations and the rows' forces."""
    qacc = qacc_smooth
    if warmstart:
        better = _cost(mass, qfrc_smooth, qacc_smooth, rows, qacc_warmstart) < _cost(
            mass, qfrc_smooth, qacc_smooth, rows, qacc_smooth)
        qacc = tuple(jnp.where(better, w, s) for w, s in zip(qacc_warmstart, qacc_smooth))
    step = lambda _, x: _newton_step(gate, mass, qfrc_smooth, rows, ls_iterations, x)
    qacc = jax.lax.fori_loop(0, iterations, step, tuple(jnp.asarray(x) for x in qacc))
    residual = _residuals(rows, qacc)
    force = tuple(jnp.where(r < 0, -w * r, 0.0) for w, r in zip(rows.weight, residual))
    qfrc_c = tuple(al.total(al.mul(j[i], f) for j, f in zip(rows.jac, force)) for i in range(len(qacc)))
    return Solution(qacc, force, qfrc_c)
