"""Replay memories: ring overwrite, proportional priorities, importance weights, save/restore."""

import numpy as np
import pytest

from hptrack.learning.replay import PRIORITY_EPS, PrioritizedReplayBuffer, ReplayBuffer


def _fill(buffer, count, dim=3):
    for i in range(count):
        buffer.add(np.full(dim, i), i % 4, float(i), np.full(dim, i + 1), i % 5 == 0)


def test_ring_buffer_overwrites_the_oldest():
    buffer = ReplayBuffer(5, 3)
    _fill(buffer, 7)
    assert len(buffer) == 5
    assert sorted(buffer.reward.tolist()) == [2.0, 3.0, 4.0, 5.0, 6.0]
    batch = buffer.sample(64, np.random.default_rng(0))
    np.testing.assert_array_equal(batch["obs"][:, 0], batch["reward"])
    np.testing.assert_array_equal(batch["next_obs"][:, 0], batch["reward"] + 1)
    np.testing.assert_array_equal(batch["weight"], 1.0)


def test_uniform_sampling_covers_only_filled_slots():
    buffer = ReplayBuffer(100, 2)
    _fill(buffer, 10, dim=2)
    index = buffer.sample(1000, np.random.default_rng(1))["index"]
    assert index.min() == 0 and index.max() == 9


def test_priorities_set_the_sampling_frequencies_and_weights():
    buffer = PrioritizedReplayBuffer(8, 1, alpha=0.6)
    _fill(buffer, 6, dim=1)
    errors = np.array([0.5, 1.0, 2.0, 4.0, 0.0, 3.0])
    buffer.update_priorities(np.arange(6), errors)
    p = (errors + PRIORITY_EPS) ** 0.6
    p /= p.sum()
    rng = np.random.default_rng(2)
    counts = np.zeros(6)
    for _ in range(400):
        batch = buffer.sample(32, rng, beta=0.5)
        counts += np.bincount(batch["index"], minlength=6)
    np.testing.assert_allclose(counts / counts.sum(), p, atol=0.01)
    batch = buffer.sample(32, rng, beta=0.5)
    w = (6 * p[batch["index"]]) ** -0.5
    np.testing.assert_allclose(batch["weight"], w / w.max(), rtol=1e-9)


def test_new_transitions_get_the_largest_priority():
    buffer = PrioritizedReplayBuffer(4, 1)
    _fill(buffer, 2, dim=1)
    buffer.update_priorities(np.array([0, 1]), np.array([5.0, 0.1]))
    buffer.add(np.zeros(1), 0, 0.0, np.zeros(1), False)
    leaves = buffer.tree[buffer._leaves : buffer._leaves + 3]
    assert leaves[2] == pytest.approx(leaves[0])
    assert buffer.tree[1] == pytest.approx(leaves.sum())


@pytest.mark.parametrize("kind", [ReplayBuffer, PrioritizedReplayBuffer])
def test_state_dict_round_trip_replays_the_same(kind):
    a = kind(10, 3)
    _fill(a, 13)
    if kind is PrioritizedReplayBuffer:
        a.update_priorities(np.arange(4), np.array([1.0, 2.0, 0.5, 3.0]))
    b = kind(10, 3)
    b.load_state_dict({k: np.array(v) for k, v in a.state_dict().items()})
    batch_a = a.sample(16, np.random.default_rng(3))
    batch_b = b.sample(16, np.random.default_rng(3))
    for key in batch_a:
        np.testing.assert_array_equal(batch_a[key], batch_b[key])
    assert b.cursor == a.cursor and len(b) == len(a)
