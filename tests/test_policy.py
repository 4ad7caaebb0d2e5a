"""A policy folder as `--controller policy:PATH`: in the core, in simulate's checks and in `sweep compare`.

The policy is an untrained Brax PPO network (seeded initial params) saved as experiments/train.py
saves one: what is tested is the path from a folder to a controller, not what training reaches.
"""

import dataclasses
import functools
import os
import shutil

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hopper_mjx import envs
from hopper_mjx.model import robot


def _save_policy(out, mj_model, key: int):
    """A `hop` policy folder at `out`, laid out as experiments/train.py writes one, its network seeded by `key`."""
    from brax.training.acme import running_statistics, specs
    from brax.training.agents.ppo import checkpoint
    from brax.training.agents.ppo import networks as ppo_networks

    from hopper_mjx.envs import policy

    env = envs.make("hop", mj_model)
    factory = functools.partial(ppo_networks.make_ppo_networks, policy_hidden_layer_sizes=(8, 8),
                                value_hidden_layer_sizes=(8, 8))
    network = factory(env.observation_size, env.action_size, preprocess_observations_fn=running_statistics.normalize)
    k_policy, k_value = jax.random.split(jax.random.PRNGKey(key))
    params = (running_statistics.init_state(specs.Array((env.observation_size,), jnp.dtype("float32"))),
              network.policy_network.init(k_policy), network.value_network.init(k_value))
    checkpoint.save(out / "checkpoints", 1, params,
                    checkpoint.network_config(env.observation_size, env.action_size, True, factory))
    shutil.copytree(policy.write_env_config(out / "checkpoints" / f"{1:012d}", env.config), out / "policy")
    return out


@pytest.fixture(scope="module")
def trained(tmp_path_factory, mj_model):
    """(folder, None): a `hop` policy folder, laid out as experiments/train.py writes one."""
    return _save_policy(tmp_path_factory.mktemp("policy") / "run", mj_model, 0), None


def test_another_checkpoints_weights_run_in_the_same_compiled_rollout(trained, mj_model, tmp_path):
    """A policy's weights are a run-time input of the core's rollout: another checkpoint of the same network
    (`with_weights`, as the checkpoint scan runs them) reuses the compiled program, and moves the robot exactly
    as that checkpoint's own controller does."""
    from hopper_mjx.envs import policy
    from hopper_mjx.sim import Sim, gravity_vectors

    first, _ = trained
    other = _save_policy(tmp_path / "other", mj_model, 1)
    g = gravity_vectors([9.81, 1.62])
    base = policy.policy_controller(mj_model, first)
    swapped = base.with_weights(policy.load_network(other)[1])
    paths, sim = {}, Sim(mj_model)
    for name, controller in (("first", base), ("other, swapped in", swapped)):
        state = sim.reset(g, key=0, controller=controller)
        paths[name] = np.asarray(sim.rollout(state, controller, steps=200)[1].qpos)
    assert len(sim._compiled) == 1  # one program for both
    own = policy.policy_controller(mj_model, other)
    fresh = Sim(mj_model)
    paths["other, its own"] = np.asarray(fresh.rollout(fresh.reset(g, key=0, controller=own), own, steps=200)[1].qpos)
    np.testing.assert_array_equal(paths["other, swapped in"], paths["other, its own"])
    assert np.abs(paths["first"] - paths["other, its own"]).max() > 1e-3  # the weights do move the robot
    with pytest.raises(ValueError, match="has no weights"):
        Sim(mj_model).limp.with_weights(())
    with pytest.raises(ValueError, match="has weights but no act_with"):
        dataclasses.replace(base, act_with=None)


