import numpy as np
import pytest

from hptrack.models.measurement import kalman_update
from hptrack.models.miss_update import miss_update
from hptrack.models.motion import ConstantVelocityModel
from hptrack.runtime.beliefs import BeliefTimeline

MOTION = ConstantVelocityModel(0.5)
R = 2.0 * np.eye(2)


def _prior():
    means = np.array([[0.0, 0.0, 1.0, 0.5], [50.0, 0.0, -1.0, 0.0]])
    covs = np.stack([np.diag([9.0, 4.0, 0.5, 0.5]), np.diag([1.0, 1.0, 0.1, 0.1])])
    return means, covs, np.array([0.1, 0.01])


def _sequential(measurements, until):
    """Reference: predict over each gap and update, one measurement at a time, in time order."""
    means, covs, q = _prior()
    t = 0.0
    for tm, i, z in sorted(measurements, key=lambda m: m[0]):
        means, covs = MOTION.predict(means, covs, q, tm - t)
        kalman_update(means[i].copy(), covs[i].copy(), np.asarray(z), R, means[i], covs[i])
        t = tm
    return MOTION.predict(means, covs, q, until - t)


MEASUREMENTS = [
    (0.3, 0, (0.5, 0.2)),
    (1.7, 1, (48.0, 0.3)),
    (2.2, 0, (2.1, 1.0)),
    (2.9, 0, (2.8, 1.4)),
]


@pytest.mark.parametrize("order", [[0, 1, 2, 3], [0, 2, 3, 1], [3, 2, 1, 0]])
def test_late_measurements_within_the_tolerance_are_filtered_in_time_order(order):
    means, covs, q = _prior()
    timeline = BeliefTimeline(means, covs, q, MOTION, tolerance_s=5.0)
    for seq, j in enumerate(order):
        t, i, z = MEASUREMENTS[j]
        timeline.add(i, t, np.asarray(z), R, seq)
    got = timeline.at(4.25)
    want = _sequential(MEASUREMENTS, 4.25)
    np.testing.assert_allclose(got[0], want[0], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(got[1], want[1], rtol=1e-12, atol=1e-12)


def test_belief_between_measurements_ignores_the_later_ones():
    means, covs, q = _prior()
    timeline = BeliefTimeline(means, covs, q, MOTION, tolerance_s=5.0)
    for seq, (t, i, z) in enumerate(MEASUREMENTS):
        timeline.add(i, t, np.asarray(z), R, seq)
    got = timeline.at(2.0)
    want = _sequential(MEASUREMENTS[:2], 2.0)
    np.testing.assert_allclose(got[1], want[1], rtol=1e-12)


def test_settled_history_gives_the_same_beliefs():
    means, covs, q = _prior()
    timeline = BeliefTimeline(means, covs, q, MOTION, tolerance_s=0.1)
    for seq, (t, i, z) in enumerate(MEASUREMENTS):
        timeline.add(i, t, np.asarray(z), R, seq)
    assert timeline.horizon_s == pytest.approx(2.8)
    np.testing.assert_allclose(timeline.at(10.0)[1], _sequential(MEASUREMENTS, 10.0)[1], rtol=1e-12)


def test_duplicates_are_recognised():
    means, covs, q = _prior()
    timeline = BeliefTimeline(means, covs, q, MOTION, tolerance_s=5.0)
    timeline.add(0, 1.0, np.array([1.0, 2.0]), R, 0)
    assert timeline.is_duplicate(0, 1.0, np.array([1.0, 2.0]))
    assert not timeline.is_duplicate(0, 1.0, np.array([1.0, 2.5]))
    assert not timeline.is_duplicate(1, 1.0, np.array([1.0, 2.0]))


def _miss(agent_x, agent_y, mean, cov):
    """The footprint's miss (100 m, Pd 0.7) as the timeline calls it."""
    miss_update(mean, cov, agent_x, agent_y, 50.0, np.zeros(1), np.array([0.7]))


def test_misses_are_filtered_in_time_order_and_a_late_detection_takes_its_miss_out():
    """A miss at 1.0 s from (55, 1) m (over the flank of target 0), then a measurement at
    2.2 s: the beliefs as predicting, missing and updating one by one; a measurement of the
    look's interval that arrives after the miss takes it out (the look detected the target
    after all)."""
    means, covs, q = _prior()
    timeline = BeliefTimeline(means, covs, q, MOTION, tolerance_s=5.0, missed=_miss, look_s=0.5)
    timeline.add_miss(0, 1.0, np.array([55.0, 1.0]))
    timeline.add(0, 2.2, np.array([2.1, 1.0]), R, 0)
    m, c = MOTION.predict(means, covs, q, 1.0)
    _miss(55.0, 1.0, m[0], c[0])
    m, c = MOTION.predict(m, c, q, 1.2)
    kalman_update(m[0].copy(), c[0].copy(), np.array([2.1, 1.0]), R, m[0], c[0])
    want = MOTION.predict(m, c, q, 0.8)
    got = timeline.at(3.0)
    np.testing.assert_allclose(got[0], want[0], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(got[1], want[1], rtol=1e-12, atol=1e-12)
    moved = MOTION.predict(means, covs, q, 3.0)
    assert not np.allclose(got[1][0], _sequential([MEASUREMENTS[2]], 3.0)[1][0])
    np.testing.assert_allclose(got[1][1], moved[1][1], rtol=1e-12)  # target 1: untouched
    # a measurement taken at 0.7 s (in the look of the miss at 1.0 s) arrives: the miss goes
    timeline.add(0, 0.7, np.array([0.5, 0.2]), R, 1)
    both = [(0.7, 0, (0.5, 0.2)), (2.2, 0, (2.1, 1.0))]
    np.testing.assert_allclose(timeline.at(3.0)[1], _sequential(both, 3.0)[1], rtol=1e-12)
