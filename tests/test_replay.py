"""The ring replay SAC trains with keeps what Brax's queue keeps and samples it uniformly, without the roll; and
SAC's temperature aims at the entropy train.py is given, and a resumed run's checkpoint is laid out as its state is."""

import jax
import jax.numpy as jnp
import numpy as np
from brax.training import replay_buffers

from hopper_mjx.envs.replay import (
    RingReplay,
    losses_in_sac,
    policy_update_in_sac,
    replicated_restore_in_sac,
    ring_replay_in_sac,
)

CAPACITY, BATCH, DRAWS = 8, 3, 4000


def _fill(buffer, inserts):
    """Inserts `inserts` batches of BATCH rows labelled 0, 1, 2, ... (value and label alike)."""
    state = buffer.init(jax.random.PRNGKey(0))
    for i in range(inserts):
        labels = jnp.arange(i * BATCH, (i + 1) * BATCH, dtype=jnp.float32)
        state = buffer.insert(state, {"label": labels, "twice": 2 * labels})
    return state


def _make(cls):
    return cls(max_replay_size=CAPACITY, dummy_data_sample={"label": 0.0, "twice": 0.0}, sample_batch_size=DRAWS)


def test_the_ring_keeps_the_newest_rows_as_brax_does_and_samples_them_uniformly():
    for inserts in (2, 5):  # 6 rows (not yet full), 15 rows (full, the oldest 7 overwritten)
        ring, queue = _make(RingReplay), _make(replay_buffers.UniformSamplingQueue)
        ring_state, queue_state = _fill(ring, inserts), _fill(queue, inserts)
        kept = np.arange(max(0, inserts * BATCH - CAPACITY), inserts * BATCH)
        filled = int(ring.size(ring_state))
        assert filled == len(kept) == int(queue.size(queue_state))
        assert sorted(np.asarray(ring_state.data[:filled, 0])) == sorted(np.asarray(queue_state.data)[
            int(queue_state.sample_position):int(queue_state.insert_position), 0]) == list(kept)
        _, batch = ring.sample(ring_state)
        labels = np.asarray(batch["label"])
        np.testing.assert_array_equal(np.asarray(batch["twice"]), 2 * labels)  # rows stay whole
        counts = np.array([np.sum(labels == k) for k in kept])
        assert counts.sum() == DRAWS  # nothing outside the newest rows
        expected = DRAWS / len(kept)  # uniform: each within 5 standard deviations of its binomial count
        assert np.all(np.abs(counts - expected) < 5 * np.sqrt(expected)), counts


def test_sac_builds_the_ring_only_inside_the_context():
    from brax.training.agents.sac import train as sac

    with ring_replay_in_sac():
        assert sac.replay_buffers.UniformSamplingQueue is RingReplay
    assert sac.replay_buffers is replay_buffers and replay_buffers.UniformSamplingQueue is not RingReplay


def _alpha_loss(log_alpha: float, target_nats):
    """SAC's temperature loss as `train` builds it, for a tiny policy on a batch of 64 observations."""
    from brax.training import types
    from brax.training.agents.sac import networks
    from brax.training.agents.sac import train as sac

    net = networks.make_sac_networks(5, 3, hidden_layer_sizes=(8,))
    policy_params = net.policy_network.init(jax.random.PRNGKey(1))
    obs = jax.random.normal(jax.random.PRNGKey(2), (64, 5))
    transitions = types.Transition(obs, jnp.zeros((64, 3)), jnp.zeros(64), jnp.ones(64), obs)
    with losses_in_sac(target_nats):
        alpha_loss, _, _ = sac.sac_losses.make_losses(sac_network=net, reward_scaling=1.0, discounting=0.99,
                                                      action_size=3)
    return float(alpha_loss(jnp.float32(log_alpha), policy_params, None, transitions, jax.random.PRNGKey(3)))


def test_sac_aims_its_temperature_at_the_given_entropy_only_inside_the_context():
    """The loss is alpha * mean(-log_prob - target): at alpha = 2 a target 4.5 nats lower (-6 for Brax's -1.5 with 3
    actions) adds exactly 2 * 4.5; None keeps Brax's, and Brax's losses are themselves again outside."""
    from brax.training.agents.sac import losses
    from brax.training.agents.sac import train as sac

    brax = _alpha_loss(np.log(2.0), None)
    np.testing.assert_allclose(_alpha_loss(np.log(2.0), -6.0) - brax, 2.0 * 4.5, rtol=1e-5)
    np.testing.assert_allclose(_alpha_loss(np.log(2.0), -1.5), brax, rtol=1e-6)
    assert sac.sac_losses is losses


def test_the_anchor_adds_its_weight_times_the_mean_squared_gap_of_the_mean_actions():
    """With an anchor (weight 2, a start policy) the policy's loss is Brax's plus 2 x the mean over the batch of the
    squared distance between the two policies' mean actions (tanh of the network's means): exactly Brax's at the
    start itself, Brax's plus that term elsewhere; Brax's losses are themselves again outside."""
    from brax.training import types
    from brax.training.agents.sac import losses, networks
    from brax.training.agents.sac import train as sac

    net = networks.make_sac_networks(5, 3, hidden_layer_sizes=(8,))
    start, moved = (net.policy_network.init(jax.random.PRNGKey(k)) for k in (1, 6))
    q_params = net.q_network.init(jax.random.PRNGKey(7))
    obs = jax.random.normal(jax.random.PRNGKey(2), (64, 5))
    transitions = types.Transition(obs, jnp.zeros((64, 3)), jnp.zeros(64), jnp.ones(64), obs)

    def actor_loss(anchor, params):
        with losses_in_sac(anchor=anchor):
            actor = sac.sac_losses.make_losses(sac_network=net, reward_scaling=1.0, discounting=0.99,
                                               action_size=3)[2]
        assert actor.__name__ == "actor_loss"  # the name the policy's own update is found by
        return float(actor(params, None, q_params, jnp.float32(0.5), transitions, jax.random.PRNGKey(3)))

    mean = lambda params: np.tanh(np.asarray(net.policy_network.apply(None, params, obs))[:, :3])
    gap = np.mean(np.sum((mean(moved) - mean(start)) ** 2, axis=1))
    assert gap > 0.01
    assert actor_loss((2.0, (None, start)), start) == actor_loss(None, start)
    np.testing.assert_allclose(actor_loss((2.0, (None, start)), moved) - actor_loss(None, moved), 2.0 * gap,
                               rtol=1e-4)
    assert sac.sac_losses is losses