def test_policy_runs_as_a_core_controller(trained, mj_model, sim):
    from hopper_mjx.envs import policy
    from hopper_mjx.sim import gravity_vectors

    out, _ = trained
    controller = policy.policy_controller(mj_model, os.path.relpath(out))  # relative, as typed on a command line
    params = policy.policy_params(sim.robot, 2, height=0.2, config=policy.read(out)[3])
    standing = robot.standing_qpos(mj_model)[2]
    np.testing.assert_allclose(np.asarray(params.command[0]), [standing + 0.2, 0.0, 0.0], rtol=1e-6)
    # The batch and steps of the weights test above: one compiled program serves both.
    state = sim.reset(gravity_vectors([9.81, 1.62]), key=0, controller=controller, params=params)
    final, traj = sim.rollout(state, controller, steps=200)
    assert not np.asarray(final.diverged).any() and np.isfinite(np.asarray(traj.qpos)).all()
    cs = final.cstate
    assert (np.asarray(cs.tick) == 200).all() and (np.asarray(cs.work) > 0).all()
    lo, hi = np.asarray(sim.layout.joint_range).T
    assert ((np.asarray(cs.target) >= lo - 1e-6) & (np.asarray(cs.target) <= hi + 1e-6)).all()
    # Ten policy decisions in 0.2 s at 50 Hz: the last action is a real policy output in [-1, 1].
    assert (np.abs(np.asarray(cs.last_action)) <= 1).all() and np.abs(np.asarray(cs.last_action)).sum() > 0


def test_the_network_runs_only_on_the_steps_an_instance_of_the_chunk_decides(trained, mj_model, sim):
    """Under the core's vmap (axis BATCH_AXIS) the network is skipped on the steps no instance of the chunk
    decides; the actions equal those of the network run for every instance and selected (a plain vmap), when
    all, some or none of the instances decide, and an instance between its decisions keeps its last action."""
    from hopper_mjx.engine import BATCH_AXIS
    from hopper_mjx.envs import policy
    from hopper_mjx.sim import gravity_vectors

    out, _ = trained
    controller = policy.policy_controller(mj_model, out)
    g = gravity_vectors([9.81, 3.71, 1.62, 9.81])
    params = policy.policy_params(sim.robot, 4, height=0.2, config=policy.read(out)[3])
    state = sim.reset(g, key=0, controller=controller, params=params)
    obs = sim._first_observation(state.data, ())
    held = jnp.full((4, 3), 0.25, jnp.float32)
    core = jax.jit(jax.vmap(controller.act, axis_name=BATCH_AXIS))
    every_step = jax.jit(jax.vmap(controller.act))  # no chunk axis: the network for every instance, selected
    per_decision = round(1 / (50.0 * sim.layout.timestep))  # the policy's 50 Hz in the 1 kHz core
    for ticks in ([0, 0, 0, 0], [0, 3, per_decision, 7], [3, 3, 3, 3]):
        cs = state.cstate._replace(tick=jnp.asarray(ticks, jnp.int32), last_action=held)
        (_, skipped), (_, full) = core(cs, obs, g), every_step(cs, obs, g)
        np.testing.assert_allclose(np.asarray(skipped.last_action), np.asarray(full.last_action), atol=1e-6)
        decides = np.asarray(ticks) % per_decision == 0
        action = np.asarray(skipped.last_action)
        assert (action[~decides] == 0.25).all() and (np.abs(action[decides] - 0.25) > 1e-4).any(axis=1).all()


def test_an_action_delay_holds_back_the_policys_targets_not_its_pd_loop(trained, mj_model):
    """With an action delay of 6 steps the policy's joint drivers track the targets it set 6 physics steps
    before (the standing targets until then), on the joints as they are now: the same path, to float32
    rounding, as the policy with that delay line written into a torque controller and no delay in the
    core."""
    from hopper_mjx.control.base import Controller, to_ctrl
    from hopper_mjx.envs import policy
    from hopper_mjx.sim import Sim, gravity_vectors

    out, _ = trained
    late, steps, g = 6, 300, gravity_vectors([9.81, 1.62])
    servo = policy.policy_controller(mj_model, out)
    layout = Sim(mj_model).layout

    def init(obs, params):  # the policy's state and its own line of targets, full of the first ones
        cs = servo.init(obs, params)
        return cs, jnp.tile(cs.target, (late + 1, 1))

    def act(state, obs, gravity):
        cs, line = state
        target, cs = servo.act(cs, obs, gravity)
        line = jnp.concatenate([target[None], line[:-1]])
        torque, cs = servo.servo.track(cs, line[late], obs)
        return to_ctrl(layout, torque), (cs, line)

    by_hand = Controller(name="late targets by hand", init=init, act=act)
    delayed = Sim(mj_model, delay_steps=late)
    paths = {}
    for name, sim, controller in (("servo", delayed, servo), ("by hand", Sim(mj_model), by_hand)):
        state = sim.reset(g, key=0, controller=controller)
        paths[name] = np.asarray(sim.rollout(state, controller, steps=steps)[1].qpos)
    # (A core that ignored the delay, or delayed the torque, would part from the hand-written line.)
    np.testing.assert_allclose(paths["servo"], paths["by hand"], atol=1e-5)
    line = np.asarray(delayed.reset(g, key=0, controller=servo).drive.line)
    assert (line == line[:, :1]).all() and np.abs(line).max() > 0.5  # full of the standing targets


