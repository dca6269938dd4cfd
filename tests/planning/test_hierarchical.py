"""The hierarchical planner in the simulator (paper Fig. 2, Sec. IV-C-4)."""

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from hptrack.baselines.greedy import GreedyPlanner
from hptrack.cli.app import app
from hptrack.interface import InputError
from hptrack.planning import hierarchical, subtask_search
from hptrack.planning.hierarchical import HierarchicalPlanner, MctsSettings
from hptrack.scenario import random_scenario
from hptrack.scenario.io import parse_scenario
from hptrack.sim.episode import run_episode
from hptrack.subtasks import read_subtasks

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "paper-flight.yaml"


def mcts(**options):
    return HierarchicalPlanner(MctsSettings(**options))


def fresh_plan(record, entry):
    """Whether the planner searched afresh as ``entry`` began: more searches at its start than
    the one re-plan of a pursuit or a dwell (none for a follow)."""
    searches = [s["step"] for s in record.info["searches"]].count(entry.start_step)
    return searches > (entry.kind in ("pursue", "dwell"))


def test_conditional_plan_is_followed_and_misses_leave_the_list():
    record = run_episode(random_scenario(3, seed=2, homogeneous=True), mcts(iterations=2000))
    log = read_subtasks(record.info["subtasks"], record.target_ids)
    assert len(log) >= 3
    assert len(record.info["searches"]) >= len(log)
    assert all(
        s["stopped_by"] == "iterations" and s["simulations"] == 2000
        for s in record.info["searches"]
    )
    for done, nxt in zip(log, log[1:], strict=False):
        if done.outcome is None:
            break
        assert done.kind == "pursue" and nxt.start_step == done.end_step
        planned = done.after_find if done.outcome == "found" else done.after_miss
        if done.outcome == "missed":
            assert nxt.target != done.target
            assert planned is None or planned.kind == "pursue"
        else:
            assert record.detections[done.end_step, done.target]
            assert planned is None or planned.kind in ("pursue", "follow")
        # the plan is flown, or a fresh plan made when it can no longer be
        assert nxt.action == planned or fresh_plan(record, nxt)


def test_same_seed_same_mission():
    scenario = random_scenario(3, seed=5, homogeneous=True)
    a = run_episode(scenario, mcts(iterations=1000))
    b = run_episode(scenario, mcts(iterations=1000))
    np.testing.assert_array_equal(a.agent_path, b.agent_path)
    assert a.uncertainty == b.uncertainty


@pytest.mark.slow
def test_mcts_beats_greedy_on_twenty_three_target_scenarios():
    u_mcts, u_greedy = [], []
    for seed in range(20):
        scenario = random_scenario(3, seed=seed, homogeneous=True)
        u_mcts.append(run_episode(scenario, mcts(iterations=2000)).uncertainty)
        u_greedy.append(run_episode(scenario, GreedyPlanner()).uncertainty)
    assert np.mean(u_mcts) < np.mean(u_greedy) - 10.0


@pytest.mark.parametrize(
    "option, value, message",
    [
        ("iterations", 0, "planner 'mcts': option iterations must be >= 1, got 0"),
        ("iterations", "abc", "planner 'mcts': option iterations must be an integer, got 'abc'"),
        ("time_limit", -1.0, "planner 'mcts': option time_limit must be > 0, got -1.0"),
        ("exploration", -1, "planner 'mcts': option exploration must be > 0, got -1"),
        (
            "exploration",
            "nan",
            "planner 'mcts': option exploration must be a finite number, got 'nan'",
        ),
        ("exploration", float("inf"), "option exploration must be a finite number"),
        ("max_weight", 1.5, "planner 'mcts': option max_weight must be <= 1, got 1.5"),
        ("root_split", "uneven", "option root_split must be 'even' or 'weighted', got 'uneven'"),
        ("dwell", -5, "planner 'mcts': option dwell must be >= 0, got -5"),
        ("readmit", "maybe", "planner 'mcts': option readmit must be true or false, got 'maybe'"),
        ("commit", -1, "planner 'mcts': option commit must be >= 0, got -1"),
        ("coverage_limit", -5, "planner 'mcts': option coverage_limit must be >= 0, got -5"),
    ],
)
def test_invalid_settings_are_refused_naming_planner_option_and_value(option, value, message):
    with pytest.raises(InputError) as err:
        MctsSettings.from_options("mcts", {option: value})
    assert message in str(err.value)


