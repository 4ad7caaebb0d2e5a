"""Unit quaternions [w, x, y, z] as the sensors and controllers use them: the rotation matrix, a vector turned,
and the product.

Our own few lines rather than `brax.math`: importing brax imports MJX with it (about 0.8 s of every process's
start), which the chain engine's commands never use. The arithmetic is evaluated in the order brax's is, so a
result is the same to the last bit (`make sweep`'s results.csv stays byte for byte).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def matrix(q: jax.Array) -> jax.Array:
    """(3, 3) body -> world rotation of `q` (normalised here: a quaternion a step's integration left slightly
    off unit length still gives a rotation)."""
    w, x, y, z = q
    scale = 2.0 / jnp.dot(q, q)
    sx, sy, sz = x * scale, y * scale, z * scale
    wx, wy, wz = w * sx, w * sy, w * sz
    xx, xy, xz = x * sx, x * sy, x * sz
    yy, yz, zz = y * sy, y * sz, z * sz
    return jnp.array([[1.0 - (yy + zz), xy - wz, xz + wy],
                      [xy + wz, 1.0 - (xx + zz), yz - wx],
                      [xz - wy, yz + wx, 1.0 - (xx + yy)]])


def rotate(v: jax.Array, q: jax.Array) -> jax.Array:
    """(3,) `v` turned by the unit quaternion `q`: 2(u·v)u + (w² - u·u)v + 2w(u × v), u its vector part."""
    w, u = q[0], q[1:]
    turned = 2 * (jnp.dot(u, v) * u) + (w * w - jnp.dot(u, u)) * v
    return turned + 2 * w * jnp.cross(u, v)


def multiply(p: jax.Array, q: jax.Array) -> jax.Array:
    """The Hamilton product p ⊗ q (q's rotation first, then p's)."""
    return jnp.array([
        p[0] * q[0] - p[1] * q[1] - p[2] * q[2] - p[3] * q[3],
        p[0] * q[1] + p[1] * q[0] + p[2] * q[3] - p[3] * q[2],
        p[0] * q[2] - p[1] * q[3] + p[2] * q[0] + p[3] * q[1],
        p[0] * q[3] + p[1] * q[2] - p[2] * q[1] + p[3] * q[0],
    ])
