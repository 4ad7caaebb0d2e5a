"""Scalar algebra for the chain engine: 3-vectors and 3x3 matrices as tuples of scalars.

Every entry is either a Python float (a model constant, known at trace time) or a traced
scalar of one instance. `vmap` turns each traced scalar into one contiguous vector over
instances, which XLA:CPU vectorises well, where (3,)/(3,3) arrays would become short minor
axes. Products with constant 0 and 1 are folded here, at trace time: XLA does not fold
`x * 0.0` (NaN semantics), and the chain's axes, offsets and identity rotations are full of them.
Matrices are row-major 9-tuples.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

Scalar = float | jax.Array
Vec = tuple  # 3 scalars
Mat = tuple  # 9 scalars, row-major


def is_const(x) -> bool:
    return isinstance(x, (int, float))


def add(a, b):
    if is_const(a) and a == 0:
        return b
    if is_const(b) and b == 0:
        return a
    return a + b


def sub(a, b):
    if is_const(b) and b == 0:
        return a
    if is_const(a) and a == 0:
        return neg(b)
    return a - b


def neg(a):
    return -a


def mul(a, b):
    if is_const(a) and is_const(b):
        return float(a * b)
    if is_const(b):
        a, b = b, a
    if is_const(a):
        if a == 0:
            return 0.0
        if a == 1:
            return b
        if a == -1:
            return -b
    return a * b


def total(terms) -> Scalar:
    """Sum, skipping constant zeros."""
    out = 0.0
    for t in terms:
        out = add(out, t)
    return out


def dot(a: Vec, b: Vec) -> Scalar:
    return total(mul(x, y) for x, y in zip(a, b))


def vadd(a: Vec, b: Vec) -> Vec:
    return tuple(add(x, y) for x, y in zip(a, b))


def vsub(a: Vec, b: Vec) -> Vec:
    return tuple(sub(x, y) for x, y in zip(a, b))


def vscale(s: Scalar, a: Vec) -> Vec:
    return tuple(mul(s, x) for x in a)


def cross(a: Vec, b: Vec) -> Vec:
    return (
        sub(mul(a[1], b[2]), mul(a[2], b[1])),
        sub(mul(a[2], b[0]), mul(a[0], b[2])),
        sub(mul(a[0], b[1]), mul(a[1], b[0])),
    )


def column(m: Mat, j: int) -> Vec:
    return (m[j], m[3 + j], m[6 + j])


def matvec(m: Mat, v: Vec) -> Vec:
    return tuple(dot(m[3 * i : 3 * i + 3], v) for i in range(3))


def mattvec(m: Mat, v: Vec) -> Vec:
    """m^T v."""
    return tuple(dot(column(m, i), v) for i in range(3))


def matmul(a: Mat, b: Mat) -> Mat:
    return tuple(dot(a[3 * i : 3 * i + 3], column(b, j)) for i in range(3) for j in range(3))


def sym_matvec(s: tuple, v: Vec) -> Vec:
    """Symmetric 3x3 stored as (xx, yy, zz, xy, xz, yz), times v."""
    xx, yy, zz, xy, xz, yz = s
    return (
        total((mul(xx, v[0]), mul(xy, v[1]), mul(xz, v[2]))),
        total((mul(xy, v[0]), mul(yy, v[1]), mul(yz, v[2]))),
        total((mul(xz, v[0]), mul(yz, v[1]), mul(zz, v[2]))),
    )


def rotate_sym(r: Mat, s: tuple) -> tuple:
    """r s r^T for symmetric s (6-tuple), as a 6-tuple."""
    full = sym_full(s)
    rs = matmul(r, full)
    pick = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
    return tuple(dot(rs[3 * i : 3 * i + 3], r[3 * j : 3 * j + 3]) for i, j in pick)


def sym_full(s: tuple) -> Mat:
    xx, yy, zz, xy, xz, yz = s
    return (xx, xy, xz, xy, yy, yz, xz, yz, zz)


def quat_to_mat(w, x, y, z) -> Mat:
    """Rotation matrix of a unit quaternion [w, x, y, z] (numbers or traced scalars)."""
    return (
        w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z,
    )


def const_mat(m) -> Mat:
    """A NumPy 3x3 as a constant 9-tuple of Python floats."""
    return tuple(float(v) for v in m.reshape(9))


def axis_rotation(axis: Vec, c: Scalar, s: Scalar) -> Mat:
    """Rotation by an angle (cos c, sin s) about a constant unit axis (Rodrigues, folded)."""
    skew = (0.0, -axis[2], axis[1], axis[2], 0.0, -axis[0], -axis[1], axis[0], 0.0)
    out = []
    for i in range(3):
        for j in range(3):
            outer = axis[i] * axis[j]
            ident = 1.0 if i == j else 0.0
            out.append(total((outer, mul(ident - outer, c), mul(skew[3 * i + j], s))))
    return tuple(out)


def sqrt(x):
    return math.sqrt(x) if is_const(x) else jnp.sqrt(x)


def vector(values, dtype) -> jax.Array:
    """Scalars (numbers or traced) as one array of `dtype`."""
    return jnp.stack([jnp.asarray(v, dtype) for v in values])
