"""Per-instance robots: the variation spec, its seeded draws, and the batch run with a model per instance
against MuJoCo C given each instance's recorded model (mj_setConst recomputing what the masses imply)."""

import copy

import mujoco
import numpy as np
import pytest

from hopper_mjx import cli, registry, simulate
from hopper_mjx.control.base import HOLD_GAINS
from hopper_mjx.model.layout import Layout
from hopper_mjx.variation import draw
from hopper_mjx.variation.spec import Dist, Spec

# Masses, inertias, centre of mass, friction, damping, dry joint friction, armature, motor strength and the leg's
# morphology at once: what both engines take at run time.
EVERYTHING = ("body_mass=scale(0.8,1.2),body_inertia=scale(0.8,1.2),base_com=uniform(-0.02,0.02),"
              "foot_friction=uniform(0.4,1.0),dof_damping=uniform(0.02,0.5),dof_armature=0..0.01,"
              "actuator_gear=scale(0.8,1.2),shank_length=scale(0.8,1.2),thigh_length=0.3..0.4,foot_radius=0.02..0.04,"
              "dof_frictionloss=uniform(0,0.2)")


def test_a_spec_reads_every_distribution_and_prints_back_the_same():
    spec = Spec.parse("foot_friction=0.4..1, base_mass=scale(0.9,1.1),dof_damping=0.1,"
                      "dof_armature=loguniform(1e-4,1e-2),hip_mass=normal(0.5,0.05)")
    assert dict(spec.items) == {"foot_friction": Dist("uniform", 0.4, 1.0), "base_mass": Dist("scale", 0.9, 1.1),
                                "dof_damping": Dist("fixed", 0.1), "dof_armature": Dist("loguniform", 1e-4, 1e-2),
                                "hip_mass": Dist("normal", 0.5, 0.05)}
    assert Spec.parse(str(spec)) == spec
    assert spec.fields == {"pair_friction", "body_mass", "dof_damping", "dof_armature"}
    assert Spec.of({"foot_friction": "0.4..1.0", "dof_damping": 0.1}) == Spec.parse("foot_friction=0.4..1,"
                                                                                    "dof_damping=0.1")


@pytest.mark.parametrize("text, message", [
    ("wheel_mass=1", "unknown parameter 'wheel_mass'"),
    ("base_mass=uniform(2,1)", "bounds reversed"),
    ("base_mass=uniform(1,inf)", "non-finite bound"),
    ("base_mass=normal(5,-1)", "sigma must be >= 0"),
    ("dof_armature=loguniform(0,1)", "loguniform needs bounds > 0"),
    ("base_com=scale(0.9,1.1)", "base_com is an offset"),
    ("base_mass", "is not NAME=DISTRIBUTION"),
    ("base_mass=heavy", "cannot read 'heavy'"),
    ("base_mass=1,base_mass=2", "base_mass given twice"),
    # the controller's, motors' and sensors' parameters, read by the same parser
    ("kp=1", "unknown parameter 'kp'"),
    ("action_delay=10..2", "bounds reversed"),
    ("gyro_noise=0..inf", "non-finite"),
    ("gyro_bias=scale(0.9,1.1)", "gyro_bias is an offset"),
])
def test_a_bad_spec_is_refused_naming_what_is_wrong(text, message):
    with pytest.raises(ValueError, match=message):
        Spec.parse(text)