def test_max_weight_without_the_max_backup_is_refused():
    with pytest.raises(
        InputError,
        match="planner 'mcts': option max_weight=0.5 applies only "
        "to backup=max, got backup=sampled",
    ):
        MctsSettings.from_options("mcts", {"preset": "paper", "max_weight": 0.5})
    assert MctsSettings.from_options("mcts", {"max_weight": 0.5}).max_weight == 0.5


def test_settings_default_effort_and_identity():
    default = MctsSettings()
    assert (default.iterations, default.time_limit) == (20_000, None)
    assert MctsSettings.from_options("mcts", {"iterations": "20000"}) == default
    timed = MctsSettings(time_limit=1.0)
    assert (timed.iterations, timed.time_limit) == (None, 1.0)
    assert default.preset == "revisit"  # the default since the default-effort scale benchmark
    assert default.canonical() == (
        '{"backup":"max","commit":0.0,"common_rollouts":false,"coverage_limit":0.0,"dwell":0.0,'
        '"estimator":"paper","exploration":0.5,"false_finds":"ignore","fortify":false,'
        '"iterations":20000,"max_weight":1.0,"miss":"drop","passes":"ignore","readmit":false,'
        '"rollout":"tour_plan","rollout_epsilon":0.1,"root_split":"even","threads":1,'
        '"time_limit":null}'
    )
    assert default.digest() != timed.digest()
    assert MctsSettings.from_options("mcts", default.as_json()) == default


def test_timed_runs_warm_the_kernels_before_the_first_search(monkeypatch):
    """The first timed search of a process must not pay the kernels' loading: reset runs a
    tiny search first (once per process)."""
    calls = []
    monkeypatch.setattr(subtask_search, "_warmed", set())
    real = subtask_search.search
    spy = lambda *a, **k: calls.append(k.get("iterations")) or real(*a, **k)  # noqa: E731
    monkeypatch.setattr(subtask_search, "search", spy)
    monkeypatch.setattr(hierarchical, "search", spy)
    scenario = random_scenario(2, seed=0).model_copy(update={"budget": 20.0})
    run_episode(scenario, mcts(time_limit=0.05))
    assert calls[:2] == [64, 64]  # the warm-up's two searches (first plan, re-plan)
    assert subtask_search._warmed
    calls.clear()
    run_episode(scenario, mcts(time_limit=0.05))
    assert 64 not in calls


def test_simulate_command_with_mcts(tmp_path):
    result = CliRunner().invoke(
        app,
        [
            "simulate",
            "--random",
            "--targets",
            "2",
            "--planner",
            "mcts",
            "--iterations",
            "500",
            "--json",
            str(tmp_path / "m.json"),
        ],
    )
    assert result.exit_code == 0, result.output
    assert "mcts mission" in result.output


