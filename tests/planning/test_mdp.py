"""The sub-task MDP's arithmetic (paper Sec. IV-C-1/2) against step-by-step computations."""

import math

import numpy as np
import pytest

from hptrack.coverage.estimator import coverage_outcome
from hptrack.coverage.false_finds import false_find_split, take_rate
from hptrack.models.measurement import PositionMeasurementModel
from hptrack.models.mission import mission_record
from hptrack.models.motion import ConstantVelocityModel
from hptrack.planning.subtask_mdp import (
    FALSE_FIND,
    FIND,
    I_LAST,
    I_MASK,
    I_STEP,
    MISS,
    PlanningProblem,
    SubtaskOptions,
    apply_outcome,
    coverage_steps,
    dwell_steps,
    expand_action,
    expand_outcomes,
    intercept_of,
    is_available,
    n_actions,
    new_memo,
    new_work,
    outcomes_of,
    terminal_value,
)

TAU, SPEED, W = 0.5, 30.0, 100.0
R = np.array([[10.0, 1.5], [1.5, 12.0]])


def prior(var_x=1500.0, var_y=900.0, rho=0.4, var_v=(0.3, 0.45)):
    cov = np.diag([var_x, var_y, *var_v])
    cov[0, 1] = cov[1, 0] = rho * math.sqrt(var_x * var_y)
    return cov


def mission(n, q=3e-4, continuous=True):
    return mission_record(TAU, 900.0, SPEED, W, R, np.full(n, q), continuous)


MISSION = mission(1)


def make_problem(means, covs, budget=900.0, continuous=True, q=3e-4, **kw):
    means = np.asarray(means, dtype=float)
    n = len(means)
    return PlanningProblem(
        mission(n, q, continuous), np.zeros(2), means, np.asarray(covs, dtype=float), budget, **kw
    )


def predict(cov, q, k, continuous=True):
    """Eq. (1) one step at a time."""
    form = "continuous" if continuous else "paper_text"
    model = ConstantVelocityModel(TAU, form)
    f, qq = model.transition(), model.process_noise(q)
    for _ in range(k):
        cov = f @ cov @ f.T + qq
    return cov


def kalman(cov):
    sensor = PositionMeasurementModel(R)
    return sensor.update(np.zeros((1, 4)), cov[None], np.zeros((1, 2)))[1][0]


def hand_estimate(cov, q, max_steps):
    """Sec. IV-B by hand: ``P_cdf(k)`` from the step-by-step covariance, the first step after
    which it stops rising, and ``E[T_find]``."""

    def p_cdf(k):
        c = predict(cov, q, k)
        area = SPEED * W * k * TAU + math.pi * W * W / 4.0
        return 1.0 - math.exp(-area / (2.0 * math.pi * math.sqrt(c[0, 0] * c[1, 1] - c[0, 1] ** 2)))

    ps = [p_cdf(0)]
    while len(ps) - 1 < max_steps:
        nxt = p_cdf(len(ps))
        if nxt <= ps[-1]:
            break
        ps.append(nxt)
    k = len(ps) - 1
    return k, ps[-1], (k * ps[-1] - sum(ps[:-1])) / ps[-1]


def setup(problem, dwell=0.0, miss="drop"):
    """``env`` (with a dwell of ``dwell`` s), the root state and its arrays ``(si, sf, cov,
    step)`` (views of the state)."""
    state = problem.root_state()
    env = problem.env(SubtaskOptions(dwell=dwell, miss=miss))
    return env, state, *state


