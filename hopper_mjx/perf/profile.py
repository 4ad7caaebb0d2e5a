"""python -m hopper_mjx.perf.profile: where the batched step spends its time, per engine.

    python -m hopper_mjx.perf.profile --num 256 --engine mjx
    python -m hopper_mjx.perf.profile --num 256 --engine chain

mjx:
An ablation of the compiled, fused step as the core runs it (vmapped over one
chunk of instances, XLA:CPU options of `Sim`, a `lax.scan` over `--steps`
steps): the same rollout is timed with MuJoCo's contact stage disabled, then
with every constraint disabled. The differences are what contacts (collision,
contact rows and their share of the solve) and the rest of the constraint
pipeline (joint-limit rows, the Newton solve itself) cost; what remains is the
smooth dynamics (kinematics, inertia, bias forces, actuation, integration).
Each rollout starts from the same standing batch (foot on the floor, after
`--settle` steps holding the stance) and keeps each motor's last torque of the
hold; without contacts the robots fall through the floor, which is what a
timing ablation asks for.

chain: the same standing batch stepped by the chain engine cut after each of
its stages in turn (kinematics; mass matrix, bias forces and actuation;
constraint rows; the solve's setup with the integration; the Newton iterations).
Each cut keeps every output of its stages alive, fed to the next step's positions
and velocities (so that no stage of the positions alone is hoisted out of the
timed loop), so the differences are what each stage costs; a cut may cost more
than the step it stands for, since the whole step computes only the outputs it
uses (on the plane the setup then reads below 0). The setup is timed as the
whole step with MuJoCo's iteration cap (`opt.iterations`) at 0: the warm start's
choice, the first gradient and the integration, no Newton iteration. Then
the Newton iterations (MuJoCo's solver_niter) over the same steps: how many
each instance needs, how many MuJoCo C runs from the same states (whether
they are the physics' own), and how many its batch runs, since a vmapped loop
runs until the batch's slowest instance is done.

Both: the kernels one step launches, counted from its compiled program (`perf.kernels`):
XLA:CPU pays a fixed cost for each, so their number bounds how fast a small step can be. And
the step's jaxpr equations by the engine function that wrote them: what tracing, lowering and
compiling the step cost grows with.
"""

from __future__ import annotations

import collections
import copy
import sys
import time

import mujoco
import numpy as np

from hopper_mjx import cli
from hopper_mjx.perf import kernels
from hopper_mjx.scenario import Physics
from hopper_mjx.shell import jaxsetup, process

REPEATS = 5  # timed rollouts per variant; the best counts (noise only adds time)
VARIANTS = (
    ("full step", 0),
    ("no contacts", mujoco.mjtDisableBit.mjDSBL_CONTACT),
    ("no constraints", mujoco.mjtDisableBit.mjDSBL_CONSTRAINT),
)


# The solve's setup is cut with the integration: cut before the integration, the state would stand still, and a
# solve warm-started from its own answer of the step before has nothing left to do. So the setup is the whole
# step with the iteration cap at 0 (`without_iterations`), and the Newton iterations what the full step adds.
CHAIN_STAGES = ("kinematics", "mass matrix, bias forces, actuation", "constraint rows",
                "solve's setup (no Newton iteration), integration", "Newton iterations")


def best_cost(step, model, data, gravity, steps: int, options: dict) -> float:
    """µs per instance-step of a compiled vmapped scan of step(model, data, gravity) from data. The engine's
    `model` is an argument of the compiled function, as the core passes it: as a constant the compiler would fold
    the chain's stored stages away and time another program (several times slower on a terrain). `options`: the
    engine's XLA:CPU options (`Engine.compiler_options`), as the core compiles it."""
    import jax

    from hopper_mjx.engine import BATCH_AXIS

    def one(m, d, g):
        return jax.lax.scan(lambda d, _: (step(m, d, g), None), d, None, length=steps)[0]

    f = jax.jit(jax.vmap(one, in_axes=(None, 0, 0), axis_name=BATCH_AXIS),  # as the core vmaps
                compiler_options=options)
    jax.block_until_ready(f(model, data, gravity))  # compiles
    best = np.inf
    for _ in range(REPEATS):
        start = time.perf_counter()
        jax.block_until_ready(f(model, data, gravity))
        best = min(best, time.perf_counter() - start)
    return best / (gravity.shape[0] * steps) * 1e6