def test_policy_path_errors_name_the_problem(tmp_path, mj_model, sim):
    from hopper_mjx.envs import policy

    with pytest.raises(ValueError, match="not a trained policy"):
        policy.policy_controller(mj_model, tmp_path)
    with pytest.raises(ValueError, match="speed"):
        policy.policy_params(sim.robot, 2, height=0.1, speed=(0.1,))


def test_a_policy_trained_on_terrain_is_refused_on_the_flat_plane(trained, mj_model, tmp_path):
    """A hop_terrain policy reads a height scan: on a model without a height field it is one clear error,
    before its network is built."""
    import json

    from hopper_mjx.envs import policy, tasks

    folder = tmp_path / "terrain-policy"
    shutil.copytree(trained[0] / "policy", folder)
    config = json.loads((folder / policy.ENV_CONFIG).read_text())
    config |= {"task": "hop_terrain", "terrain": tasks.HOP_TERRAIN}
    (folder / policy.ENV_CONFIG).write_text(json.dumps(config))
    net_file = folder / policy.NETWORK_CONFIGS["ppo"]
    net = json.loads(net_file.read_text())
    net_file.write_text(json.dumps({**net, "observation_size": net["observation_size"] + 25}))  # a 5 x 5 scan
    assert policy.read(folder)[3].terrain == tasks.HOP_TERRAIN  # a consistent folder: sizes agree
    with pytest.raises(ValueError, match="reads a height scan .*run it on a --terrain"):
        policy.policy_controller(mj_model, folder)