def test_interception_and_budget_truncation_by_hand():
    """Agent at the origin, mean 1000 m away on x: still target 1000/30 s = 66.7 -> 67 steps;
    one fleeing at 3 m/s 1000/27 s = 74.07 -> 75 steps. Their cutoffs (120 and 136 steps from
    the start of the coverage) make the sub-tasks 187 and 211 steps long: a 100 s budget
    truncates the second one only."""
    covs = [prior(), prior(2000.0, 2000.0, 0.0, (0.5, 0.5))]
    problem = make_problem([[1000, 0, 0, 0], [1000, 0, 3, 0]], covs, budget=100.0)
    env, state, si, sf, cov, step = setup(problem)
    assert problem.n_steps == 200
    got = [expand_action(env, state, a, new_work()) for a in (0, 1)]
    for a, ic in ((0, 67), (1, 75)):
        k, p, expected = hand_estimate(predict(covs[a], 3e-4, ic), 3e-4, 200 - ic)
        assert intercept_of(env, sf, a, 0) == ic
        assert got[a][0] == pytest.approx(p, rel=1e-12)
        assert got[a][1:] == (ic + round(expected), ic + k)
    assert got[0][2] == 187
    assert got[1][2] == 200


def test_a_coverage_limit_truncates_a_pursuit_as_the_budget_does():
    """The two targets above with the whole budget: their cutoffs (120 and 136 coverage steps)
    against a 30 s limit (60 steps): both coverages end after 60 steps, each chance of a find
    and finding time that of a coverage truncated there (Sec. IV-B by hand), under either
    estimator; a limit beyond both cutoffs changes nothing."""
    covs = [prior(), prior(2000.0, 2000.0, 0.0, (0.5, 0.5))]
    problem = make_problem([[1000, 0, 0, 0], [1000, 0, 3, 0]], covs)
    state = problem.root_state()
    limited = problem.env(SubtaskOptions(coverage_limit=30.0))
    assert limited.coverage_steps == 60 and problem.env().coverage_steps == -1
    for a, ic in ((0, 67), (1, 75)):
        k, p, expected = hand_estimate(predict(covs[a], 3e-4, ic), 3e-4, 60)
        assert k == 60
        got = expand_action(limited, state, a, new_work())
        assert got[0] == pytest.approx(p, rel=1e-12)
        assert got[1:] == (ic + round(expected), ic + 60)
        sharp = problem.env(SubtaskOptions(estimator="sharp", coverage_limit=30.0))
        assert expand_action(sharp, state, a, new_work())[2] == ic + 60
        unlimited = expand_action(problem.env(), state, a, new_work())
        assert unlimited[2] == ic + (120, 136)[a]
        beyond = problem.env(SubtaskOptions(coverage_limit=100.0))
        assert expand_action(beyond, state, a, new_work()) == unlimited


def test_coverage_limits_in_whole_steps():
    assert [coverage_steps(TAU, s) for s in (0.0, 30.0, 0.1, 10.26)] == [-1, 60, 1, 21]
    for bad in (-1.0, math.inf, math.nan):
        with pytest.raises(ValueError, match="coverage_limit must be a non-negative finite"):
            coverage_steps(TAU, bad)


def test_unavailable_actions():
    problem = make_problem(
        [[3000, 0, 0, 0], [100, 0, 31, 0], [100, 0, 0, 0]],
        [prior()] * 3,
        budget=100.0,
        available=[True, True, False],
    )
    env, state, *_ = setup(problem)
    # 3000 m takes exactly 200 steps: no coverage step left; faster than the agent; missed
    assert [is_available(env, state, a) for a in range(3)] == [False, False, False]


