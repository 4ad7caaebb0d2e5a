"""Brax's SAC as train.py runs it: a ring replay buffer in place of its `UniformSamplingQueue`, and (below) the
entropy its temperature aims at and an anchor to a policy it starts from (its losses), a resume that works, and a
policy held while its critic first learns or stepped slower than it (its update).

Brax's queue keeps the newest `max_replay_size` transitions by rolling the whole buffer on every insert
once it is full (`jnp.roll` inside the training step): a copy of the entire replay per batch of env steps.
Measured inside a scan as Brax runs it, for a 1 M replay over 2 devices (500 000 rows of 62 floats each):
112 ms per insert against 0.07 ms for a ring write (load 17; docs/learning-notebook.md), where a whole SAC training
step took ~100 ms: SAC's env steps/s halved once its replay filled. The ring overwrites the oldest rows in
place and samples uniformly over the filled rows: the same transitions kept, drawn from the same
distribution; only their order in memory differs.
"""

from __future__ import annotations

import contextlib
import types

import jax
import jax.numpy as jnp
from brax.training import replay_buffers


class RingReplay(replay_buffers.UniformSamplingQueue):
    """Uniform sampling over the newest transitions, written in a ring. Its state reuses Brax's fields:
    `insert_position` counts the filled rows (up to the capacity), `sample_position` is the next row written."""

    def insert_internal(self, buffer_state, samples):
        update = self._flatten_fn(samples)
        capacity, n = buffer_state.data.shape[0], update.shape[0]
        rows = (buffer_state.sample_position + jnp.arange(n)) % capacity
        return buffer_state.replace(data=buffer_state.data.at[rows].set(update),
                                    insert_position=jnp.minimum(buffer_state.insert_position + n, capacity),
                                    sample_position=(buffer_state.sample_position + n) % capacity)

    def sample_internal(self, buffer_state):
        key, sample_key = jax.random.split(buffer_state.key)
        rows = jax.random.randint(sample_key, (self._sample_batch_size,), 0, buffer_state.insert_position)
        return buffer_state.replace(key=key), self._unflatten_fn(jnp.take(buffer_state.data, rows, axis=0))

    def size(self, buffer_state):
        return buffer_state.insert_position


@contextlib.contextmanager
def in_brax(train, module: str, **replaced):
    """Within this context the Brax `train` module `train` (PPO's or SAC's) sees its imported module `module` with
    the attributes `replaced`; the module itself, and every other user of it, is left as it is."""
    original = getattr(train, module)
    setattr(train, module, types.SimpleNamespace(**{**vars(original), **replaced}))
    try:
        yield
    finally:
        setattr(train, module, original)


def _in_sac(module: str, **replaced):
    from brax.training.agents.sac import train as sac

    return in_brax(sac, module, **replaced)


def ring_replay_in_sac():
    """Brax's SAC `train` builds its replay as `replay_buffers.UniformSamplingQueue(...)`: here, a `RingReplay`."""
    return _in_sac("replay_buffers", UniformSamplingQueue=RingReplay)


def losses_in_sac(nats: float | None = None, anchor: tuple | None = None):
    """SAC's losses as Brax makes them (`losses.make_losses`), with two optional changes:
    - `nats`: the policy entropy its temperature aims at. Brax aims at -0.5 nats per action dimension (the
      `target_entropy` of `make_losses`, which reads `action_size` for nothing else); None leaves Brax's target.
    - `anchor` = (weight, (normaliser, policy params)): the policy's loss gains weight x the squared distance between
      its mean action and that policy's, on the batch's observations, each through its own normaliser (a
      behaviour-cloning term towards a policy it started from, so that a fresh critic's gradient cannot pull it
      far from it). None leaves Brax's actor loss."""
    if nats is None and anchor is None:
        return contextlib.nullcontext()
    from brax.training.agents.sac import losses

    def make_losses(*, sac_network, action_size, **kwargs):
        made = losses.make_losses(sac_network=sac_network, action_size=action_size if nats is None else -2.0 * nats,
                                  **kwargs)
        return made if anchor is None else (*made[:2], _anchored(made[2], sac_network, *anchor))

    return _in_sac("sac_losses", make_losses=make_losses)


def _anchored(actor_loss, sac_network, weight: float, start):
    """Brax's `actor_loss` plus `weight` x the mean squared distance of the mean actions from `start`'s."""
    start_normaliser, start_policy = start

    def mean_action(normaliser, params, observation):
        parameters = sac_network.policy_network.apply(normaliser, params, observation)
        return sac_network.parametric_action_distribution.mode(parameters)

    def anchored(policy_params, normalizer_params, q_params, alpha, transitions, key):
        observation = transitions.observation
        gap = mean_action(normalizer_params, policy_params, observation) - jax.lax.stop_gradient(
            mean_action(start_normaliser, start_policy, observation))
        loss = actor_loss(policy_params, normalizer_params, q_params, alpha, transitions, key)
        return loss + weight * jnp.mean(jnp.sum(gap**2, axis=-1))

    anchored.__name__ = actor_loss.__name__  # `policy_update_in_sac` finds the actor's update by this name
    return anchored


def replicated_restore_in_sac():
    """Brax 0.14.2's SAC `train` puts a restored checkpoint's normaliser and policy into its training state as
    `checkpoint.load` returns them, on no device axis, where the state is replicated over the devices: its first
    evaluation then fails ('numpy.ndarray' object has no attribute 'addressable_shards'), so no SAC run could
    resume. Here `checkpoint.load` returns them replicated, as the state is."""
    from brax.training.agents.sac import checkpoint

    def load(path):
        return jax.device_put_replicated(checkpoint.load(path), jax.local_devices())

    return _in_sac("checkpoint", load=load)


def policy_update_in_sac(held_updates: int = 0, learning_rate: float | None = None):
    """Brax's SAC updates its policy with the Q networks' Adam step, from its first gradient step on, against Q
    networks just initialised: a policy it starts from (train.py --start-from) is pulled wherever the untrained
    critic points, by steps of the critic's size. Here the policy's update differs in two ways, each optional:
    - held: its loss is zeroed for its first `held_updates` gradient steps, while the Q networks and the temperature
      learn (Adam's step count runs on, its moments stay zero, and the policy's parameters stay exactly as they were);
    - its own Adam step, `learning_rate` (a policy slower than its critic; Brax has one rate for both).
    With neither, Brax's SAC is left as it is."""
    if not held_updates and learning_rate is None:
        return contextlib.nullcontext()
    import optax
    from brax.training import gradients

    def gradient_update_fn(loss_fn, optimizer, pmap_axis_name, has_aux=False):
        update = gradients.gradient_update_fn
        if getattr(loss_fn, "__name__", "") != "actor_loss":  # Brax's alpha and critic losses are left alone
            return update(loss_fn, optimizer, pmap_axis_name, has_aux)
        if learning_rate is not None:  # the same Adam but its step: the state Brax made for it fits as it is
            optimizer = optax.adam(learning_rate=learning_rate)
        if not held_updates:
            return update(loss_fn, optimizer, pmap_axis_name, has_aux)

        def held(*args, optimizer_state):
            on = (optax.tree_utils.tree_get(optimizer_state, "count") >= held_updates).astype(jnp.float32)
            scaled = lambda *a: on * loss_fn(*a)
            return update(scaled, optimizer, pmap_axis_name, has_aux)(*args, optimizer_state=optimizer_state)

        return held

    return _in_sac("gradients", gradient_update_fn=gradient_update_fn)
