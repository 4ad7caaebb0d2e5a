"""Writes a trained policy (experiments/train.py's Brax PPO or SAC) as an ONNX file a robot's computer can run,
checked against the JAX policy on observations from real rollouts in the core.

    python experiments/export_onnx.py runs/hop-ppo --out hop.onnx
    python experiments/export_onnx.py runs/hop-ppo/checkpoints/000020000000 --out hop.onnx --num 64 --seconds 2

POLICY is a training run's folder (its policy/) or one of its checkpoints, as `--controller policy:PATH` takes.
The file maps `observation`, (batch, observation size) float32, the features `hopper_mjx.envs.terms.observe`
builds, to `action`, (batch, 3) in [-1, 1]: the policy's deterministic action (the tanh of the Gaussian's mean,
as Brax's policy gives it), the observation normalisation included. A robot turns the action into joint targets
(stance + action_scale · action, within the joint ranges) that its drivers track with kp and kd, at policy_rate:
the task's config (hopper_env.json) is in the file's metadata as `hopper_env`, the observation's layout as
`observation_layout`.

The check: --num robots run the policy in the core for --seconds (1 ms physics, the policy's recorded motor and
action delay, its ground; the robots spread over the sweep's nine gravities, kicked as a sweep kicks them, their
commands drawn in the trained ranges). At every policy step the observation the controller read is rebuilt and
onnxruntime runs the file on it; the last line printed is the largest difference from the action the core's
controller sent. Above --tolerance nothing is written (exit 1).
"""

from __future__ import annotations

# First, so that Ctrl-C during the imports below is already one line (hopper_mjx.shell.startup arms it).
import hopper_mjx  # noqa: F401  # isort: skip

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from hopper_mjx import cli, registry
from hopper_mjx.shell import process
from hopper_mjx.shell.files import atomic_write

OPSET = 17  # ONNX's operator set: Gemm, Sub, Div, Tanh and the activations, in runtimes from 2022 on
# Brax's activation names (brax.training.networks.ACTIVATION) and the ONNX nodes that compute the same function.
ACTIVATIONS = {
    "relu": [("Relu", {})],
    "silu": [("Sigmoid", {}), ("Mul", {})],  # x · sigmoid(x)
    "swish": [("Sigmoid", {}), ("Mul", {})],
    "tanh": [("Tanh", {})],
    "sigmoid": [("Sigmoid", {})],
    "elu": [("Elu", {"alpha": 1.0})],
    "softplus": [("Softplus", {})],
    "leaky_relu": [("LeakyRelu", {"alpha": 0.01})],  # flax's default negative slope
    "linear": [],
}
MIN_OBSERVATIONS = 1000


def parser() -> argparse.ArgumentParser:
    p = cli.parser("python experiments/export_onnx.py", __doc__)
    p.add_argument("policy", type=Path, help="a training run's folder (its policy/) or one of its checkpoints")
    p.add_argument("--out", type=Path, required=True, help="the ONNX file to write (FILE.onnx)")
    p.add_argument("--urdf", default=None, help="the robot the policy will run on (default: the shipped monoped); "
                   "a policy trained on another robot is refused")
    p.add_argument("--task", default=None, help=f"refuse a policy of any other task ({', '.join(registry.TASKS)})")
    p.add_argument("--num", type=int, default=32, help="robots rolled out for the check (default 32)")
    p.add_argument("--seconds", type=float, default=1.0, help="seconds each robot runs (default 1)")
    p.add_argument("--seed", type=int, default=0, help="the robots' kicks and commands (default 0)")
    p.add_argument("--tolerance", type=float, default=1e-5,
                   help="largest action difference allowed between onnxruntime and JAX (default 1e-5)")
    return p