def test_presets_resolve_to_their_options_and_the_identity_is_every_option():
    paper = MctsSettings.from_options("mcts", {"preset": "paper"})
    assert (paper.backup, paper.rollout) == ("sampled", "uniform")
    assert json.loads(paper.canonical()) == {
        **hierarchical.PRESETS["paper"],
        "exploration": 0.5,
        "iterations": 100_000,
        "time_limit": None,
        "rollout_epsilon": 0.1,
        "threads": 1,
    }
    improved = MctsSettings.from_options("mcts", {"preset": "improved"})
    assert {
        k: getattr(improved, k) for k in hierarchical.PRESETS["improved"]
    } == hierarchical.PRESETS["improved"]
    # an option given explicitly wins over the preset; the identity names the resolved options
    mixed = MctsSettings.from_options("mcts", {"preset": "improved", "backup": "expected"})
    assert mixed.backup == "expected"
    assert '"backup":"expected"' in mixed.canonical()
    same = MctsSettings.from_options(
        "mcts", {"preset": "improved", "backup": "sampled", "rollout": "uniform"}
    )
    assert same.canonical() == paper.canonical()  # the same search, the same results
    assert (
        MctsSettings(rollout="most_uncertain", rollout_epsilon=0.2).canonical()
        != MctsSettings(rollout="most_uncertain").canonical()
    )
    with pytest.raises(
        InputError, match="option preset must be 'paper', 'improved' or 'revisit', got 'fast'"
    ):
        MctsSettings.from_options("mcts", {"preset": "fast"})


def test_the_revisit_preset_is_the_tour_inside_the_search_at_its_own_default_effort():
    """``preset=revisit`` is the improved search with the revisit tour as rollout policy and
    leaf value; its default effort is a fifth of the others' (its simulations cost about five
    times as much), and a time limit or explicit iterations replace it."""
    revisit = MctsSettings.from_options("mcts", {"preset": "revisit"})
    assert {k: getattr(revisit, k) for k in hierarchical.PRESETS["revisit"]} == {
        **hierarchical.PRESETS["improved"],
        "rollout": "tour_plan",
    }
    assert (revisit.iterations, revisit.time_limit) == (20_000, None)
    timed = MctsSettings.from_options("mcts", {"preset": "revisit", "time_limit": 1.0})
    assert (timed.iterations, timed.rollout) == (None, "tour_plan")
    given = MctsSettings.from_options("mcts", {"preset": "revisit", "iterations": 300})
    assert given.iterations == 300
    # the same options under another preset are the same search, the same identity
    spelled = MctsSettings.from_options(
        "mcts", {"preset": "improved", "rollout": "tour_plan", "iterations": 20_000}
    )
    assert spelled.canonical() == revisit.canonical()
    assert MctsSettings.from_canonical(spelled.canonical()).preset == "revisit"
    # fortify is the revisit search's option, and still refused without the tour
    assert MctsSettings.from_options("mcts", {"preset": "revisit", "fortify": True}).fortify
    with pytest.raises(InputError, match="fortify=true applies only to rollout=tour_plan"):
        MctsSettings.from_options(
            "mcts", {"preset": "revisit", "fortify": True, "rollout": "uniform"}
        )


def test_paper_search_follows_the_first_find_at_low_effort_and_the_max_backup_does_not():
    """The premature follow (issue 11): with the paper's mean backup and 2,000 simulations, the
    planner often follows the first target it finds for the rest of the mission; the mean of
    random rollouts makes every other continuation look worse than the exactly known follow.
    The max backup values each continuation by its best plan and keeps switching."""

    def early_follows(options):
        count = 0
        for seed in range(10):
            scenario = random_scenario(6, seed=seed, homogeneous=True)
            record = run_episode(
                scenario, mcts(iterations=2000, **options), belief_stride=scenario.n_steps
            )
            log = read_subtasks(record.info["subtasks"], record.target_ids)
            follows = [e for e in log if e.kind == "follow"]
            count += bool(follows and follows[0].start_step < 0.6 * scenario.n_steps)
        return count

    assert early_follows({"preset": "paper"}) >= 3
    assert early_follows({"preset": "paper", "backup": "max"}) == 0


