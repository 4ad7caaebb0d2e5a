"""Physics on terrain, against MuJoCo C on the exported model: the flat spec is today's floor, a body
resting on the height field sits at its height, and the `mjx` engine (the reference on terrain) follows
MuJoCo C's limp drops onto rough ground, a step's edge and a block at Earth, Mars and Moon gravity."""

import mujoco
import numpy as np
import pytest

from hopper_mjx import model, terrain
from hopper_mjx.model import __main__ as model_main
from hopper_mjx.model.robot import stance_qpos

GRAVITIES = (9.81, 3.71, 1.62)


def test_the_flat_spec_is_todays_model():
    today, flat = model.load(), model.load(terrain=terrain.parse("flat").terrain())
    for name in ("geom_type", "geom_size", "geom_pos", "pair_geom1", "pair_geom2", "pair_dim", "pair_friction",
                 "body_mass", "opt.timestep"):
        obj_a, obj_b = (m.opt if name.startswith("opt.") else m for m in (today, flat))
        field = name.removeprefix("opt.")
        assert np.array_equal(getattr(obj_a, field), getattr(obj_b, field)), name
    assert flat.nhfield == 0


def rest_height(t: terrain.Terrain | None, xy, r: float = 0.03, mass: float = 6.8) -> tuple[float, float]:
    """MuJoCo C: a free sphere of the foot's radius and the robot's mass, set down touching the ground at
    `xy` (the plane, or `t` through `terrain.to_spec`), after 3 s; (its centre's height, its speed)."""
    spec = mujoco.MjSpec()
    floor = spec.worldbody.add_geom(name=model.FLOOR_GEOM, type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 0.05])
    ground = 0.0
    if t is not None:
        terrain.to_spec(spec, floor, t)
        xs, ys = t.axes()
        ground = t.heights[np.argmin(abs(ys - xy[1])), np.argmin(abs(xs - xy[0]))]
    body = spec.worldbody.add_body(pos=[xy[0], xy[1], ground + r - 1e-4])  # no impact: it is set down
    body.add_freejoint()
    body.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[r, 0, 0], mass=mass)
    m = spec.compile()
    d = mujoco.MjData(m)
    mujoco.mj_step(m, d, 3000)
    return float(d.qpos[2]), float(np.abs(d.qvel).max())


@pytest.mark.parametrize("spec, height", [("steps:height=0.07,x=-0.5,depth=1", 0.07),
                                          ("obstacle:height=0.15,x=-0.3,length=0.6", 0.15)])
def test_a_body_resting_on_the_height_field_sits_at_its_height(spec, height):
    """On a raised patch a sphere rests exactly `height` above where it rests on the plane (MuJoCo's soft
    contact sinks it 0.37 mm into both) inside a triangle, where MuJoCo C makes one contact; on a vertex
    shared by six triangles it makes several, each as stiff as one, and sinks less (0.28 mm higher, measured)."""
    t = terrain.parse(spec).terrain()
    on_plane, still = rest_height(None, (0.013, 0.021))
    assert still < 1e-9 and 0.03 - 1e-3 < on_plane < 0.03
    for xy in ((0.013, 0.021), (0.03, 0.01), (-0.21, 0.255)):  # inside triangles, both kinds (not on an edge)
        z, still = rest_height(t, xy)
        assert z - on_plane == pytest.approx(height, abs=1e-9) and still < 1e-6, xy
    z, still = rest_height(t, (0.0, 0.0))  # a vertex
    assert height + 2e-4 < z - on_plane < height + 3.5e-4 and still < 1e-6


def start_qpos(m: mujoco.MjModel, t: terrain.Terrain) -> np.ndarray:
    """The default stance lifted by the highest ground within 0.1 m of the start (the foot starts 5 cm over it)."""
    q = stance_qpos(m)
    xs, ys = t.axes()
    q[2] += max(0.0, t.heights[(np.abs(ys) < 0.1)[:, None] & (np.abs(xs) < 0.1)[None, :]].max())
    return q


# The ground under the start: rough everywhere, a step's edge at x = 0, a 10 cm block under the foot.
DROPS = {"rough": "rough:amp=0.03,wavelength=0.4,seed=1", "steps": "steps:height=0.05,x=0",
         "obstacle": "obstacle:height=0.1,x=-0.05,length=0.1"}
DROP_SECONDS = 0.6  # the first touchdown and the fall that follows, before the limp leg folds on its own
# Measured max |base path, mjx - C| over the 0.6 s, at 9.81, 3.71, 1.62 m/s² (the test prints them):
# rough 9.5e-4, 6.6e-6, 9.5e-7 m; steps 1.6e-3, 5.7e-4, 1.8e-4 m; obstacle 1.6e-3, 8.2e-4, 7.6e-7 m.
# MJX collides with the hfield's prisms by its own convex routine (and Newton with 4 iterations), C by
# its general convex collision (GJK/EPA): the paths part at the touchdown and grow apart as the limp robot topples
# (by 1 s at 9.81: up to 0.13 m on the block). The bound is twice the worst measured.
PATH_TOLERANCE = 3.5e-3  # m