def check(args):
    """(policy path, algorithm, network config, task config, physics of the check's rollouts), or ValueError
    naming the first bad argument. Reads JSON and compiles the MuJoCo model only."""
    from hopper_mjx.envs import policy
    from hopper_mjx.envs.task_config import decimation
    from hopper_mjx.model.layout import Layout
    from hopper_mjx.model.robot import same_robot

    try:  # the `export` extra's packages
        import onnx  # noqa: F401
        import onnxruntime  # noqa: F401
    except ImportError as err:
        raise ValueError(f"{err.name} is not installed: pip install -e '.[export]'") from None
    if args.out.suffix != ".onnx":
        raise ValueError(f"--out {args.out}: give a file ending in .onnx")
    cli.check_writable("--out", args.out)
    for flag, value, low in (("--num", args.num, 1), ("--seconds", args.seconds, 0)):
        cli.check_range(flag, value, low=low, open_low=flag == "--seconds")
    cli.check_range("--tolerance", args.tolerance, low=0, open_low=True)
    cli.check_seed(args.seed)
    if not args.policy.is_dir():
        raise ValueError(cli.no_policy_folder(args.policy))
    if args.task is not None:
        try:
            registry.check("task", registry.TASKS, args.task)
        except ValueError as err:
            raise ValueError(f"--task: {err}") from None
    path, algo, net, config = policy.read(args.policy)
    if args.task is not None and config.task != args.task:
        raise ValueError(f"{path} is a {config.task} policy, not {args.task} (--task)")
    kwargs = net["network_factory_kwargs"]
    if kwargs["distribution_type"] != "tanh_normal":
        raise ValueError(f"{path}: only tanh_normal policies are exported (Brax's default), not "
                         f"{kwargs['distribution_type']!r}")
    if kwargs["activation"] not in ACTIVATIONS:
        raise ValueError(f"{path}: activation {kwargs['activation']!r} has no ONNX form here; known: "
                         f"{', '.join(ACTIVATIONS)}")
    if net["action_size"] != 3:
        raise ValueError(f"{path}: the policy gives {net['action_size']} actions; the monoped takes 3")
    if args.num * math.floor(args.seconds * config.policy_rate) < MIN_OBSERVATIONS:
        raise ValueError(f"--num {args.num} x --seconds {args.seconds:g} at the policy's {config.policy_rate:g} Hz "
                         f"gives fewer than {MIN_OBSERVATIONS} observations to check; raise either")
    from hopper_mjx.envs.curriculum import judged_on

    # The core's physics for the policy (1 ms, converged), with the motor, delay and ground it recorded (a course's
    # policy on the ground it is judged on: the course's centre is flat, and its scan would read nothing).
    physics = cli.check_physics(argparse.Namespace(
        urdf=args.urdf, engine=registry.DEFAULT_ENGINE, terrain=judged_on(config.terrain or "flat"), randomize=None,
        motor=config.motor, action_delay=config.action_delay * 1e3, push=None))
    same_robot(config.robot, physics.mj_model, f"the policy {path}")
    decimation(Layout.of(physics.mj_model), config)  # the policy rate must divide the core's 1 kHz
    return path, algo, net, config, physics


def observation_layout(config) -> list[tuple[str, int]]:
    """The observation's parts in order, (name, size), as `terms.observe` concatenates them."""
    from hopper_mjx.envs import tasks
    from hopper_mjx.envs.terms import ROBOT_SIGNALS

    parts = [*ROBOT_SIGNALS, ("command", tasks.task_class(config.task).command_size), ("last action", 3)]
    if config.observe_gravity:
        parts.append(("gravity / 9.81", 1))
    parts.append(("base height over the scan points", config.scan_size))
    return [(name, size) for name, size in parts if size]


def onnx_model(weights, net: dict, config):
    """The deterministic policy as an ONNX model: normalise, the MLP's layers, tanh of the mean."""
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    normaliser, params = weights
    layers = params["params"]
    names = [f"hidden_{i}" for i in range(len(layers))]
    if sorted(layers) != sorted(names) or any(sorted(layers[n]) != ["bias", "kernel"] for n in names):
        raise ValueError(f"the policy network is not a plain MLP (layers {sorted(layers)}): no ONNX form here")
    action_size = net["action_size"]
    initializers, nodes, x = [], [], "observation"

    def constant(name, value):
        initializers.append(numpy_helper.from_array(np.asarray(value, np.float32), name))
        return name

    if net["normalize_observations"]:  # Brax's running_statistics.normalize: (x - mean) / std
        nodes += [helper.make_node("Sub", [x, constant("obs_mean", normaliser.mean)], ["centred"]),
                  helper.make_node("Div", ["centred", constant("obs_std", normaliser.std)], ["normalised"])]
        x = "normalised"
    for i, name in enumerate(names):
        kernel, bias = np.asarray(layers[name]["kernel"]), np.asarray(layers[name]["bias"])
        last = i == len(names) - 1
        if last:  # Brax splits the last layer into the Gaussian's (mean, scale); the deterministic action is its mean
            kernel, bias = kernel[:, :action_size], bias[:action_size]
        nodes.append(helper.make_node("Gemm", [x, constant(f"{name}_kernel", kernel), constant(f"{name}_bias", bias)],
                                      [f"{name}_out"]))
        x = f"{name}_out"
        if last:
            break
        steps = ACTIVATIONS[net["network_factory_kwargs"]["activation"]]
        for j, (op, attributes) in enumerate(steps):
            out = f"{name}_act{j}"
            inputs = [x] if op != "Mul" else [f"{name}_out", x]  # silu: x times its sigmoid
            nodes.append(helper.make_node(op, inputs, [out], **attributes))
            x = out
    nodes.append(helper.make_node("Tanh", [x], ["action"]))
    graph = helper.make_graph(
        nodes, f"hopper_mjx_{config.task}_policy",
        [helper.make_tensor_value_info("observation", TensorProto.FLOAT, ["batch", net["observation_size"]])],
        [helper.make_tensor_value_info("action", TensorProto.FLOAT, ["batch", action_size])], initializers)
    model = helper.make_model(graph, producer_name="hopper_mjx", opset_imports=[helper.make_opsetid("", OPSET)])
    model.ir_version = 8  # the IR of opset 17: older runtimes read the file too
    helper.set_model_props(model, {"hopper_env": json.dumps(config.to_dict()),
                                   "observation_layout": json.dumps(observation_layout(config))})
    onnx.checker.check_model(model, full_check=True)
    return model