def test_draws_are_the_seeds_and_land_where_the_parameter_says(mj_model):
    spec = Spec.parse(EVERYTHING + ",base_mass=5.5")
    a, b = draw.draw(spec, mj_model, 64, seed=3), draw.draw(spec, mj_model, 64, seed=3)
    c = draw.draw(spec, mj_model, 64, seed=4)
    assert a.keys() == b.keys() == c.keys() == spec.fields
    for field in a:
        assert a[field].shape == (64, *np.shape(getattr(mj_model, field)))
        np.testing.assert_array_equal(a[field], b[field])
        assert not np.allclose(a[field], c[field]), field
    m = mj_model
    lay = Layout.of(m)
    base = int(m.jnt_bodyid[0])
    assert (a["body_mass"][:, base] == 5.5).all()  # given later than body_mass: it wins on the base
    others = [b for b in range(2, m.nbody)]
    ratio = a["body_mass"][:, others] / m.body_mass[others]
    assert ratio.min() >= 0.8 and ratio.max() <= 1.2 and ratio.std() > 0.05
    assert (a["body_mass"][:, 0] == 0).all()  # the world body is no link
    # One factor per link for its three principal axes: the inertia stays a physical one.
    factor = a["body_inertia"][:, 1:] / m.body_inertia[1:]
    np.testing.assert_allclose(factor, factor[:, :, :1].repeat(3, axis=2))
    offset = a["body_ipos"][:, base] - m.body_ipos[base]
    assert np.abs(offset).max() <= 0.02 and np.abs(offset).min() < 0.02 and offset.std(axis=0).min() > 0.005
    foot = a["pair_friction"][:, [p for p in range(m.npair) if m.pair_geom2[p] == lay.foot_geom][0]]
    np.testing.assert_array_equal(foot[:, 0], foot[:, 1])  # both sliding directions, one draw
    assert 0.4 <= foot[:, 0].min() and foot[:, 0].max() <= 1.0
    np.testing.assert_array_equal(foot[:, 2:], np.broadcast_to(m.pair_friction[0, 2:], (64, 3)))
    assert (a["dof_damping"][:, :6] == 0).all()  # the free base is not a joint
    gear = a["actuator_gear"]
    assert (gear[:, :, 1:] == 0).all() and 0.8 <= (gear[:, :, 0] / m.actuator_gear[:, 0]).min()
    # A length keeps the offset's direction: the shank link 0.3..0.4 below the knee's parent, the foot link the
    # URDF's shank times U(0.8, 1.2); the foot radius is the sphere's size, nothing else moves.
    shank, foot = int(m.joint("kfe_joint").bodyid[0]), int(m.geom_bodyid[lay.foot_geom])
    pos = a["body_pos"]
    assert (pos[:, [shank, foot], :2] == 0).all() and -0.4 <= pos[:, shank, 2].min() and pos[:, shank, 2].max() <= -0.3
    ratio = pos[:, foot, 2] / m.body_pos[foot, 2]
    assert 0.8 <= ratio.min() and ratio.max() <= 1.2 and ratio.std() > 0.05
    others = [b for b in range(m.nbody) if b not in (shank, foot)]
    np.testing.assert_array_equal(pos[:, others], np.broadcast_to(m.body_pos[others], (64, len(others), 3)))
    radius = a["geom_size"][:, lay.foot_geom]
    assert 0.02 <= radius[:, 0].min() and radius[:, 0].max() <= 0.04
    assert (radius[:, 1:] == m.geom_size[lay.foot_geom, 1:]).all()
    assert draw.columns(spec, m, a)["shank_length"] == pytest.approx(-pos[:, foot, 2])


def test_adding_a_parameter_leaves_the_others_draws_as_they_were(mj_model):
    one = draw.draw(Spec.parse("foot_friction=0.4..1"), mj_model, 16, seed=0)
    two = draw.draw(Spec.parse("dof_damping=0..1,foot_friction=0.4..1"), mj_model, 16, seed=0)
    np.testing.assert_array_equal(one["pair_friction"], two["pair_friction"])


def test_a_value_outside_the_parameters_range_is_refused_naming_the_instance(mj_model):
    with pytest.raises(ValueError, match=r"base_mass drew a value of -[\d.]+ kg for instance \d+; it must be > 0"):
        draw.draw(Spec.parse("base_mass=normal(5,5)"), mj_model, 64, seed=0)