def rollout_cost(mj_model, qpos, qvel, ctrl, gravity, steps: int) -> float:
    """µs per instance-step of mjx.step from (qpos, qvel), its motors held at `ctrl`."""
    import jax
    from mujoco import mjx

    model = mjx.put_model(mj_model)
    data = jax.vmap(lambda q, v, u: mjx.make_data(mj_model).replace(qpos=q, qvel=v, ctrl=u))(qpos, qvel, ctrl)
    step = lambda m, d, g: mjx.step(m.replace(opt=m.opt.replace(gravity=g)), d)
    from hopper_mjx.engine import CPU_COMPILER_OPTIONS

    return best_cost(step, model, data, gravity, steps, CPU_COMPILER_OPTIONS)  # the mjx engine's


def chain_cut(engine, depth: int):
    """The chain engine's step cut after its first `depth` stages (CHAIN_STAGES)."""
    import jax
    import jax.numpy as jnp

    from hopper_mjx.engine import chain
    from hopper_mjx.engine.chain import constraint as chain_constraint
    from hopper_mjx.engine.chain import smooth as chain_smooth

    if depth >= len(CHAIN_STAGES) - 1:
        full = engine if depth == len(CHAIN_STAGES) else without_iterations(engine)
        return lambda m, d, g: full.integrate(m, full.forward(m, d, g), g)
    cm = engine.chain

    def step(model, d, g):
        gate = model.gate
        qpos = tuple(d.qpos[i] for i in range(cm.nq))
        qvel = tuple(d.qvel[i] for i in range(cm.nv))
        pose = chain_smooth.kinematics(cm, gate, qpos)
        outputs = [pose]
        if depth >= 2:
            outputs.append(chain._smooth(cm, gate, pose, qpos, qvel, tuple(d.ctrl), tuple(g)))
        if depth >= 3:
            outputs.append(chain_constraint.rows(cm, gate, pose, qpos, qvel, model.terrain))
        leaves = [x for x in jax.tree_util.tree_leaves(outputs) if not isinstance(x, (int, float))]
        # Every output feeds the next step's qpos and qvel: a stage of qpos alone (the kinematics, the ground's
        # contacts) fed only qvel, the timed loop's qpos stood still and XLA hoisted the stage out of the loop,
        # so its cost was counted in the solve's setup instead (1.9 µs of 2.5 on rough ground).
        touch = 1e-12 * sum(jnp.sum(x) for x in leaves)
        return d.replace(qpos=d.qpos + touch, qvel=d.qvel + touch)

    return step


def without_iterations(engine):
    """The chain engine of the same model with MuJoCo's Newton iteration cap (`opt.iterations`) at 0: its step
    chooses the better of the warm start and the smooth accelerations, evaluates the gradient there and integrates.
    It takes the same model argument (`engine.model`)."""
    from hopper_mjx.engine import chain

    source = copy.deepcopy(engine.source)
    source.opt.iterations = 0
    return chain.make_for_tools(source)


def _chain_data(engine, qpos, qvel, ctrl):
    import jax

    return jax.vmap(lambda q, v, u: engine.make_data(q, v).replace(ctrl=u))(qpos, qvel, ctrl)


def chain_costs(engine, qpos, qvel, ctrl, gravity, steps: int) -> dict:
    data = _chain_data(engine, qpos, qvel, ctrl)
    cumulative = [best_cost(chain_cut(engine, k), engine.model, data, gravity, steps, engine.compiler_options)
                  for k in range(1, len(CHAIN_STAGES) + 1)]
    return dict(zip(CHAIN_STAGES, np.diff(cumulative, prepend=0.0))) | {"full step": cumulative[-1]}


def newton_iterations(engine, qpos, qvel, ctrl, gravity, steps: int) -> tuple[np.ndarray, tuple]:
    """(instances, steps) Newton iterations of each instance's forward along the same rollout the costs time, and
    the states each forward started from: (qpos, qvel, qacc_warmstart), each (instances, steps, n)."""
    import jax

    from hopper_mjx.engine import BATCH_AXIS

    def one(m, d, g):
        def step(d, _):
            start = (d.qpos, d.qvel, d.qacc_warmstart)
            d = engine.forward(m, d, g)
            return engine.integrate(m, d, g), (d.solver_niter, start)
        return jax.lax.scan(step, d, None, length=steps)[1]

    f = jax.jit(jax.vmap(one, in_axes=(None, 0, 0), axis_name=BATCH_AXIS), compiler_options=engine.compiler_options)
    niter, states = f(engine.model, _chain_data(engine, qpos, qvel, ctrl), gravity)
    return np.asarray(niter), tuple(np.asarray(x) for x in states)