def test_find_miss_and_terminal_transitions_by_hand():
    q = 3e-4
    covs = [prior(), prior(700.0, 1200.0, -0.3, (0.25, 0.5))]
    means = np.array([[600.0, 800.0, 2.0, -1.0], [-500.0, 0.0, 0.0, 1.5]])
    problem = make_problem(means, covs)
    env, state, si, sf, cov, step = setup(problem)
    model = env
    work = new_work()
    p, find_steps, miss_steps = expand_action(env, state, 0, work)
    # find target 0: its belief is the posterior of a measurement at the end of the sub-task
    apply_outcome(env, state, 0, FIND, find_steps, work)
    t1 = find_steps
    assert (si[I_STEP], si[I_MASK], si[I_LAST]) == (t1, 0b11, 0)
    np.testing.assert_allclose(sf, means[0, :2] + means[0, 2:] * t1 * TAU, rtol=1e-12)
    np.testing.assert_allclose(cov[0], kalman(predict(covs[0], q, t1)), rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(cov[1], covs[1])  # grows implicitly from its base
    assert list(step) == [t1, 0]
    # pursue target 1 from target 0's estimated position (no memo: 1 is still at its base)
    ic1 = intercept_of(env, sf, 1, si[I_STEP])
    p1, find1, miss1 = expand_action(env, state, 1, work)
    t_start = t1 + ic1
    k, p_hand, expected = hand_estimate(predict(covs[1], q, t_start), q, model.n_steps - t_start)
    d, v = means[1, :2] + means[1, 2:] * t1 * TAU - sf, means[1, 2:]
    closing = SPEED**2 - v @ v
    t_hand = (d @ v + math.sqrt((d @ v) ** 2 + closing * (d @ d))) / closing  # |d + v t| = v_a t
    assert ic1 == math.ceil(t_hand / TAU)
    assert (p1, find1, miss1) == (pytest.approx(p_hand, rel=1e-12), ic1 + round(expected), ic1 + k)
    # miss target 1: it leaves the action list, nothing found
    apply_outcome(env, state, 1, MISS, miss1, work)
    t2 = t1 + miss1
    assert (si[I_STEP], si[I_MASK], si[I_LAST]) == (t2, 0b01, -1)
    np.testing.assert_allclose(sf, means[1, :2] + means[1, 2:] * t2 * TAU, rtol=1e-12)
    np.testing.assert_array_equal(cov[1], covs[1])
    # -U at the end of the budget: every belief grown from its base
    expected_u = sum(
        np.linalg.slogdet(predict(c, q, model.n_steps - s)[:2, :2])[1]
        for c, s in ((kalman(predict(covs[0], q, t1)), t1), (covs[1], 0))
    )
    assert terminal_value(env, state) == pytest.approx(-expected_u, rel=1e-12)


def test_intercept_of_a_moving_mean_from_a_later_state():
    """After 100 steps (50 s) the fleeing mean is at 1150 m: the agent at the origin needs
    1150 / 27 s = 42.59 s -> 86 steps."""
    problem = make_problem([[1000, 0, 3, 0], [0, 0, 0, 0]], [prior(), prior()])
    env, state, si, sf, cov, step = setup(problem)
    assert intercept_of(env, sf, 0, 100) == 86


def test_follow_to_the_end_after_a_find():
    q = 3e-4
    problem = make_problem([[900, 0, 1, 1], [0, 900, 0, 0]], [prior(), prior()])
    env, state, si, sf, cov, step = setup(problem)
    model = env
    work = new_work()
    _, find_steps, _ = expand_action(env, state, 0, work)
    apply_outcome(env, state, 0, FIND, find_steps, work)
    left = model.n_steps - find_steps
    assert expand_action(env, state, 0, work) == (1.0, left, left)
    apply_outcome(env, state, 0, FIND, left, work)
    expected = kalman(predict(prior(), q, find_steps))
    for _ in range(left):
        expected = kalman(predict(expected, q, 1))
    assert si[I_STEP] == model.n_steps
    np.testing.assert_allclose(cov[0], expected, rtol=1e-9, atol=1e-12)
    assert not any(is_available(env, state, a) for a in range(2))


def test_a_sub_task_lasts_at_least_one_step():
    """Agent on a tiny belief: no intercept, the target is found at once (P_cdf = 1, E = 0)."""
    tiny = np.diag([1.0, 1.0, 0.01, 0.01])
    problem = make_problem([[0, 0, 0, 0]], [tiny])
    env, state, *_ = setup(problem)
    cutoff, p, expected = coverage_outcome(MISSION, tiny, 3e-4, 1800)
    assert (p, expected) == (1.0, 0.0)
    assert expand_action(env, state, 0, new_work()) == (1.0, 1, cutoff)


def test_memo_gives_the_same_expansion():
    problem = make_problem([[400, -300, 1, 0], [-800, 100, 0, 2]], [prior(), prior()])
    env, state, *_ = setup(problem)
    first = [expand_action(env, state, a, new_work()) for a in (0, 1)]
    assert (env.memo.cutoff >= 0).sum() == 2
    again = [expand_action(env, state, a, new_work()) for a in (0, 1)]
    other = env._replace(memo=new_memo(2, env.n_steps))
    fresh = [expand_action(other, state, a, new_work()) for a in (0, 1)]
    assert first == again == fresh


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(means=np.zeros((2, 3))), "shape"),
        (dict(covariances=np.zeros((1, 4, 4))), "covariances"),
        (dict(remaining_budget=0.0), "remaining_budget"),
        (dict(available=[True, False], current_action=1), "current_action"),
        (dict(last_found=2), "last_found"),
        (dict(mission=mission(0)), "1 to 256 targets"),
    ],
)
def test_problem_validation(change, message):
    base = dict(
        mission=mission(2),
        agent_position=np.zeros(2),
        means=np.zeros((2, 4)),
        covariances=np.array([prior()] * 2),
        remaining_budget=900.0,
    )
    with pytest.raises(ValueError, match=message):
        PlanningProblem(**(base | change))