def rollout_observations(path, config, physics, *, num: int, seconds: float, seed: int):
    """(observations (K, obs size), the actions the core's controller sent on them (K, 3)): `num` robots run the
    policy in the core; at each policy step the features the controller reads are rebuilt from the state."""
    import jax
    import jax.numpy as jnp

    from hopper_mjx.envs import policy, tasks
    from hopper_mjx.envs.task_config import decimation
    from hopper_mjx.envs.terms import observe
    from hopper_mjx.hardware.signals import SensorConfig
    from hopper_mjx.sim import gravity_vectors
    from hopper_mjx.sweep.grid import DEFAULT_GRAVITY, SweepSpec, expand

    sim = physics.sim()
    controller = policy.policy_controller(physics.mj_model, path)
    every = decimation(sim.layout, config)
    per_gravity = -(-num // len(DEFAULT_GRAVITY))
    spec = SweepSpec(kind="gravity", gravity=DEFAULT_GRAVITY, num=per_gravity, duration=seconds, height=0.0,
                     speed=(0.0, 0.0), seed=seed)
    batch = expand(spec, sim.layout.nv)  # the sweep's kicks
    g, kick = batch.gravity[:num], batch.qvel[:num]
    rng = np.random.default_rng(seed)
    if tasks.task_class(config.task).command_size:  # apex height above the floor, vx, vy, in the trained ranges
        lateral = config.lateral_speed_range or config.speed_range
        commands = np.stack([rng.uniform(*config.apex_range, num), rng.uniform(*config.speed_range, num),
                             rng.uniform(*lateral, num)], axis=1)
    else:
        commands = np.zeros((num, 0))
    params = policy.PolicyParams(jnp.asarray(commands, jnp.float32))
    state = sim.reset(gravity_vectors(g), key=seed, controller=controller, params=params, qvel=kick)
    features = jax.jit(jax.vmap(lambda obs, gravity, cs: observe(sim.layout, config, obs, gravity, cs.command,
                                                                         cs.last_action)))
    sensors = SensorConfig.uniform(config.policy_rate)  # one record per policy step: a rollout of `every` steps
    observations, actions = [], []
    for _ in range(int(seconds * config.policy_rate)):
        seen = features(sim._first_observation(state.data, state.ground), state.gravity, state.cstate)
        state, _ = sim.rollout(state, controller, steps=every, sensors=sensors)
        alive = ~np.asarray(state.diverged)  # a diverged robot is frozen: its controller decided nothing
        observations.append(np.asarray(seen)[alive])
        actions.append(np.asarray(state.cstate.last_action)[alive])
    return np.concatenate(observations), np.concatenate(actions)


def main(argv=None) -> int:
    args = parser().parse_args(argv)
    try:
        path, _, net, config, physics = check(args)
    except ValueError as err:
        return cli.fail(err)
    from hopper_mjx.shell import jaxsetup

    jaxsetup.configure()
    import onnxruntime

    from hopper_mjx.envs import policy

    try:
        _, weights, _ = policy.load_network(path)  # a damaged checkpoint: one line, before any compile
        model = onnx_model(weights, net, config)
    except ValueError as err:
        return cli.fail(err)
    observations, sent = rollout_observations(path, config, physics, num=args.num, seconds=args.seconds,
                                              seed=args.seed)
    if len(observations) < MIN_OBSERVATIONS:  # robots whose physics diverged were dropped
        print(f"error: only {len(observations)} observations from robots that did not diverge; raise --num or "
              "--seconds; nothing written", file=sys.stderr)
        return 1
    session = onnxruntime.InferenceSession(model.SerializeToString(), providers=["CPUExecutionProvider"])
    exported = session.run(["action"], {"observation": observations.astype(np.float32)})[0]
    difference = float(np.abs(exported - sent).max())
    print(f"checked on {len(observations):,} observations of {args.num} robots x {args.seconds:g} s in the core "
          f"({config.task}, {net['observation_size']} observations -> 3 actions)")
    if not difference <= args.tolerance:
        print(f"largest action difference (onnxruntime vs JAX): {difference:.3g}")
        print(f"error: the ONNX actions differ from JAX's by {difference:.3g} > --tolerance {args.tolerance:g}; "
              "nothing written", file=sys.stderr)
        return 1
    atomic_write(args.out, lambda f: f.write(model.SerializeToString()))
    print(f"wrote {args.out} ({args.out.stat().st_size:,} bytes)")
    print(f"largest action difference (onnxruntime vs JAX): {difference:.3g}")
    return 0


if __name__ == "__main__":
    sys.exit(process.run(main))