def test_a_distribution_reaching_outside_the_range_is_refused_whatever_it_draws(mj_model):
    """A bounded distribution is refused by its range, not by its draws: uniform(-1,1) for a friction drew a
    valid 0.07 for one robot at seed 0 and passed, where at four robots it was refused. A normal, unbounded, is
    judged by its draws (above); a range within the parameter's passes; a fixed value outside it is refused."""
    once = draw.draw(Spec.parse("foot_friction=normal(0.5,0.3)"), mj_model, 1, seed=0)["pair_friction"]
    assert np.all(once >= 0)  # a normal that draws within the range passes
    for n in (1, 4):
        with pytest.raises(ValueError, match=r"^foot_friction=uniform\(-1,1\) can draw a value of -1; it must be "
                                             r">= 0 and <= 10$"):
            draw.draw(Spec.parse("foot_friction=-1..1"), mj_model, n, seed=0)
    with pytest.raises(ValueError, match="foot_friction=11 sets a value of 11; it must be >= 0 and <= 10"):
        draw.draw(Spec.parse("foot_friction=11"), mj_model, 4, seed=0)
    with pytest.raises(ValueError, match=r"thigh_length=scale\(0.5,20\) can draw a value of [\d.]+ m; it must be "
                                         r"> 0 and <= 1"):
        draw.draw(Spec.parse("thigh_length=scale(0.5,20)"), mj_model, 1, seed=0)
    with pytest.raises(ValueError, match=r"action_delay=uniform\(-1,5\) can draw a value of -1 ms"):
        draw.draw_controls(Spec.parse("action_delay=-1..5"), mj_model, 1, 0)
    assert draw.draw(Spec.parse("foot_friction=0..10"), mj_model, 2, seed=0)["pair_friction"].max() <= 10


def test_every_parameter_names_a_field_and_elements_of_the_model(mj_model):
    for name, par in registry.PARAMETERS.items():
        assert hasattr(mj_model, par.field), name
        assert draw.rows(mj_model, par.elements), name


def test_the_constants_are_mujocos_own_for_each_instance(mj_model):
    """with_constants gives what mj_setConst gives on the instance's model (and the nominal ones unvaried)."""
    drawn = draw.draw(Spec.parse("body_mass=scale(0.5,2),dof_armature=0..0.05"), mj_model, 3, seed=1)
    full = draw.with_constants(mj_model, drawn)
    for i in range(3):
        m = draw.instance_model(mj_model, drawn, i)
        for c in draw.CONSTANTS:
            np.testing.assert_allclose(full[c][i], getattr(m, c), rtol=1e-12)
    # The masses do move the constraint's regularisation (what MJX's contact rows read).
    assert np.abs(full["body_invweight0"] / np.maximum(mj_model.body_invweight0, 1e-12) - 1).max() > 0.05
    assert draw.with_constants(mj_model, {}) == {}


def _c_path(m: mujoco.MjModel, gravity, qpos0, steps: int, lay: Layout, limp: bool = False) -> np.ndarray:
    """Base position (steps, 3) of MuJoCo C stepping `m` from qpos0 under the hold controller, which
    knows the nominal robot's layout `lay` only (its gear: a varied gear scales the torque it applies),
    or `limp`."""
    m.opt.gravity[:] = gravity
    d = mujoco.MjData(m)
    d.qpos[:] = qpos0
    joints, dofs, acts = list(lay.joint_qpos), list(lay.joint_dof), list(lay.actuator_of_joint)
    target, limit = d.qpos[joints].copy(), np.asarray(lay.effort_limit)
    base = []
    for _ in range(steps):
        base.append(d.qpos[:3].copy())
        torque = HOLD_GAINS["p"] * (target - d.qpos[joints]) - HOLD_GAINS["d"] * d.qvel[dofs]
        torque *= not limp
        d.ctrl[acts] = np.clip(torque, -limit, limit) / np.asarray(lay.gear)
        mujoco.mj_step(m, d)
    return np.array(base)


def _simulate(out, engine: str, spec: str) -> dict:
    """`simulate --randomize spec` on `engine`: 8 instances at 9.81 and 1.62 holding their stance through touchdown."""
    argv = ["--gravity", "9.81,1.62", "--num", "4", "--duration", "0.4", "--controller", "hold", "--rate", "1000",
            "--engine", engine, "--seed", "5", "--randomize", spec, "--out", str(out)]
    assert simulate.main(argv) == 0
    return dict(np.load(out))