def test_a_stored_identity_means_the_same_search_whatever_the_default_preset(monkeypatch):
    """A canonical text names every option, so a stored result is rebuilt as the search that
    made it even if the default preset changes, under the preset that stands for it."""
    paper = MctsSettings.from_options("mcts", {"preset": "paper", "iterations": 300})
    improved = MctsSettings.from_options("mcts", {"preset": "improved", "iterations": 300})
    other = MctsSettings.from_options("mcts", {"backup": "expected", "iterations": 300})
    for default in ("paper", "improved", "revisit"):
        monkeypatch.setattr(hierarchical, "DEFAULT_PRESET", default)
        for settings in (paper, improved, other):
            again = MctsSettings.from_canonical(settings.canonical())
            assert again.model_dump(exclude={"preset"}) == settings.model_dump(exclude={"preset"})
            assert again.canonical() == settings.canonical()
        assert MctsSettings.from_canonical(paper.canonical()).preset == "paper"
        assert MctsSettings.from_canonical(improved.canonical()).preset == "improved"
        assert MctsSettings.from_canonical(other.canonical()).preset == default


def test_dwell_follows_the_target_just_found_for_its_length_then_flies_the_plan():
    """With ``dwell`` (beyond the paper) the planner may follow a target it has just found for
    the dwell's length only: each dwell starts where a find ended, lasts its length, and is
    followed by the plan made for it, or a fresh plan if that one cannot be flown."""
    scenario = random_scenario(4, seed=1, homogeneous=True)
    record = run_episode(scenario, mcts(iterations=2000, preset="improved", dwell=10.0))
    log = read_subtasks(record.info["subtasks"], record.target_ids)
    dwells = [i for i, entry in enumerate(log) if entry.kind == "dwell"]
    assert dwells, "the search never chose the dwell"
    for i in dwells:
        entry, before = log[i], log[i - 1]
        assert entry.target == before.target and entry.parameter == 20
        assert before.outcome in ("found", None)
        assert entry.start_step == before.end_step
        assert entry.after_miss is None
        if entry.end_step is not None:
            assert entry.end_step - entry.start_step == 20
            after = log[i + 1]
            assert after.start_step == entry.end_step
            assert after.action == entry.after_find or fresh_plan(record, after)
    again = run_episode(scenario, mcts(iterations=2000, preset="improved", dwell=10.0))
    assert again.uncertainty == record.uncertainty
    settings = MctsSettings(preset="improved", dwell=10.0)
    assert '"dwell":10.0' in settings.canonical()
    assert '"dwell":0.0' in MctsSettings(preset="improved").canonical()
    assert MctsSettings.from_canonical(settings.canonical()).dwell == 10.0


def test_options_keep_their_names_from_the_settings_to_the_records():
    """Every field of the search's and the sub-task MDP's option records is the planner option
    of the same name (the backup and the rollout as the instances the kernels take)."""
    from hptrack.planning.backups import Max
    from hptrack.planning.search import SearchOptions
    from hptrack.planning.subtask_mdp import SubtaskOptions
    from hptrack.planning.subtask_rollout import Nearest

    settings = MctsSettings(
        exploration=0.7,
        backup="max",
        max_weight=0.5,
        root_split="weighted",
        common_rollouts=True,
        rollout="nearest",
        rollout_epsilon=0.3,
        estimator="sharp",
        dwell=12.5,
    )
    assert set(SearchOptions._fields) | set(SubtaskOptions._fields) <= set(
        MctsSettings.model_fields
    )
    assert settings.search_options() == SearchOptions(
        exploration=0.7,
        backup=Max(0.5),
        root_split="weighted",
        common_rollouts=True,
        rollout=Nearest(0.3),
    )
    assert settings.subtask_options() == SubtaskOptions(estimator="sharp", dwell=12.5)
    paper = MctsSettings(preset="paper")
    assert paper.search_options() == SearchOptions()
    assert paper.subtask_options() == SubtaskOptions()