def test_policy_commands_and_sizes_are_checked_before_anything_runs(trained, sim, tmp_path, capsys):
    """simulate with a hop policy: a command outside its training box, or a folder whose task config
    does not match its network's input, is one line on stderr and exit 2, with nothing written."""
    import json
    import shutil

    from hopper_mjx import simulate

    out, _ = trained
    npz = tmp_path / "x.npz"
    from hopper_mjx.envs import policy

    rise = [apex - sim.robot.standing_height for apex in policy.read(out)[3].apex_range]  # m
    cases = [(["--height", "0.5"],
              f"--height 0.5 is outside the hop policy's trained range [{rise[0]:g}, {rise[1]:g}]"),
             (["--height", "0.15", "--speed", "0.3,0"],
              "--speed VX 0.3 is outside the hop policy's trained range [0, 0]")]
    for args, message in cases:
        assert simulate.main(["--controller", f"policy:{out}", *args, "--out", str(npz)]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1
    other = tmp_path / "other"
    shutil.copytree(out / "policy", other)
    config = json.loads((other / "hopper_env.json").read_text())
    (other / "hopper_env.json").write_text(json.dumps({**config, "task": "stand"}))
    assert simulate.main(["--controller", f"policy:{other}", "--out", str(npz)]) == 2
    assert "takes 27 observations but task 'stand' (observe_gravity=False) gives 24" in capsys.readouterr().err
    assert not npz.exists()


def test_sweep_compare_judges_the_policy_and_raibert_alike(trained, tmp_path, capsys):
    """`sweep compare`: one gravity sweep per controller, same grid and kicks, one table and plot."""
    import json

    from hopper_mjx.sweep import __main__ as sweep

    out, _ = trained
    folder = tmp_path / "compared"  # new: a sweep writes only into a folder it made
    # Raibert's sweep has tests/test_sweep.py's sizes (chunks of 2, 3 s): its program is compiled once for both.
    args = ["compare", "--controllers", f"raibert,policy:{out}", "--values", "9.81,1.62", "--num", "1",
            "--duration", "3", "--chunk", "2", "--height", "0.15", "--no-progress", "--out", str(folder)]
    assert sweep.main(args) == 0
    groups = json.loads((folder / "comparison.json").read_text())["groups"]
    assert [(g["controller"], g["gravity"], g["n"]) for g in groups] == [
        ("raibert", 9.81, 1), ("raibert", 1.62, 1), ("policy-run", 9.81, 1), ("policy-run", 1.62, 1)]
    assert (folder / "gravity.png").stat().st_size > 1000
    table = (folder / "table.txt").read_text()
    assert table.count("raibert") == 2 and table.count("policy-run") == 2
    manifests = [json.loads((folder / d / "manifest.json").read_text()) for d in ("raibert", "policy-run")]
    assert manifests[0]["controller"] == "raibert" and manifests[1]["controller"] == f"policy:{out}"
    assert {k: v for k, v in manifests[0].items() if k != "controller"} == \
        {k: v for k, v in manifests[1].items() if k != "controller"}  # same grid, kicks, commands
    capsys.readouterr()
    assert sweep.main(["compare", "--controllers", f"raibert,policy:{tmp_path}", "--out", str(tmp_path / "x")]) == 2
    assert "is not a trained policy" in capsys.readouterr().err and not (tmp_path / "x").exists()


def test_an_obstacle_sweep_runs_a_policy_as_a_gravity_sweep_on_its_block_does(trained, tmp_path):
    """`sweep obstacle --controller policy:PATH`: each robot meets its block as the same policy does in a gravity
    sweep on that ground alone (the same kicks, commands and ground), whose rows it gives; a level ground (height 0)
    in the same sweep gives other falls, so each robot ran on its own ground."""
    import csv
    import json

    from hopper_mjx.sweep import __main__ as sweep

    out, _ = trained
    common = ["--controller", f"policy:{out}", "--gravity", "9.81,1.62", "--num", "2", "--duration", "2",
              "--chunk", "4", "--speed", "0,0", "--no-progress"]
    assert sweep.main(["obstacle", "--heights", "0,0.1", "--x", "0.15", *common,
                       "--out", str(tmp_path / "o")]) == 0
    block = json.loads((tmp_path / "o" / "manifest.json").read_text())["grounds"][1]
    assert sweep.main(["gravity", "--terrain", block, *common, "--out", str(tmp_path / "g")]) == 0
    def read(name, key=lambda r: ()):
        with open(tmp_path / name / "results.csv") as f:
            return sorted(csv.DictReader(f), key=lambda r: (*key(r), float(r["gravity"]), int(r["replicate"])))

    rows, alone = read("o", lambda r: (float(r["obstacle_height"]),)), read("g")
    level, on_block = rows[:4], rows[4:]
    assert {float(r["obstacle_height"]) for r in on_block} == {0.1}
    assert [(r["gravity"], r["replicate"]) for r in on_block] == [(r["gravity"], r["replicate"]) for r in alone]
    shared = [k for k in alone[0] if k not in ("gravity", "replicate", "label")]
    assert {"hops", "fell", "apex_height", "mean_speed", "max_pitch"} <= set(shared), shared
    for name in shared:
        np.testing.assert_allclose([float(r[name]) for r in on_block], [float(r[name]) for r in alone],
                                   rtol=1e-5, atol=1e-6, equal_nan=True, err_msg=name)
    # The untrained policy's robots fall within 2 s; the block 0.15 m ahead changes how.
    falls = lambda rows: np.array([float(r["fall_x"]) for r in rows])
    assert not np.allclose(falls(on_block), falls(level), atol=0.01, equal_nan=True), (falls(on_block), falls(level))


def _damage_env(folder):
    (folder / "hopper_env.json").write_text("[1, 2]")
    return f"{folder / 'hopper_env.json'} must hold a JSON object, not a list"


def _garble_env(folder):
    (folder / "hopper_env.json").write_text('{"task": "hop", ')
    return f"{folder / 'hopper_env.json'} is not valid JSON (JSONDecodeError"


def _drop_network_key(folder):
    import json

    net = json.loads((folder / "ppo_network_config.json").read_text())
    del net["network_factory_kwargs"]["policy_hidden_layer_sizes"]
    (folder / "ppo_network_config.json").write_text(json.dumps(net))
    return f"{folder / 'ppo_network_config.json'} lacks network_factory_kwargs.policy_hidden_layer_sizes"


def _resize_layers(folder):
    import json

    net = json.loads((folder / "ppo_network_config.json").read_text())
    net["network_factory_kwargs"]["policy_hidden_layer_sizes"] = [16, 16]
    (folder / "ppo_network_config.json").write_text(json.dumps(net))
    return f"{folder}: its parameters do not fit its network config"


def _truncate_params(folder):
    for f in folder.rglob("*"):
        if f.is_file() and not f.name.endswith(".json"):
            f.write_bytes(f.read_bytes()[: f.stat().st_size // 2])
    return f"{folder}: its parameters cannot be read"


@pytest.mark.parametrize("damage", [_damage_env, _garble_env, _drop_network_key, _resize_layers, _truncate_params],
                         ids=["env-list", "env-garbled", "network-key", "layer-sizes", "truncated-params"])
def test_a_damaged_policy_folder_is_one_line_naming_it(trained, tmp_path, capsys, damage):
    """A policy is a folder a user may copy, edit or cut short: each damage is refused before anything
    is compiled, in one line naming the file, with nothing written."""
    from hopper_mjx import simulate

    out, _ = trained
    copy = tmp_path / "copy"
    shutil.copytree(out / "policy", copy)
    message = damage(copy)
    npz = tmp_path / "x.npz"
    assert simulate.main(["--controller", f"policy:{copy}", "--out", str(npz)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: --controller: {message}") and err.count("\n") == 1, err
    assert not npz.exists()


def test_reading_a_policy_for_the_checks_leaves_jax_a_device_per_core(trained):
    """Every command checks its arguments, `policy:PATH` included, before it configures JAX for its run; reading
    the policy is then the process's first JAX computation, and JAX takes the device count only before that
    one. In a process of its own (an in-process call inherits this session's configured JAX and cannot show
    it): the check, then the command's configuration, then as many devices as cores."""
    import subprocess
    import sys
    import textwrap

    from test_bad_inputs import ENV

    out, _ = trained
    script = textwrap.dedent(f"""
        import os
        from hopper_mjx import cli
        from hopper_mjx.shell import jaxsetup
        cli.check_controller("policy:{out}", 0.1)
        jaxsetup.configure()
        import jax
        print(len(jax.devices()), os.cpu_count())
    """)
    done = subprocess.run([sys.executable, "-c", script], env=ENV, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    devices, cores = done.stdout.split()
    assert devices == cores


def test_as_trained_puts_the_sweep_on_the_policys_training_physics(trained):
    """`sweep --as-trained`: the policy's recorded timestep and solver caps replace the core's in the sweep's
    physics (and so in its model and its manifest); a controller that is no policy is refused in one line."""
    import dataclasses

    from hopper_mjx.envs import policy
    from hopper_mjx.scenario import Physics
    from hopper_mjx.sweep.__main__ import as_trained, main

    folder, _ = trained
    config = dataclasses.replace(policy.read(folder)[3])
    physics = as_trained(Physics(), [f"policy:{folder}"])
    assert physics.model_options == {"timestep": config.timestep, "iterations": config.solver_iterations,
                                     "ls_iterations": config.ls_iterations}
    m = physics.mj_model
    assert (m.opt.timestep, m.opt.iterations, m.opt.ls_iterations) == (0.001, 2, 4)  # training's cap, not the core's
    assert (Physics().mj_model.opt.timestep, Physics().mj_model.opt.iterations) == (0.001, 4)
    # One part alone, the other the core's: what results.py runs to tell which part makes a gap.
    assert as_trained(Physics(), [f"policy:{folder}"], "timestep").model_options == {"timestep": config.timestep}
    assert as_trained(Physics(), [f"policy:{folder}"], "solver").model_options == {
        "iterations": config.solver_iterations, "ls_iterations": config.ls_iterations}
    with pytest.raises(ValueError, match="; raibert is not a policy:PATH$"):
        as_trained(Physics(), ["raibert", f"policy:{folder}"])
    assert main(["gravity", "--as-trained", "--num", "1", "--out", str(folder.parent / "no")]) == 2
    assert not (folder.parent / "no").exists()
    with pytest.raises(SystemExit) as bad:  # argparse's one line, before anything is built
        main(["gravity", f"--controller=policy:{folder}", "--as-trained=step", "--out", str(folder.parent / "no")])
    assert bad.value.code == 2 and not (folder.parent / "no").exists()
