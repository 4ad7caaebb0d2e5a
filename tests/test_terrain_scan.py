"""The height scan: MuJoCo's triangles (checked against MuJoCo C's own rays), exact on planes, and
the scan turning with the base's yaw."""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from hopper_mjx import model, terrain
from hopper_mjx.terrain.scan import height_at, measured_heights, normal_at, scan_points, yaw


def test_planes_are_exact_off_the_vertices():
    x, y = terrain.vertices((1.5, 1.0), (21, 31))
    heights = 0.2 * x - 0.3 * y + 0.05
    px, py = np.random.default_rng(0).uniform([-1.5, -1.0], [1.5, 1.0], (500, 2)).T
    got = height_at(jnp.asarray(heights), (1.5, 1.0), jnp.asarray(px), jnp.asarray(py))
    np.testing.assert_allclose(got, 0.2 * px - 0.3 * py + 0.05, atol=1e-6)  # float32


def test_the_scan_is_the_surface_mujoco_collides_with():
    """On rough ground (every cell a saddle), the scan at random points equals MuJoCo C's surface,
    probed with rays: the same triangles, not a bilinear patch (which misses by up to 18 mm here)."""
    t = terrain.parse("rough:amp=0.05,wavelength=0.3,seed=4,size=2x2,cell=0.1").terrain()
    m = model.load(terrain=t)
    d = mujoco.MjData(m)
    d.qpos[2] = 100.0  # the robot out of the rays' way
    mujoco.mj_forward(m, d)
    pts = np.random.default_rng(1).uniform(-0.98, 0.98, (300, 2))
    geom = np.zeros(1, np.int32)
    c = np.array([5.0 - mujoco.mj_ray(m, d, np.array([x, y, 5.0]), np.array([0, 0, -1.0]), None, 1, -1, geom)
                  for x, y in pts])
    with jax.enable_x64(True):
        ours = np.asarray(height_at(jnp.asarray(terrain.from_model(m).heights), t.size, jnp.asarray(pts[:, 0]),
                                    jnp.asarray(pts[:, 1])))
    np.testing.assert_allclose(ours, c, atol=1e-9)
    xs, ys = t.axes()
    u, v = np.interp(pts[:, 0], xs, np.arange(len(xs))), np.interp(pts[:, 1], ys, np.arange(len(ys)))
    c0, r0 = np.minimum(u.astype(int), len(xs) - 2), np.minimum(v.astype(int), len(ys) - 2)
    u, v, h = u - c0, v - r0, t.heights
    bilinear = ((1 - u) * (1 - v) * h[r0, c0] + u * (1 - v) * h[r0, c0 + 1] + (1 - u) * v * h[r0 + 1, c0]
                + u * v * h[r0 + 1, c0 + 1])
    assert np.abs(bilinear - c).max() > 5e-3  # the triangulation matters


def test_the_scan_turns_with_the_yaw_only():
    x, y = terrain.vertices((2.0, 2.0), (41, 41))
    heights = jnp.asarray(0.1 * x)  # a slope rising along world +x
    points = jnp.asarray(scan_points((3, 1), (0.5, 0.1)))  # behind, under, ahead of the base
    np.testing.assert_allclose(points, [[-0.5, 0], [0, 0], [0.5, 0]])
    pos = jnp.array([0.3, -0.2, 0.8])

    def quat(angle, axis):
        return jnp.concatenate([jnp.array([np.cos(angle / 2)]), np.sin(angle / 2) * jnp.asarray(axis, float)])

    facing_x = measured_heights(heights, (2.0, 2.0), pos, quat(0.0, [0, 0, 1]), points)
    np.testing.assert_allclose(facing_x, 0.1 * (0.3 + np.array([-0.5, 0, 0.5])), atol=1e-6)
    facing_y = measured_heights(heights, (2.0, 2.0), pos, quat(np.pi / 2, [0, 0, 1]), points)
    np.testing.assert_allclose(facing_y, 0.03, atol=1e-6)  # ahead is +y: level along the slope's contour
    pitched = measured_heights(heights, (2.0, 2.0), pos, quat(0.4, [0, 1, 0]), points)
    np.testing.assert_allclose(pitched, facing_x, atol=1e-6)  # pitch does not move the scan
    assert float(yaw(quat(2.0, [0, 0, 1]))) == pytest.approx(2.0, abs=1e-6)