def test_several_dwell_lengths_are_flown_each_for_its_own_length():
    """``dwell=[5, 20]``: every dwell in the log lasts one of the two lengths (10 or 40 steps),
    as the plan chose it, and ``-o dwell=5,20`` means the same settings."""
    scenario = random_scenario(3, seed=1, homogeneous=True)
    record = run_episode(scenario, mcts(iterations=2000, preset="improved", dwell=[5.0, 20.0]))
    log = read_subtasks(record.info["subtasks"], record.target_ids)
    dwells = [e for e in log if e.kind == "dwell" and e.end_step is not None]
    assert dwells, "the search never chose a dwell"
    for entry in dwells:
        assert entry.parameter in (10, 40)
        assert entry.end_step - entry.start_step == entry.parameter
    parsed = MctsSettings.from_options("mcts", {"dwell": "5,20"})
    assert parsed.dwell == [5.0, 20.0]
    assert '"dwell":[5.0,20.0]' in parsed.canonical()
    assert MctsSettings.from_canonical(parsed.canonical()).dwell == [5.0, 20.0]
    one = MctsSettings.from_options("mcts", {"dwell": [20]})
    assert one.canonical() == MctsSettings.from_options("mcts", {"dwell": 20}).canonical()
    with pytest.raises(InputError, match=r"option dwell must be one length or several"):
        MctsSettings.from_options("mcts", {"dwell": "5,-1"})


def test_a_kept_miss_leaves_the_target_available_to_the_planner():
    """``miss="keep"``: after a missed pursuit the target may be pursued again; with the
    paper's ``drop`` it is not, until measured by chance."""
    scenario = random_scenario(6, seed=3, homogeneous=True)
    for miss in ("drop", "keep"):
        planner = mcts(iterations=500, preset="improved", miss=miss)
        record = run_episode(scenario, planner)
        log = read_subtasks(record.info["subtasks"], record.target_ids)
        missed = [e for e in log if e.outcome == "missed"]
        if miss == "keep":
            assert planner._available.all()
        for entry in missed:
            later = [e for e in log if e.start_step >= entry.end_step]
            again = [e for e in later if e.kind == "pursue" and e.target == entry.target]
            if miss == "drop" and not record.detections[entry.end_step :, entry.target].any():
                assert not again


def test_a_coverage_limit_ends_every_pursuit_in_flight_by_its_length():
    """``coverage_limit=20``: every pursuit flown ends at its intercept plus 20 s of spiral at
    the latest, and plans it so (``t_cutoff``); without it some pursuit runs longer."""
    scenario = random_scenario(6, seed=3, homogeneous=True)
    tau = scenario.time_step

    def pursuits(**options):
        record = run_episode(scenario, mcts(iterations=300, preset="improved", **options))
        log = read_subtasks(record.info["subtasks"], record.target_ids)
        return [e for e in log if e.kind == "pursue" and e.end_step is not None]

    assert any(e.t_cutoff > 20.0 for e in pursuits())
    limited = pursuits(coverage_limit=20.0)
    assert limited
    for entry in limited:
        assert entry.t_cutoff <= 20.0
        assert (entry.end_step - entry.start_step) * tau <= entry.intercept_time + 20.0


def _wrong_priors():
    """The paper-flight example with both targets 40 m off their priors (north and south):
    both pursuits miss."""
    data = yaml.safe_load(EXAMPLE.read_text())
    data["targets"][0]["truth"] = [30.5, 49.5, 3.0, 0.1]
    data["targets"][1]["truth"] = [29.5, -50.5, 3.0, -0.1]
    return parse_scenario(data, "wrong priors")


def _still_steps(record):
    """The steps after which the agent did not move."""
    return np.flatnonzero(np.hypot(*np.diff(record.agent_path, axis=0).T) < 1e-9)