def test_problem_arrays_are_frozen_copies():
    means = np.zeros((1, 4))
    problem = make_problem(means, [prior()], available=[True], last_found=0)
    means[0, 0] = 5.0
    assert problem.means[0, 0] == 0.0
    assert not problem.means.flags.writeable
    assert problem.n_steps == 1800
    assert problem.root_state()[0].tolist() == [0, 1, 0]


def test_dwell_measures_the_target_just_found_at_every_step_and_keeps_it_last():
    """The dwell (an option beyond the paper): action ``n`` after a find lasts ``dwell_steps``,
    has ``p_find = 1``, and leaves the found target measured at every step of it (by hand: one
    prediction and update per step); the agent ends on its mean and it stays the last found,
    so it can be followed or dwelt on again."""
    q = 3e-4
    means = [[900, 0, 1, 1], [0, 900, 0, 0]]
    problem = make_problem(means, [prior(), prior()])
    assert n_actions(2, SubtaskOptions(dwell=10.0)) == 3
    env, state, si, sf, cov, step = setup(problem, dwell=10.0)
    assert env.stay_steps.tolist() == [20]
    work = new_work()
    assert not is_available(env, state, 2)  # nothing found yet
    _, find_steps, _ = expand_action(env, state, 0, work)
    apply_outcome(env, state, 0, FIND, find_steps, work)
    assert is_available(env, state, 2)
    assert expand_action(env, state, 2, work) == (1.0, 20, 20)
    apply_outcome(env, state, 2, FIND, 20, work)
    expected = kalman(predict(prior(), q, find_steps))
    for _ in range(20):
        expected = kalman(predict(expected, q, 1))
    np.testing.assert_allclose(cov[0], expected, rtol=1e-9, atol=1e-12)
    end = find_steps + 20
    assert (si[I_STEP], si[I_LAST], step[0], si[I_MASK]) == (end, 0, end, 0b11)
    np.testing.assert_allclose(sf, [900 + end * TAU, end * TAU])
    # dwelling, then following to the end, is following from the find to the end
    left = env.n_steps - end
    apply_outcome(env, state, 0, FIND, expand_action(env, state, 0, work)[1], work)
    followed = make_problem(means, [prior(), prior()])
    env2, state2, si2, sf2, cov2, step2 = setup(followed)
    apply_outcome(env2, state2, 0, FIND, find_steps, work)
    apply_outcome(env2, state2, 0, FIND, 20 + left, work)
    np.testing.assert_allclose(cov[0], cov2[0], rtol=1e-9, atol=1e-12)
    assert terminal_value(env, state) == pytest.approx(terminal_value(env2, state2), rel=1e-12)


