"""The exact optimum of the sub-task MDP (exhaustive expectimax) on the paper's flight, and the
tree search converging to it."""

from dataclasses import replace
from pathlib import Path

import pytest

from hptrack.planning import PlanningProblem, search
from hptrack.planning.hierarchical import MctsSettings
from hptrack.planning.subtask_mdp import SubtaskOptions
from hptrack.planning.subtask_optimum import optimal_plan
from hptrack.scenario.io import load_scenario

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "paper-flight.yaml"


def paper_flight(budget=None):
    """The root of the paper's flight (two targets 20 m apart), its budget shortened if asked."""
    scenario = load_scenario(EXAMPLE)
    if budget is not None:
        scenario = scenario.model_copy(update={"budget": budget})
    return PlanningProblem.from_observation(
        scenario.mission_spec().record, scenario.initial_observation()
    )


@pytest.mark.parametrize("estimator", ["paper", "sharp"])
def test_the_max_backup_search_converges_to_the_exact_optimum(estimator):
    problem, options = paper_flight(20.0), SubtaskOptions(estimator=estimator)
    best = optimal_plan(problem, options)
    settings = MctsSettings(preset="improved", estimator=estimator)
    found = search(problem, settings.search_options(), options, iterations=20_000, seed=0)
    assert found.root.values.max() == pytest.approx(best.value, rel=1e-12)
    assert found.best_action == max(best.action_values, key=best.action_values.get)
    assert set(best.action_values) == {0, 1}


def test_the_best_plan_on_the_paper_flight_alternates():
    """Both estimators' best plans switch target after every find; the sharp estimator, which
    credits finds on the way, expects half the paper's U from it."""
    paper = optimal_plan(paper_flight())
    sharp = optimal_plan(paper_flight(), SubtaskOptions(estimator="sharp"))
    for best in (paper, sharp):
        switches = sum(a != b for a, b in zip(best.actions, best.actions[1:], strict=False))
        assert switches >= 15
        assert best.actions[-1] == best.actions[-2]  # the last find is followed to the end
        assert len(best.p_find) == len(best.steps) == len(best.actions)
    assert -paper.value == pytest.approx(15.607, abs=1e-3)
    assert -sharp.value == pytest.approx(7.123, abs=1e-3)
    # the paper's estimator gives a target found seconds earlier at most 0.94
    assert max(paper.p_find[2:-1]) < 0.95 < min(sharp.p_find[2:-1])


def test_replanning_values_only_the_current_action():
    best = optimal_plan(replace(paper_flight(20.0), current_action=1))
    assert list(best.action_values) == [1]
    assert best.actions[0] == 1


def test_too_large_a_problem_is_refused():
    with pytest.raises(ValueError, match="max_nodes=10 "):
        optimal_plan(paper_flight(), max_nodes=10)