def test_after_both_misses_the_paper_stays_and_readmit_pursues_the_missed_targets_again():
    scenario = _wrong_priors()
    paper = run_episode(scenario, mcts(iterations=500))
    first, second = paper.info["subtasks"][:2]
    assert (first["outcome"], second["outcome"]) == ("missed", "missed")
    # the paper's miss rule: both targets left the action list, the vehicle stays to the end
    assert "readmitted" not in paper.info and not paper.detections.any()
    np.testing.assert_array_equal(_still_steps(paper), np.arange(second["end_step"], 120))
    again = run_episode(scenario, mcts(iterations=500, readmit=True))
    assert again.info["subtasks"][:2] == paper.info["subtasks"][:2]  # the same until then
    step = second["end_step"]
    assert again.info["readmitted"][0] == {"step": step, "targets": [0, 1]}
    third = again.info["subtasks"][2]
    assert third["start_step"] == step and third["kind"] == "pursue"
    assert third["target"] in (0, 1)
    assert len(_still_steps(again)) < 10  # only at the end, when no pursuit fits the budget
    assert again.detections.any() and again.uncertainty < paper.uncertainty


def _early_misses(log):
    """The pairs (a pursuit missed within 10 s of its start, the pursuit that followed it)."""
    return [
        (a, b)
        for a, b in zip(log, log[1:], strict=False)
        if a.get("outcome") == "missed"
        and b["start_step"] == a["end_step"]
        and b["kind"] == "pursue"
        and (a["end_step"] - a["start_step"]) * 0.5 < 10.0
    ]


def test_commit_pursues_a_target_missed_early_again_instead_of_switching():
    scenario = _wrong_priors()
    free = run_episode(scenario, mcts(iterations=500, estimator="sharp", miss="keep"))
    # without commitment the plan switches targets right after early misses
    assert any(b["target"] != a["target"] for a, b in _early_misses(free.info["subtasks"]))
    assert "committed" not in free.info
    held = run_episode(scenario, mcts(iterations=500, estimator="sharp", miss="keep", commit=10.0))
    pairs = _early_misses(held.info["subtasks"])
    assert pairs and all(b["target"] == a["target"] for a, b in pairs)
    switches = [
        a["end_step"]
        for a, _ in pairs
        if a.get("plan_after_miss", {}).get("target", a["target"]) != a["target"]
    ]
    assert switches and held.info["committed"] == switches


def test_credited_passes_fly_end_to_end_and_name_themselves():
    """``passes="credit"`` reaches the MDP, enters the identity, and a mission flies with it."""
    settings = MctsSettings.from_options("mcts", {"passes": "credit"})
    assert settings.subtask_options().passes == "credit"
    assert '"passes":"credit"' in settings.canonical()
    with pytest.raises(InputError, match=r"option passes must be 'ignore' or 'credit'"):
        MctsSettings.from_options("mcts", {"passes": "always"})
    record = run_episode(
        random_scenario(6, seed=3, homogeneous=True), mcts(iterations=300, passes="credit")
    )
    assert np.isfinite(record.uncertainty) and record.info["subtasks"]


def test_the_settings_name_exactly_the_registered_rollouts_and_estimators():
    """A rollout policy or an estimator is chosen by name: the settings accept exactly the
    registered names, and each name gives an instance of its registered class."""
    from typing import get_args

    from hptrack.planning.hierarchical import ROLLOUT_POLICIES, MctsSettings
    from hptrack.planning.subtask_estimators import ESTIMATORS, estimator_of

    def names(field):
        literal = get_args(MctsSettings.model_fields[field].annotation)[0]
        return set(get_args(literal))

    assert names("rollout") == set(ROLLOUT_POLICIES)
    assert names("estimator") == set(ESTIMATORS)
    for name, policy in ROLLOUT_POLICIES.items():
        settings = MctsSettings(rollout=name, rollout_epsilon=0.25)
        instance = settings.search_options().rollout
        assert type(instance) is policy
        assert getattr(instance, "epsilon", 0.25) == 0.25
    for name, estimator in ESTIMATORS.items():
        assert type(estimator_of(name)) is estimator
    with pytest.raises(ValueError, match="estimator must be one of \\('paper', 'sharp'\\)"):
        estimator_of("oracle")
