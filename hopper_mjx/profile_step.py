"""python -m hopper_mjx.profile_step: where the batched MJX step spends its time, by pipeline stage.

    python -m hopper_mjx.profile_step --num 256

Each stage of the step's pipeline (`mjx.step` = position -> velocity ->
actuation -> acceleration -> constraint solve -> Euler) is compiled on its own,
vmapped over one chunk of instances the way the core runs it (same XLA:CPU
options), and timed on the output of the stages before it. Fusion across
stage boundaries is lost, so the sum slightly exceeds the fused step. Two batches are timed: airborne (the
core's initial state, no contact) and standing (the same instances after
`--settle` steps holding the stance, foot on the floor: the solver works).

The stages are MJX's own functions (`mujoco.mjx._src`, a private module: this is
a measuring tool, not part of the core's path).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from hopper_mjx import runtime

REPEATS = 20  # timed calls per prefix; the best counts (noise only adds time)


def pipeline():
    """(name, f(m, d) -> d) in mjx.step's order, with fwd_position split at its costly parts."""
    from mujoco.mjx._src import collision_driver, constraint, forward, smooth, solver

    def kinematics_and_mass(m, d):
        for f in (smooth.kinematics, smooth.com_pos, smooth.crb, smooth.factor_m):
            d = f(m, d)
        return d

    return (
        ("kinematics, com, crb, factor_m", kinematics_and_mass),
        ("collision", collision_driver.collision),
        ("make_constraint", constraint.make_constraint),
        ("transmission", smooth.transmission),
        ("fwd_velocity", forward.fwd_velocity),
        ("fwd_actuation", forward.fwd_actuation),
        ("fwd_acceleration", forward.fwd_acceleration),
        ("solver.solve", solver.solve),
        ("euler", forward.euler),
    )


def stage_costs(mj_model, data, gravity) -> list[tuple[str, float]]:
    """[(stage, µs per instance-step)] for one batch `data` (an mjx.Data with a leading axis).

    Each stage is compiled alone and timed on the output of the stages before it,
    less the time of a stage that only passes the batch through (moving the whole
    Data in and out of a call, which the fused step does not pay per stage).
    """
    import jax
    from mujoco import mjx

    from hopper_mjx.sim import CPU_COMPILER_OPTIONS

    model = mjx.put_model(mj_model)
    num = gravity.shape[0]

    def timed(stage, d):
        def one(d, g):
            return stage(model.replace(opt=model.opt.replace(gravity=g)), d)

        f = jax.jit(jax.vmap(one), compiler_options=CPU_COMPILER_OPTIONS)
        out = jax.block_until_ready(f(d, gravity))  # compiles
        best = np.inf
        for _ in range(REPEATS):
            start = time.perf_counter()
            jax.block_until_ready(f(d, gravity))
            best = min(best, time.perf_counter() - start)
        return best / num * 1e6, out

    pass_through, _ = timed(lambda m, d: d.replace(time=d.time + 0.0), data)
    costs = []
    for name, stage in pipeline():
        cost, data = timed(stage, data)
        costs.append((name, max(cost - pass_through, 0.0)))
    return costs


def measure(num: int, settle: int) -> dict:
    import jax

    from hopper_mjx import model
    from hopper_mjx.control.base import hold
    from hopper_mjx.sim import Sim, gravity_vectors

    if num < 1:
        raise ValueError(f"--num must be >= 1, got {num}")
    mj_model = model.load()
    sim = Sim(mj_model, chunk=num, devices=jax.local_devices()[:1])
    gravity = gravity_vectors(np.linspace(1.62, 9.81, num))
    controller = hold(sim.layout)
    airborne = sim.reset(gravity, controller=controller)
    standing, _ = sim.rollout(airborne, controller, steps=settle)
    rows = {label: stage_costs(mj_model, state.data, state.gravity)
            for label, state in (("airborne", airborne), ("standing", standing))}
    efc_rows = int(standing.data._impl.efc_J.shape[1])  # allocated per instance, used or not
    return {"num": num, "settle_steps": settle, "constraint_rows": efc_rows, "stages": rows}


def table(record: dict) -> str:
    names = [name for name, _ in record["stages"]["airborne"]]
    cost = {label: dict(rows) for label, rows in record["stages"].items()}
    total = {label: sum(c.values()) for label, c in cost.items()}
    lines = [f"{record['num']} instances on one device, {record['constraint_rows']} constraint rows per instance",
             f"{'stage':32s} {'airborne µs':>12s} {'share':>6s} {'standing µs':>12s} {'share':>6s}"]
    for name in names:
        a, s = cost["airborne"][name], cost["standing"][name]
        lines.append(f"{name:32s} {a:12.2f} {a / total['airborne']:6.0%} {s:12.2f} {s / total['standing']:6.0%}")
    lines.append(f"{'sum (one instance-step)':32s} {total['airborne']:12.2f} {'':6s} {total['standing']:12.2f}")
    return "\n".join(lines)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(prog="python -m hopper_mjx.profile_step", description=__doc__.split("\n")[0])
    p.add_argument("--num", type=int, default=256, help="instances in the batch (the core's chunk)")
    p.add_argument("--settle", type=int, default=300, help="physics steps holding the stance before 'standing'")
    args = p.parse_args(argv)
    runtime.configure()
    try:
        record = measure(args.num, args.settle)
    except ValueError as err:
        p.error(str(err))
    print(table(record))


if __name__ == "__main__":
    main()