def c_replay(mj_model, states, ctrl, gravity, read) -> np.ndarray:
    """read(MjData) after MuJoCo C's (float64) mj_forward from each of the states `newton_iterations` returns
    ((instances, steps, n) each), each instance's motors at `ctrl` and its gravity: (instances, steps, ...)."""
    m = copy.deepcopy(mj_model)
    d = mujoco.MjData(m)
    qpos, qvel, warm = states
    out = []
    for i in range(qpos.shape[0]):
        m.opt.gravity[:] = gravity[i]
        d.ctrl[:] = ctrl[i]
        for t in range(qpos.shape[1]):
            d.qpos[:], d.qvel[:], d.qacc_warmstart[:] = qpos[i, t], qvel[i, t], warm[i, t]
            mujoco.mj_forward(m, d)
            out.append(np.array(read(d)))
    return np.reshape(out, qpos.shape[:2] + out[0].shape)


def c_iterations(mj_model, states, ctrl, gravity) -> np.ndarray:
    """(instances, steps) Newton iterations MuJoCo C (float64) runs from the same states (`newton_iterations`'), each
    instance's motors at `ctrl` and its gravity: whether the iterations a batch runs are the physics' own."""
    return c_replay(mj_model, states, ctrl, gravity, lambda d: d.solver_niter[0]).astype(int)


def standing_batch(num: int, settle: int, physics: Physics):
    """The core on one device (a chunk of `num`) and its batch after `settle` steps holding the stance, at
    gravities spanning the bench's."""
    import jax

    from hopper_mjx.control.base import hold
    from hopper_mjx.perf.bench import GRAVITY_SPAN
    from hopper_mjx.sim import gravity_vectors

    sim = physics.sim(chunk=num, devices=jax.local_devices()[:1])
    controller = hold(sim.layout)
    state = sim.reset(gravity_vectors(np.linspace(*GRAVITY_SPAN, num)), controller=controller)
    return sim, sim.rollout(state, controller, steps=settle)[0]


def measure(num: int, steps: int, settle: int, physics: Physics = Physics()) -> dict:
    from hopper_mjx.engine.mjx import without_sensors

    if num < 1 or steps < 1:
        raise ValueError(f"--num and --steps must be >= 1, got {num}, {steps}")
    mj_model = physics.mj_model
    sim, standing = standing_batch(num, settle, physics)
    record = {"num": num, "steps": steps, "engine": sim.engine.name, "terrain": str(physics.ground),
              "kernels": kernels.per_step(sim.engine, standing.data, standing.gravity),
              "equations": kernels.equations(sim.engine, standing.data, standing.gravity)}
    if sim.engine.name == "chain":
        args = (sim.engine, standing.data.qpos, standing.data.qvel, standing.data.ctrl, standing.gravity, steps)
        niter, states = newton_iterations(*args)
        c_niter = c_iterations(mj_model, states, np.asarray(standing.data.ctrl), np.asarray(standing.gravity))
        cap = sim.engine.chain.iterations
        count = lambda x: np.bincount(x.ravel(), minlength=cap + 1).tolist()
        return record | {"us": chain_costs(*args),
                         "newton": {"instance": count(niter), "batch": count(niter.max(axis=0)), "c": count(c_niter),
                                    "same_as_c": float(np.mean(niter == c_niter))}}
    costs = {}
    for name, flag in VARIANTS:
        variant = without_sensors(mj_model)  # as the core: it computes its own signals
        variant.opt.disableflags |= flag
        costs[name] = rollout_cost(variant, standing.data.qpos, standing.data.qvel, standing.data.ctrl,
                                   standing.gravity, steps)
    return record | {"constraint_rows": int(standing.data._impl.efc_J.shape[1]), "us": costs}


def table(record: dict) -> str:
    return (_table(record) + f"\nkernels one step launches (compiled, one pass through its loops): "
            f"{record['kernels']:,}\n" + _equations(record["equations"]))


