"""The ring replay SAC trains with keeps what Brax's queue keeps and samples it uniformly, without the roll."""

import jax
import jax.numpy as jnp
import numpy as np
from brax.training import replay_buffers

from hopper_mjx.envs.replay import RingReplay, ring_replay_in_sac

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