def test_a_scan_batches_over_instances_each_on_its_own_grid():
    x, y = terrain.vertices((1.0, 1.0), (11, 11))
    grids = jnp.stack([jnp.asarray(0.1 * x), jnp.asarray(-0.2 * y)])
    points = jnp.asarray(scan_points())
    pos = jnp.array([[0.1, 0.2, 0.5], [0.1, 0.2, 0.5]])
    quat = jnp.array([[1.0, 0, 0, 0]] * 2)
    out = jax.vmap(measured_heights, in_axes=(0, None, 0, 0, None))(grids, (1.0, 1.0), pos, quat, points)
    assert out.shape == (2, 25)
    np.testing.assert_allclose(out[0], 0.1 * (0.1 + points[:, 0]), atol=1e-6)
    np.testing.assert_allclose(out[1], -0.2 * (0.2 + points[:, 1]), atol=1e-6)


def test_the_normal_is_mujoco_cs_contact_normal_on_a_face():
    """A small sphere pressed into rough ground inside a triangle: MuJoCo C's contact normal is the
    triangle's, and `normal_at` gives it (float64)."""
    t = terrain.parse("rough:amp=0.05,wavelength=0.3,seed=4,size=2x2,cell=0.1").terrain()
    spec = mujoco.MjSpec()
    floor = spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_PLANE, size=[1, 1, 0.1])
    terrain.to_spec(spec, floor, t)
    ball = spec.worldbody.add_body(pos=[0, 0, 1])
    ball.add_freejoint()
    ball.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.005, 0, 0])
    m = spec.compile()
    d = mujoco.MjData(m)
    heights = terrain.from_model(m).heights
    rng = np.random.default_rng(2)
    # Points well inside a triangle (its own u, v > 0.2 from the edges), so the sphere touches the face alone.
    cells = rng.integers(2, 17, (40, 2))
    u, v = rng.uniform(0.25, 0.75, (2, 40))
    upper = rng.random(40) < 0.5
    u, v = np.where(upper, np.minimum(u, v) * 0.6, u), np.where(upper, v, np.minimum(u, v) * 0.6)
    x, y = -1.0 + 0.1 * (cells[:, 0] + u), -1.0 + 0.1 * (cells[:, 1] + v)
    with jax.enable_x64(True):
        h = np.asarray(height_at(jnp.asarray(heights), t.size, jnp.asarray(x), jnp.asarray(y)))
        ours = np.asarray(normal_at(jnp.asarray(heights), t.size, jnp.asarray(x), jnp.asarray(y)))
    for k in range(40):
        d.qpos[:3] = [x[k], y[k], h[k]] + ours[k] * 0.004  # 1 mm into the face along its normal
        d.qpos[3:] = [1, 0, 0, 0]
        mujoco.mj_forward(m, d)
        assert d.ncon == 1
        np.testing.assert_allclose(d.contact[0].frame[:3], ours[k], atol=1e-9)


def test_the_observed_ground_is_the_scan_and_the_normal_under_the_contact():
    from types import SimpleNamespace

    from hopper_mjx.hardware import signals

    x, y = terrain.vertices((1.0, 1.0), (21, 21))
    heights = jnp.asarray(0.2 * x)  # a slope rising along +x: normal (-0.2, 0, 1) / |.|
    sensors = signals.SensorConfig(scan_counts=(3, 1), scan_spacing=(0.2, 0.1))
    d = SimpleNamespace(qpos=jnp.array([0.1, 0.0, 0.9, 1.0, 0, 0, 0, 0, 0, 0]))
    touching = signals.Contact(jnp.bool_(True), jnp.zeros(3), jnp.array([0.3, 0.1, 0.06]))
    sensed = signals.ground(heights, (1.0, 1.0), jnp.asarray(sensors.scan_points()), d, touching)
    np.testing.assert_allclose(sensed.scan, 0.2 * np.array([-0.1, 0.1, 0.3]), atol=1e-6)
    np.testing.assert_allclose(sensed.normal, np.array([-0.2, 0, 1]) / np.sqrt(1.04), atol=1e-6)
    np.testing.assert_allclose(sensed.height(0.3, 0.0), 0.06, atol=1e-6)
    off = signals.ground(heights, (1.0, 1.0), jnp.asarray(sensors.scan_points()), d,
                         touching._replace(flag=jnp.bool_(False)))
    np.testing.assert_array_equal(off.normal, 0.0)  # like the contact point: zeros off contact