def _follows_mujoco_c(mj_model, f: dict, spec: str, engine: str) -> None:
    """Each instance of the recording `f`, its recorded model set into MuJoCo C's (mj_setConst): the base path
    within 1e-3 m through touchdown, where the nominal robot's is over 5e-3 m away."""
    drawn = {k.removeprefix("model_"): v for k, v in f.items() if k.startswith("model_")}
    assert set(drawn) == Spec.parse(spec).fields
    steps, lay = f["qpos"].shape[1], Layout.of(mj_model)
    apart = []
    for i in range(len(f["gravity"])):
        touchdown = int(np.argmax(f["contact"][i]))
        assert f["contact"][i].any() and touchdown < steps - 100, "the comparison must include touchdown"
        path = _c_path(draw.instance_model(mj_model, drawn, i), f["gravity"][i], f["qpos"][i, 0], steps, lay)
        err = np.abs(path - f["qpos"][i, :, :3]).max()
        assert err < 1e-3, f"instance {i}: {engine} and MuJoCo C differ by {err:.2e} m"
        nominal = _c_path(copy.deepcopy(mj_model), f["gravity"][i], f["qpos"][i, 0], steps, lay)
        apart.append(np.abs(nominal - f["qpos"][i, :, :3]).max())
    # Not the nominal robot: the variation moved the paths well beyond the tolerance.
    assert max(apart) > 5e-3, apart


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    return _simulate(tmp_path_factory.mktemp("vary") / "run.npz", "mjx", EVERYTHING)


def test_each_instance_follows_mujoco_c_given_its_recorded_model(mj_model, recorded):
    _follows_mujoco_c(mj_model, recorded, EVERYTHING, "mjx")


def test_same_seed_same_draws_and_results(recorded, tmp_path):
    again = _simulate(tmp_path / "again.npz", "mjx", EVERYTHING)
    assert again.keys() == recorded.keys()
    for k in again:
        np.testing.assert_array_equal(again[k], recorded[k], err_msg=k)


def test_auto_keeps_the_chain_for_every_parameter_and_refuses_a_field_it_cannot_take(mj_model, capsys):
    from hopper_mjx.sim import Sim
    from hopper_mjx.variation.spec import check_engine_varies

    batch = cli.check_batch(simulate.parser().parse_args(["--randomize", "foot_friction=0.5,dof_frictionloss=0.1"]))
    sim = Sim(mj_model, engine=batch.physics.engine, varies=batch.physics.variation.fields)
    assert sim.engine.name == "chain" and "uses mjx" not in capsys.readouterr().err
    # Every parameter's field is one the chain takes at run time; a model field no parameter sets is refused.
    assert {p.field for p in registry.PARAMETERS.values()} <= registry.CHAIN_VARIES
    with pytest.raises(ValueError, match="the chain engine cannot vary jnt_stiffness per instance yet"):
        check_engine_varies("chain", frozenset({"jnt_stiffness", "dof_frictionloss"}))


def test_friction_and_damping_leave_mujocos_constants_as_they_are(mj_model):
    drawn = draw.draw(Spec.parse("foot_friction=0.4..1,dof_damping=0..1,dof_frictionloss=0..0.3"), mj_model, 4,
                           seed=0)
    assert draw.with_constants(mj_model, drawn).keys() == drawn.keys()
    for i in range(4):
        m = draw.instance_model(mj_model, drawn, i)
        for c in draw.CONSTANTS:
            np.testing.assert_array_equal(getattr(m, c), getattr(mj_model, c), err_msg=c)


@pytest.fixture(scope="module")
def on_chain(tmp_path_factory):
    """Every parameter, dry joint friction among them, on the chain (each instance from its own stance)."""
    return _simulate(tmp_path_factory.mktemp("vary") / "chain.npz", "chain", EVERYTHING)


def test_the_chain_takes_each_instances_robot_as_mujoco_c_does(mj_model, on_chain):
    _follows_mujoco_c(mj_model, on_chain, EVERYTHING, "chain")


def test_the_varied_program_is_the_same_whatever_order_its_fields_come_in(mj_model):
    """The fields a batch varies are a set, whose order changes with each process's string hashing: the program
    traced from them (and so its persistent-cache key) must not, or every run compiles it afresh."""
    import jax

    from hopper_mjx.engine import chain

    spec = Spec.parse(EVERYTHING)
    values = draw.with_constants(mj_model, draw.draw(spec, mj_model, 1, seed=0))
    one = {field: v[0] for field, v in values.items()}
    engine = chain.make(mj_model, varies=spec.fields)
    traced = lambda: str(jax.make_jaxpr(lambda v: engine.vary(engine.model, v))(one))
    first = traced()
    for order in (reversed, sorted):
        engine.settable = dict(order(list(engine.settable.items())))
        assert traced() == first, order.__name__
    assert first.count("slice") >= 20  # each drawn entry is sliced out of its field's array once, here