def test_dwell_is_available_only_after_a_find_and_before_the_budget_ends():
    problem = make_problem([[0, 0, 0, 0]], [prior()], budget=30.0, last_found=0)
    assert dwell_steps(TAU, 14.75) == 30  # 29.5 steps: the nearest whole step, 30
    env, state, *_ = setup(problem, dwell=14.75)
    assert is_available(env, state, 1)  # 30 < 60 steps left
    short = make_problem([[0, 0, 0, 0]], [prior()], budget=15.0, last_found=0)
    env, state, *_ = setup(short, dwell=14.75)
    assert not is_available(env, state, 1)  # 30 steps is the whole budget: that is the follow
    env, state, *_ = setup(make_problem([[0, 0, 0, 0]], [prior()], last_found=0))
    assert not is_available(env, state, 1)  # no dwell action without the option
    assert (dwell_steps(TAU, 0.0), n_actions(1, SubtaskOptions())) == (0, 1)
    assert dwell_steps(TAU, 0.1) == 1
    with pytest.raises(ValueError, match="current_action=1"):
        make_problem([[0, 0, 0, 0]], [prior()], current_action=1)  # nothing found: no dwell
    with pytest.raises(ValueError, match="dwell must be"):
        dwell_steps(TAU, -1.0)
    make_problem([[0, 0, 0, 0]], [prior()], last_found=0, current_action=1)


def test_several_dwell_lengths_are_one_action_each_after_the_targets():
    """``dwell=(5, 10, 40)`` s: actions ``n``, ``n + 1`` and ``n + 2`` dwell 10, 20 and 80
    steps (``p_find = 1``), each available after a find while it ends before the budget; the
    measured covariance is the one of a single dwell of the same length."""
    means = [[900, 0, 1, 1], [0, 900, 0, 0]]
    problem = make_problem(means, [prior(), prior()], budget=30.0, last_found=0)
    options = SubtaskOptions(dwell=(5.0, 10.0, 40.0))
    assert n_actions(2, options) == 5
    env = problem.env(options)
    state = problem.root_state()
    work = new_work()
    assert env.stay_steps.tolist() == [10, 20, 80]
    assert [is_available(env, state, a) for a in (2, 3, 4)] == [True, True, False]  # 60 left
    assert expand_action(env, state, 3, work) == (1.0, 20, 20)
    apply_outcome(env, state, 3, FIND, 20, work)
    single = make_problem(means, [prior(), prior()], budget=30.0, last_found=0)
    env1, state1, *_ = setup(single, dwell=10.0)
    apply_outcome(env1, state1, 2, FIND, 20, work)
    np.testing.assert_array_equal(state[2], state1[2])
    assert state[0].tolist() == state1[0].tolist() == [20, 0b11, 0]
    with pytest.raises(ValueError, match="current_action=5"):
        make_problem(means, [prior(), prior()], last_found=0, current_action=5).env(options)


def test_a_miss_drops_the_target_as_in_the_paper_or_keeps_it_to_pursue_again():
    """``miss="drop"`` (the paper): the missed target leaves the action list. ``"keep"``: it
    stays, its belief unmeasured (its base unchanged, so it grows on from the root), and it can
    be pursued again, now from a larger covariance: a longer coverage."""
    problem = make_problem([[900, 0, 1, 1], [0, 900, 0, 0]], [prior(), prior()])
    work = new_work()
    for miss, mask in (("drop", 0b10), ("keep", 0b11)):
        env, state, si, sf, cov, step = setup(problem, miss=miss)
        p, find_steps, miss_steps = expand_action(env, state, 0, work)
        apply_outcome(env, state, 0, MISS, miss_steps, work)
        assert (si[I_STEP], si[I_MASK], si[I_LAST], step[0]) == (miss_steps, mask, -1, 0)
        np.testing.assert_array_equal(cov[0], prior())
        assert is_available(env, state, 0) == (miss == "keep")
    again = expand_action(env, state, 0, work)
    assert again[0] < p and again[2] > miss_steps - intercept_of(env, sf, 0, 0)
    with pytest.raises(ValueError, match="miss must be one of"):
        problem.env(SubtaskOptions(miss="forget"))