@pytest.mark.slow
# The step only: each terrain compiles MJX's hfield program anew (about 2 minutes); the chain's test below runs all
# three drops against C in one program. The other two were measured with every terrain listed here (numbers above).
@pytest.mark.parametrize("name", ["steps"])
def test_mjx_follows_mujoco_c_on_the_exported_terrain(name, tmp_path, capsys):
    from hopper_mjx.hardware.signals import SensorConfig
    from hopper_mjx.sim import Sim, gravity_vectors

    path = tmp_path / f"{name}.xml"
    assert model_main.main(["--export", str(path), "--terrain", DROPS[name]]) == 0
    exported = mujoco.MjModel.from_xml_path(str(path))
    q0 = start_qpos(exported, terrain.from_model(exported))
    sim = Sim(exported, engine="mjx")
    _, traj = sim.run(gravity_vectors(GRAVITIES), duration=DROP_SECONDS, sensors=SensorConfig.uniform(1000), qpos=q0)
    ours = np.asarray(traj.qpos)[:, :, :3]
    worst = []
    for i, g in enumerate(GRAVITIES):
        m = mujoco.MjModel.from_xml_path(str(path))
        m.opt.gravity[:] = (0.0, 0.0, -g)
        d = mujoco.MjData(m)
        d.qpos[:] = q0
        c = []
        for _ in range(ours.shape[1]):
            c.append(d.qpos[:3].copy())
            mujoco.mj_step(m, d)
        c = np.array(c)
        assert c[:, 2].min() < q0[2] - 0.05  # it fell onto the terrain
        worst.append(float(np.linalg.norm(ours[i] - c, axis=1).max()))
    with capsys.disabled():
        print(f"\n{name}: max |base path mjx - C| over {DROP_SECONDS} s at g = {GRAVITIES}: "
              + ", ".join(f"{w:.2e}" for w in worst) + " m")
    assert max(worst) < PATH_TOLERANCE


@pytest.mark.slow
def test_mjx_takes_the_height_field_as_a_traced_input():
    """MJX's `hfield_data` is a jax.Array of its model: one compiled forward, vmapped over two grids, stands
    one foot on a 5 cm platform and leaves the other in the air (what per-instance terrain will build on)."""
    import jax
    import jax.numpy as jnp

    from hopper_mjx import engine

    m = model.load(terrain=terrain.parse("steps:height=0.05,x=-0.5,depth=1").terrain())
    eng = engine.make("mjx", m)
    assert isinstance(eng.model.hfield_data, jax.Array)
    platform = jnp.asarray(eng.model.hfield_data)
    grids = jnp.stack([platform, jnp.zeros_like(platform)])  # with the platform, and level at its foot
    q = stance_qpos(m, clearance=0.05 - 0.002)  # 2 mm into the platform's top

    def foot(data_h):
        mdl = eng.model.replace(hfield_data=data_h)
        d = eng.forward(mdl, eng.make_data(jnp.asarray(q, jnp.float32), jnp.zeros(m.nv)), jnp.array([0, 0, -9.81]))
        return eng.foot_contact(mdl, d)

    flag, _, pos = jax.jit(jax.vmap(foot))(grids)
    assert flag.tolist() == [True, False]
    assert float(pos[0, 2]) == pytest.approx(0.05 - 0.001, abs=2e-4)  # midway through the overlap


def test_chain_follows_mujoco_c_on_the_exported_terrains(tmp_path, capsys):
    """The chain engine (float32, the foot's and the box's contacts on the height field) against C on each
    exported model: the same limp drops, the three grounds given to one compiled batch as its instances'
    heights. Its paths through the touchdowns stay within 1e-3 m of C's."""
    from hopper_mjx.hardware.signals import SensorConfig
    from hopper_mjx.sim import Sim, gravity_vectors

    exported, starts, grounds = {}, {}, {}
    for name, spec in DROPS.items():
        path = tmp_path / f"{name}.xml"
        assert model_main.main(["--export", str(path), "--terrain", spec]) == 0
        exported[name] = path
        t = terrain.from_model(mujoco.MjModel.from_xml_path(str(path)))
        starts[name], grounds[name] = start_qpos(mujoco.MjModel.from_xml_path(str(path)), t), t.heights
    cases = [(name, g) for name in DROPS for g in GRAVITIES]
    sim = Sim(mujoco.MjModel.from_xml_path(str(exported["rough"])), engine="chain")
    _, traj = sim.run(gravity_vectors([g for _, g in cases]), duration=DROP_SECONDS,
                      sensors=SensorConfig.uniform(1000), qpos=np.stack([starts[n] for n, _ in cases]),
                      ground=np.stack([grounds[n] for n, _ in cases]))
    ours = np.asarray(traj.qpos)[:, :, :3]
    worst = {}
    for i, (name, g) in enumerate(cases):
        m = mujoco.MjModel.from_xml_path(str(exported[name]))
        m.opt.gravity[:] = (0.0, 0.0, -g)
        d = mujoco.MjData(m)
        d.qpos[:] = starts[name]
        c = []
        for _ in range(ours.shape[1]):
            c.append(d.qpos[:3].copy())
            mujoco.mj_step(m, d)
        c = np.array(c)
        assert c[:, 2].min() < starts[name][2] - 0.05  # it fell onto the terrain
        worst[name, g] = float(np.linalg.norm(ours[i] - c, axis=1).max())
    with capsys.disabled():
        for name in DROPS:
            print(f"\n{name}: max |base path chain - C| over {DROP_SECONDS} s at g = {GRAVITIES}: "
                  + ", ".join(f"{worst[name, g]:.2e}" for g in GRAVITIES) + " m")
    assert max(worst.values()) < 1e-3
