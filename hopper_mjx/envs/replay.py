"""Brax's SAC as train.py runs it: a ring replay buffer in place of its `UniformSamplingQueue`, and (below) the
entropy its temperature aims at, a resume that works and a policy held while its critic first learns.

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
def _in_sac(module: str, **replaced):
    """Within this context Brax's SAC `train` sees its imported module `module` with the attributes `replaced`;
    the module itself, and every other user of it, is left as it is."""
    from brax.training.agents.sac import train as sac

    original = getattr(sac, module)
    setattr(sac, module, types.SimpleNamespace(**{**vars(original), **replaced}))
    try:
        yield
    finally:
        setattr(sac, module, original)


def ring_replay_in_sac():
    """Brax's SAC `train` builds its replay as `replay_buffers.UniformSamplingQueue(...)`: here, a `RingReplay`."""
    return _in_sac("replay_buffers", UniformSamplingQueue=RingReplay)


def target_entropy_in_sac(nats: float | None):
    """Brax's SAC tunes its temperature towards a policy entropy of -0.5 nats per action dimension (the
    `target_entropy` of `losses.make_losses`, which reads `action_size` for nothing else); here it aims at `nats`
    instead. None leaves Brax's target."""
    if nats is None:
        return contextlib.nullcontext()
    from brax.training.agents.sac import losses

    def make_losses(*, action_size, **kwargs):
        return losses.make_losses(action_size=-2.0 * nats, **kwargs)

    return _in_sac("sac_losses", make_losses=make_losses)


def replicated_restore_in_sac():
    """Brax 0.14.2's SAC `train` puts a restored checkpoint's normaliser and policy into its training state as
    `checkpoint.load` returns them, on no device axis, where the state is replicated over the devices: its first
    evaluation then fails ('numpy.ndarray' object has no attribute 'addressable_shards'), so no SAC run could
    resume. Here `checkpoint.load` returns them replicated, as the state is."""
    from brax.training.agents.sac import checkpoint

    def load(path):
        return jax.device_put_replicated(checkpoint.load(path), jax.local_devices())

    return _in_sac("checkpoint", load=load)


def held_policy_in_sac(updates: int):
    """Brax's SAC updates its policy from its first gradient step on, against Q networks just initialised: a policy
    it starts from (train.py --start-from) is pulled wherever the untrained critic points. Here the policy's loss is
    zeroed for its first `updates` gradient steps, while the Q networks and the temperature learn: Adam's step count
    runs on, its moments stay zero, and the policy's parameters stay exactly as they were. 0 leaves Brax's SAC."""
    if not updates:
        return contextlib.nullcontext()
    import optax
    from brax.training import gradients

    def gradient_update_fn(loss_fn, optimizer, pmap_axis_name, has_aux=False):
        update = gradients.gradient_update_fn
        if getattr(loss_fn, "__name__", "") != "actor_loss":  # Brax's alpha and critic losses are left alone
            return update(loss_fn, optimizer, pmap_axis_name, has_aux)

        def held(*args, optimizer_state):
            on = (optax.tree_utils.tree_get(optimizer_state, "count") >= updates).astype(jnp.float32)
            scaled = lambda *a: on * loss_fn(*a)
            return update(scaled, optimizer, pmap_axis_name, has_aux)(*args, optimizer_state=optimizer_state)

        return held

    return _in_sac("gradients", gradient_update_fn=gradient_update_fn)