def test_passes_credit_the_targets_a_flight_crosses():
    """``passes="credit"``: pursuing target 0 900 m east flies over target 1, 450 m east, whose
    belief is small: it is measured at the closest approach (half-way, by the step rounding of
    the MDP) and, dropped before, is back in the action list. Target 2, 400 m off the line, is
    not measured; with the paper's ``"ignore"`` neither is."""
    small = prior(100.0, 100.0, 0.0)
    means = [[900, 0, 0, 0], [450, 0, 0, 0], [450, 400, 0, 0]]
    problem = make_problem(means, [prior(), small, small], available=[True, False, True])
    work = new_work()
    for passes in ("ignore", "credit"):
        state = problem.root_state()
        si, sf, cov, step = state
        env = problem.env(SubtaskOptions(passes=passes))
        p, find_steps, miss_steps = expand_action(env, state, 0, work)
        apply_outcome(env, state, 0, FIND, find_steps, work)
        np.testing.assert_array_equal(cov[2], small)
        if passes == "ignore":
            assert (step[1], si[I_MASK]) == (0, 0b101)
            np.testing.assert_array_equal(cov[1], small)
        else:
            k = math.floor(find_steps / 2 + 0.5)
            assert (step[1], si[I_MASK]) == (k, 0b111)
            np.testing.assert_allclose(cov[1], kalman(predict(small, 3e-4, k)), rtol=1e-9)
        assert (si[I_STEP], si[I_LAST], step[0], step[2]) == (find_steps, 0, find_steps, 0)
    with pytest.raises(ValueError, match="passes must be one of"):
        problem.env(SubtaskOptions(passes="always"))


def _scaled_by_hand(cov, c):
    """The position block times ``c``, the rest by the regression on the position."""
    s, b = cov[:2, :2], cov[2:, :2]
    k = b @ np.linalg.inv(s)
    out = cov.copy()
    out[:2, :2] = c * s
    out[2:, :2] = c * b
    out[:2, 2:] = out[2:, :2].T
    out[2:, 2:] = cov[2:, 2:] + (c - 1.0) * k @ s @ k.T
    return out


@pytest.mark.parametrize("pd", [1.0, 0.7])
def test_negative_information_scales_the_covariance_a_miss_leaves(pd):
    """With ``negative_information`` a missed pursuit's covariance, predicted to the miss's end,
    is scaled by the closed form of a look over the swept Mahalanobis disc: at ``Pd = 1`` by
    ``1 + a``, ``a = -ln(1 - p_find)``; below, ``a = -ln(1 - p_find) / eta`` and the disc
    detected with ``p_find / (1 - e^-a)``. ``miss="keep"`` pursues it again from there."""
    q = 3e-4
    record = mission_record(
        TAU, 900.0, SPEED, W, R, np.full(2, q), True, None, pd, negative_information=True
    )
    means = np.array([[900.0, 0, 1, 1], [0, 900.0, 0, 0]])
    problem = PlanningProblem(record, np.zeros(2), means, np.array([prior(), prior()]), 900.0)
    work = new_work()
    env, state, si, sf, cov, step = setup(problem, miss="keep")
    p, _, miss_steps = expand_action(env, state, 0, work)
    apply_outcome(env, state, 0, MISS, miss_steps, work)
    eta = record.sensor.find_factor
    a = -math.log(1.0 - p) / eta
    detect = p / (1.0 - math.exp(-a))
    c = (2.0 * (1.0 - detect) + detect * math.exp(-a) * (2.0 * a + 2.0)) / (
        2.0 * (1.0 - detect * (1.0 - math.exp(-a)))
    )
    if pd == 1.0:
        assert eta == 1.0 and detect == pytest.approx(1.0) and c == pytest.approx(1.0 + a)
    else:
        assert 0.7 < eta < 1.0 and detect < 1.0
    assert c > 1.2  # the miss widens the belief by more than the tolerance below
    want = _scaled_by_hand(predict(prior(), q, miss_steps), c)
    np.testing.assert_allclose(cov[0], want, rtol=1e-5, atol=1e-9)  # (the floor: ~1e-7)
    assert (si[I_MASK], step[0], step[1]) == (0b11, miss_steps, 0)
    # pursued again from the belief the miss left
    again = expand_action(env, state, 0, work)
    ic = intercept_of(env, sf, 0, si[I_STEP])
    k, p_hand, _ = hand_estimate(predict(want, q, ic), q, env.n_steps - si[I_STEP] - ic)
    if pd == 1.0:
        assert again[0] == pytest.approx(p_hand, rel=1e-5) and again[2] == ic + k
    # the default record (no negative information) leaves the base as it was
    plain = make_problem(means, [prior(), prior()])
    env, state, si, sf, cov, step = setup(plain, miss="keep")
    apply_outcome(env, state, 0, MISS, expand_action(env, state, 0, work)[2], work)
    np.testing.assert_array_equal(cov[0], prior())
    assert step[0] == 0


