"""The quaternion helpers the sensors and Raibert use (`hardware.rotation`): MuJoCo C's rotations, and brax.math's
to the bit (what they replaced, so that no result moved)."""

import jax
import mujoco
import numpy as np
from brax import math as bmath

from hopper_mjx.hardware import rotation

RNG = np.random.default_rng(11)
# Unit quaternions, and a few a step's integration leaves slightly off unit length.
QUATS = np.concatenate([RNG.normal(size=(40, 4)), RNG.normal(size=(8, 4)) * 1.001]).astype(np.float32)
QUATS[:40] /= np.linalg.norm(QUATS[:40], axis=1, keepdims=True)
VECS = RNG.normal(size=(48, 3)).astype(np.float32)


def _c(fn, *args, size):
    out = np.zeros(size)
    fn(out, *(np.asarray(a, np.float64) for a in args))
    return out


def test_the_rotations_are_mujoco_cs():
    for q, v, p in zip(QUATS[:40], VECS, QUATS[::-1]):
        unit = q / np.linalg.norm(q)
        np.testing.assert_allclose(np.asarray(rotation.matrix(q)).ravel(), _c(mujoco.mju_quat2Mat, unit, size=9),
                                   atol=2e-6)
        np.testing.assert_allclose(np.asarray(rotation.rotate(v, q)), _c(mujoco.mju_rotVecQuat, v, q, size=3),
                                   atol=1e-5)
        np.testing.assert_allclose(np.asarray(rotation.multiply(p, q)), _c(mujoco.mju_mulQuat, p, q, size=4),
                                   atol=2e-6)
    # A quaternion off unit length still gives a rotation: orthonormal, determinant 1.
    for q in QUATS[40:]:
        m = np.asarray(rotation.matrix(q), np.float64)
        np.testing.assert_allclose(m @ m.T, np.eye(3), atol=1e-5)
        assert abs(np.linalg.det(m) - 1.0) < 1e-5


def test_they_are_brax_maths_to_the_bit_eager_and_batched():
    pairs = ((rotation.matrix, bmath.quat_to_3x3, (QUATS,)), (rotation.rotate, bmath.rotate, (VECS, QUATS)),
             (rotation.multiply, bmath.quat_mul, (QUATS, QUATS[::-1])))
    for ours, theirs, args in pairs:
        np.testing.assert_array_equal(np.asarray(jax.jit(jax.vmap(ours))(*args)),
                                      np.asarray(jax.jit(jax.vmap(theirs))(*args)))
        for one in zip(*args):
            np.testing.assert_array_equal(np.asarray(ours(*one)), np.asarray(theirs(*one)))