def _equations(counts: dict, shown: int = 8) -> str:
    """The step's jaxpr equations, and the engine functions that wrote the most of them."""
    total = sum(counts.values())
    modules = collections.Counter()
    for name, n in counts.items():
        modules[name.split(".")[0]] += n
    lines = [f"jaxpr equations of one step (its size before XLA; tracing and compiling grow with it): {total:,}",
             "  by module: " + ", ".join(f"{m} {n / total:.0%}" for m, n in modules.most_common())]
    lines += [f"  {name:48s} {n:7,d} {n / total:6.0%}" for name, n in list(counts.items())[:shown]]
    return "\n".join(lines)


def _table(record: dict) -> str:
    us = record["us"]
    full = us["full step"]
    if record["engine"] == "chain":
        head = f"{record['num']} standing instances on one device, {record['steps']} steps, engine chain"
        parts = tuple((name, us[name]) for name in CHAIN_STAGES)
        runs = _mean(record["newton"]["batch"])
        each = f"{us[CHAIN_STAGES[-1]] / runs:.2f} µs each" if runs else "none run"
        return (_lines(head, parts, full) + "\n" + _iterations(record["newton"])
                + f"\nNewton iterations the batch runs: {runs:.2f} a step, {each}")
    parts = (
        ("contacts (collision, contact rows, their solve)", us["full step"] - us["no contacts"]),
        ("other constraints (limit rows, the solve itself)", us["no contacts"] - us["no constraints"]),
        ("smooth dynamics (kinematics .. integration)", us["no constraints"]),
    )
    head = (f"{record['num']} standing instances on one device, {record['steps']} steps, engine mjx, "
            f"{record['constraint_rows']} constraint rows per instance"
            + ("" if record["terrain"] == "flat" else f", terrain {record['terrain']}"))
    return _lines(head, parts, full)


def _iterations(newton: dict) -> str:
    """Shares of the instance-steps and of the batch's steps that ran 0, 1, ... Newton iterations, and the means."""
    lines = [f"{'Newton iterations':50s} " + " ".join(f"{k:>6d}" for k in range(len(newton["instance"]))) + "    mean"]
    for name, label in (("instance", "share of instance-steps (what each needs)"),
                        ("c", "MuJoCo C from the same states (float64)"),
                        ("batch", "share of the batch's steps (its slowest instance)")):
        counts = np.asarray(newton[name])
        share = counts / counts.sum()
        lines.append(f"{label:50s} " + " ".join(f"{x:6.1%}" for x in share) + f" {_mean(counts):7.2f}")
    lines.append(f"instance-steps with C's own count: {newton['same_as_c']:.1%}")
    return "\n".join(lines)


def _mean(counts) -> float:
    """The mean Newton iterations of a count per iteration number (0, 1, ...)."""
    counts = np.asarray(counts)
    return float(np.arange(len(counts)) @ (counts / counts.sum()))


def _lines(head: str, parts, full: float) -> str:
    lines = [head, f"{'part of the step':50s} {'µs':>7s} {'share':>6s}"]
    lines += [f"{name:50s} {cost:7.2f} {cost / full:6.0%}" for name, cost in parts]
    lines.append(f"{'full step (one instance-step)':50s} {full:7.2f}")
    if any(cost < 0 for _, cost in parts):
        lines.append("(below 0: the cuts before it keep every output of their stages, some of which the whole step "
                     "never computes, so they cost more than the part of the step they stand for)")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = cli.parser("python -m hopper_mjx.perf.profile", __doc__.split("\n")[0])
    p.add_argument("--num", type=int, default=256, help="instances in the batch (the core's chunk)")
    p.add_argument("--steps", type=int, default=200, help="steps per timed rollout")
    p.add_argument("--settle", type=int, default=300, help="physics steps holding the stance before timing")
    cli.add_physics_options(p)
    args = p.parse_args(argv)
    for name in ("num", "steps", "settle"):
        if getattr(args, name) < 1:
            return cli.fail(ValueError(f"--{name} must be >= 1, got {getattr(args, name)}"))
    try:
        physics = cli.check_physics(args, n=args.num)
        cli.refuse_each(physics.ground, "perf.profile")
        cli.check_whole_periods("--settle", args.settle, physics.timestep)  # the settling rollout records them
    except ValueError as err:
        return cli.fail(err)
    jaxsetup.configure()
    try:
        record = measure(args.num, args.steps, args.settle, physics)
    except ValueError as err:
        return cli.fail(err)
    print(table(record))
    return 0


if __name__ == "__main__":
    sys.exit(process.run(main))