def test_a_restored_checkpoint_is_replicated_over_the_devices_as_sacs_state_is(tmp_path):
    """Brax's SAC replaces its replicated normaliser and policy with what its `checkpoint.load` returns, then reads
    device 0's copy of each (`_unpmap`): inside the context every leaf has a leading axis of one copy a device,
    each the saved value bit for bit; outside, Brax's own load is back."""
    import functools

    from brax.training.acme import running_statistics, specs
    from brax.training.agents.sac import checkpoint, networks
    from brax.training.agents.sac import train as sac

    factory = functools.partial(networks.make_sac_networks, hidden_layer_sizes=(8,))
    policy = factory(observation_size=5, action_size=3).policy_network.init(jax.random.PRNGKey(4))
    normaliser = running_statistics.update(running_statistics.init_state(specs.Array((5,), jnp.float32)),
                                           jax.random.normal(jax.random.PRNGKey(5), (7, 5)))
    checkpoint.save(tmp_path, 40, (normaliser, policy), checkpoint.network_config(5, 3, True, factory))
    saved = jax.tree_util.tree_leaves(checkpoint.load(tmp_path / f"{40:012d}"))
    with replicated_restore_in_sac():
        loaded = jax.tree_util.tree_leaves(sac.checkpoint.load(tmp_path / f"{40:012d}"))
    assert sac.checkpoint is checkpoint and len(loaded) == len(saved)
    for copies, value in zip(loaded, saved):
        assert len(copies.addressable_shards) == jax.local_device_count()
        for shard in copies.addressable_shards:
            np.testing.assert_array_equal(np.asarray(shard.data).squeeze(0), np.asarray(value))


def _losses():
    """An actor loss and a critic loss, as Brax's SAC names them, each pulling two parameters from 0 to 1."""
    def actor_loss(params, target):
        return jnp.sum((params - target) ** 2)

    def critic_loss(params, target):
        return jnp.sum((params - target) ** 2)

    return actor_loss, critic_loss


def _trajectory(loss_fn, optimizer, steps=5):
    """The parameters after each of `steps` updates Brax's SAC builds for `loss_fn`, from 0 towards 1."""
    from brax.training.agents.sac import train as sac

    start, target = jnp.zeros(2), jnp.ones(2)
    update = sac.gradients.gradient_update_fn(loss_fn, optimizer, pmap_axis_name=None)
    params, state, seen = start, optimizer.init(start), []
    for _ in range(steps):
        _, params, state = update(params, target, optimizer_state=state)
        seen.append(np.asarray(params))
    return seen


def test_sac_holds_its_policy_for_the_given_updates_and_trains_its_critic_meanwhile():
    """Inside the context Brax's SAC builds an actor update that leaves the policy's parameters exactly as they were
    for its first 3 steps and moves them from the 4th on; any other loss (the critic's) moves from its first step;
    outside the context Brax's own update moves the actor at once."""
    import optax
    from brax.training import gradients
    from brax.training.agents.sac import train as sac

    (actor_loss, critic_loss), optimizer, start = _losses(), optax.adam(0.1), np.zeros(2)
    trajectory = lambda loss: _trajectory(loss, optimizer)
    with policy_update_in_sac(held_updates=3):
        actor, critic = trajectory(actor_loss), trajectory(critic_loss)
    assert all(np.array_equal(p, start) for p in actor[:3]) and not np.array_equal(actor[3], start)
    assert not np.array_equal(critic[0], start)
    assert sac.gradients is gradients and not np.array_equal(trajectory(actor_loss)[0], start)
    with policy_update_in_sac(0):
        assert sac.gradients is gradients


def test_sacs_policy_takes_its_own_adam_step_and_its_critic_keeps_braxs():
    """Adam's first step moves each parameter by its learning rate (the gradient's sign times the rate): inside the
    context the actor moves 0.01 where the optimizer Brax gave it says 0.1, the critic 0.1; outside, both 0.1."""
    import optax
    from brax.training import gradients
    from brax.training.agents.sac import train as sac

    (actor_loss, critic_loss), optimizer = _losses(), optax.adam(0.1)
    with policy_update_in_sac(learning_rate=0.01):
        actor, critic = _trajectory(actor_loss, optimizer, 1)[0], _trajectory(critic_loss, optimizer, 1)[0]
    np.testing.assert_allclose(actor, [0.01, 0.01], rtol=1e-5)
    np.testing.assert_allclose(critic, [0.1, 0.1], rtol=1e-5)
    assert sac.gradients is gradients
    np.testing.assert_allclose(_trajectory(actor_loss, optimizer, 1)[0], [0.1, 0.1], rtol=1e-5)