def _cluttered(n: int, density: float = 1e-6):
    return mission_record(TAU, 900.0, SPEED, W, R, np.full(n, 3e-4), false_alarm_density=density)


def test_false_finds_split_a_pursuit_into_three_outcomes_only_when_modelled():
    """With the mission's clutter and ``false_finds="model"`` a pursuit's find and miss lose
    the chance of a false alarm taken first (`false_find_split` at the take rate of the belief
    predicted to the spiral's start); a follow has no false find; ``"ignore"`` or no clutter
    leave the paper's two outcomes exactly."""
    means = np.array([[900.0, 0, 1, 1], [0, 900.0, 0, 0]])
    covs = np.array([prior(), prior()])
    problem = PlanningProblem(_cluttered(2), np.zeros(2), means, covs, 900.0)
    work = new_work()
    plain = problem.env(SubtaskOptions())
    modelled = problem.env(SubtaskOptions(false_finds="model"))
    assert (outcomes_of(plain), outcomes_of(modelled)) == (2, 3)
    quiet = PlanningProblem(mission(2), np.zeros(2), means, covs, 900.0)
    assert outcomes_of(quiet.env(SubtaskOptions(false_finds="model"))) == 2
    state = problem.root_state()
    p_find, find_steps, miss_steps = expand_action(plain, state, 0, work)
    p, payload = np.empty(3), np.empty(3, dtype=np.int64)
    expand_outcomes(modelled, state, 0, p, payload, work)
    ic = intercept_of(modelled, state[1], 0, 0)
    cov = predict(prior(), 3e-4, ic)
    rate = take_rate(1e-6, W / 2, cov[0, 0], cov[0, 1], cov[1, 1], R[0, 0], R[0, 1], R[1, 1])
    assert rate > 0.0
    split = false_find_split(p_find, find_steps - ic, miss_steps - ic, rate)
    np.testing.assert_allclose(p, [split[0], split[1], split[2]], rtol=1e-9)
    assert p.sum() == pytest.approx(1.0) and p[FIND] < p_find and p[FALSE_FIND] > 0.0
    assert payload[FIND] == find_steps and payload[MISS] == miss_steps
    assert payload[FALSE_FIND] == max(1, ic + math.floor(split[3] + 0.5))
    two_p, two_payload = np.empty(2), np.empty(2, dtype=np.int64)
    expand_outcomes(modelled, state, 0, two_p, two_payload, work)
    assert two_p.tolist() == [p_find, 1.0 - p_find]  # no room for the third: the paper's
    with pytest.raises(ValueError, match="false_finds must be one of"):
        problem.env(SubtaskOptions(false_finds="maybe"))


def test_a_false_find_ends_the_search_having_learnt_nothing():
    """After a false find the target's belief is as before (its base unchanged), it leaves
    the action list (``miss="drop"``) or stays (``"keep"``), and nothing is the last found."""
    means = np.array([[900.0, 0, 1, 1], [0, 900.0, 0, 0]])
    problem = PlanningProblem(_cluttered(2), np.zeros(2), means, np.array([prior()] * 2), 900.0)
    work = new_work()
    for miss, mask in (("drop", 0b10), ("keep", 0b11)):
        env = problem.env(SubtaskOptions(false_finds="model", miss=miss))
        state = problem.root_state()
        si, _, cov, step = state
        p, payload = np.empty(3), np.empty(3, dtype=np.int64)
        expand_outcomes(env, state, 0, p, payload, work)
        apply_outcome(env, state, 0, FALSE_FIND, payload[FALSE_FIND], work)
        assert (si[I_STEP], si[I_MASK], si[I_LAST], step[0]) == (payload[FALSE_FIND], mask, -1, 0)
        np.testing.assert_array_equal(cov[0], prior())
