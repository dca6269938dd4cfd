"""Replay a mission log: the same events, in the same order, through a fresh controller.

The controller is rebuilt from the log's header (scenario, planner and its settings, seed,
controller settings). Each odometry and detection record is fed again, accepted or not (a
detection without identity waits for its tick's look, whose associations are compared with the
logged ``look`` record: the same reports to the same beliefs, the same weights and claims); the
records a ``setpoint`` call made are grouped by their call number and the call is made again at
the same mission time. The planner runs in the caller's thread, and only when the log says its
outcome was delivered (`ReplayRunner`), so no wall clock is
involved: the beliefs, the ticks, the observations, the planner's decisions and the setpoint
modes are reproduced, and every difference from the log is reported. A planner whose effort is
wall time (``mcts`` with a time limit) may decide differently on replay; one with an iteration
budget decides the same.

A log whose planner flies a model file it names (``-o model=PATH`` of ``adfq``, ``sb3``) is
replayed with the log's own decisions (`LoggedDecisions`): a replay never loads a model
a log names, since a log may come from anybody; flying that model again is an explicit
``hptrack simulate``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import ValidationError

from hptrack.interface import CurrentPlan, InputError, MissionSpec, Observation, Planner
from hptrack.registry import make_planner, planner_settings
from hptrack.runtime.controller import MissionController
from hptrack.runtime.inputs import ControllerSettings
from hptrack.runtime.log import (
    ABORT,
    MISSION_START_MESSAGE,
    MissionLog,
    check_record,
    log_array,
    log_float,
    read_log,
)
from hptrack.runtime.team import TeamController
from hptrack.runtime.worker import ReplayRunner
from hptrack.scenario.io import format_validation_error, parse_scenario
from hptrack.sim.record import EpisodeRecord

MAX_LISTED_MISMATCHES = 20
MAX_REPLAY_ITERATIONS = 10**8
"""Most search iterations a replay runs in all (its planner's per decision times the log's
plans): minutes to hours at 1e4 to 1e5 a second; a log that asks for more is refused."""


def never_started(header: dict, records: list[dict]) -> str | None:
    """Why the flight of a ``fly`` log never started its mission (its ``abort`` record's
    detail, or that the log ends before), or ``None`` when it started (or is no flight)."""
    if header.get("source") != "fly" or any(
        r.get("kind") == "status" and r.get("message") == MISSION_START_MESSAGE for r in records
    ):
        return None
    abort = next((r for r in records if r.get("kind") == ABORT), None)
    if abort is None:
        return "the log ends before offboard started"
    return str(abort.get("detail") or abort.get("reason"))


@dataclass
class ReplayResult:
    """A replayed mission.

    Attributes:
        controller: the replaying controller (its own log in memory).
        record: the mission (true target states where the log has them, else NaN).
        summary: JSON-ready summary (``U``, the logged ``U``, mismatches, counts, ends;
            ``never_started`` says why a flight's mission never started, and its ``U``,
            ``ended_by`` and ``time`` are then ``None``).
    """

    controller: MissionController
    record: EpisodeRecord
    summary: dict[str, Any]


def _close(a: Any, b: Any) -> bool:
    a, b = log_array(a), log_array(b)
    return a.shape == b.shape and bool(np.allclose(a, b, rtol=1e-9, atol=1e-9, equal_nan=True))


def _differences(logged: list[dict], replayed: list[dict]) -> list[str]:
    """What the replayed records of one step do differently from the logged ones."""
    out = []
    kinds = [r["kind"] for r in logged], [r["kind"] for r in replayed]
    if kinds[0] != kinds[1]:
        return [f"records {kinds[0]} became {kinds[1]}"]
    for old, new in zip(logged, replayed, strict=True):
        kind = old["kind"]
        keys = {
            "odometry": ("accepted", "reason"),
            "detection": ("accepted", "reason"),
            "tick": ("k", "submitted", "detected"),
            "look": ("k", "reports", "belief", "claims", "superseded"),
            "plan": ("k", "status"),
            "late": ("k",),
            "mode": ("mode",),
            "end": ("reason", "yields"),
            "setpoint": ("reason",),
            "yield": ("vehicle", "to"),
        }.get(kind, ())
        for key in keys:
            if old.get(key) != new.get(key):
                out.append(f"{kind} {key}: {old.get(key)!r} became {new.get(key)!r}")
        numbers = {
            "tick": ("logdet", "means", "agent", "separation_m"),
            "look": ("time", "agent", "weight", "tentative"),
            "plan": ("waypoint",),
            "mode": ("position",),
            "yield": ("reference",),
            "fence": ("reference", "projected"),
            "end": ("U", "min_separation_m", "min_reference_separation_m"),
        }.get(kind, ())
        for key in numbers:
            if not _close(old.get(key), new.get(key)):
                out.append(f"{kind} {key} differs")
    return out


class LoggedDecisions:
    """Stands in for a planner that flies a model file named in the log: each tick's decision
    is the waypoint of the log's plan record of that tick (a logged planner error is raised
    again), so the model is never loaded."""

    def __init__(self, name: str, settings: Any, plans: dict[int, dict]) -> None:
        self.name, self.settings, self._plans = name, settings, plans

    def reset(
        self, mission: MissionSpec, observation: Observation, rng: np.random.Generator
    ) -> None:
        """Nothing to prepare: the decisions are the log's."""

    def act(self, observation: Observation) -> np.ndarray:
        plan = self._plans.get(observation.step)
        if plan is None or plan.get("error"):
            raise RuntimeError(plan["error"] if plan else "the log has no decision of this tick")
        return log_array(plan["waypoint"])

    def current_plan(self) -> CurrentPlan:
        return CurrentPlan()

    def episode_info(self) -> dict[str, Any]:
        return {"settings": self.settings.as_json(), "decisions": "logged"}


def _planner(header: dict[str, Any], records: list[dict]) -> Planner:
    """The header's planner, or `LoggedDecisions` when its settings name a model file."""
    settings = planner_settings(header["planner"], header.get("planner_settings") or {})
    if getattr(settings, "model", None) is None:
        return make_planner(header["planner"], settings)
    plans = {int(r["k"]): r for r in records if r.get("kind") == "plan" and "k" in r}
    return LoggedDecisions(header["planner"], settings, plans)


def replay_log(path: str | Path) -> ReplayResult:
    """Replay the mission log at ``path`` (module docstring).

    Raises:
        InputError: an unreadable or malformed log, or a header this hptrack cannot rebuild.
    """
    contents = read_log(path)
    header = contents.header
    check_record(header, f"{path}: line 1", header=True)
    try:
        scenario = parse_scenario(header["scenario"], f"{path}: header scenario")
        settings = ControllerSettings(**header["controller"])
        planner = _planner(header, contents.records)
        seed = int(header["seed"])
    except KeyError as err:
        raise InputError(f"{path}: the header has no {err.args[0]!r}") from None
    except ValidationError as err:
        raise InputError(
            f"{path}: header controller settings: {format_validation_error(err)}"
        ) from None
    plans = sum(r["kind"] == "plan" for r in contents.records)
    field = type(planner.settings).effort_fields.get("iterations")
    effort = getattr(planner.settings, field, None) if field else None
    if effort is not None and effort * plans > MAX_REPLAY_ITERATIONS:
        raise InputError(
            f"{path}: the header's planner searches {effort:,} iterations per decision; "
            f"replaying its {plans} plans would run more than {MAX_REPLAY_ITERATIONS:.0e} "
            "iterations (hours)"
        )
    runner = ReplayRunner()
    log = MissionLog()
    team = scenario.n_vehicles > 1
    controller = (TeamController if team else MissionController)(
        scenario,
        planner,
        seed=seed,
        settings=settings,
        log=log,
        runner=runner,
        header={"source": "replay", "replay_of": str(path)},
        **({"separation_m": log_float(header.get("separation_m"))} if team else {}),
    )
    records = contents.records
    mismatches: list[str] = []
    truth: dict[int, np.ndarray] = {}
    adapter: list[dict] = []
    logged_end: dict | None = None
    i = 0
    while i < len(records):
        record = records[i]
        call = record.get("call")
        before = len(log.records)
        if call is not None:
            group = [record]
            while i + len(group) < len(records) and records[i + len(group)].get("call") == call:
                group.append(records[i + len(group)])
            for item in group:
                if item["kind"] == "plan":
                    runner.release(item["k"])
                if item["kind"] == "end":
                    logged_end = item
            controller.setpoint(log_float(group[0]["t"]))
            logged = group
            i += len(group)
        else:
            i += 1
            kind = record["kind"]
            logged = [record]
            if kind in ("odometry", "detection") and "raw" in record:
                controller.bad_input(
                    kind, record.get("reason", ""), record.get("detail", ""), record.get("raw")
                )
            elif kind == "odometry" and isinstance(controller, TeamController):
                controller.odometry(
                    log_float(record["t"]), log_array(record["position"]), record.get("vehicle")
                )
            elif kind == "odometry":
                controller.odometry(log_float(record["t"]), log_array(record["position"]))
            elif kind == "detection":
                covariance = record.get("covariance")
                confidence = record.get("confidence")
                controller.detection(
                    log_float(record["t"]),
                    record.get("target"),
                    log_array(record["position"]),
                    None if covariance is None else log_array(covariance),
                    None if confidence is None else log_float(confidence),
                    record.get("vehicle"),
                )
            elif kind == "plan":
                runner.release(record["k"])
                logged = []
            elif kind == "end":
                logged_end = record
                controller.finish(log_float(record["t"]), record["reason"])
            else:
                if kind == "truth":
                    truth[int(record["k"])] = log_array(record["states"])
                else:
                    adapter.append(record)
                continue
        # a plan that arrived after the end shows in the end record's planner info
        replayed = [r for r in log.records[before:] if not r.get("after_end")]
        logged = [r for r in logged if not r.get("after_end")]
        for problem in _differences(logged, replayed):
            mismatches.append(f"record {logged[0]['seq'] if logged else '?'}: {problem}")
    if not controller.finished:
        last = max((log_float(r.get("t")) for r in records if r.get("t") is not None), default=0.0)
        controller.finish(last if math.isfinite(last) else 0.0, "log ended")
    final_k = round(controller.final["time"] / scenario.time_step)
    truth_array = (
        np.array([truth[k] for k in range(final_k + 1)])
        if all(
            k in truth and truth[k].shape == (len(scenario.targets), 4) for k in range(final_k + 1)
        )
        else None
    )
    record = controller.episode_record(truth_array)
    summary = {
        "log": str(path),
        "source": header.get("source"),
        "planner": header["planner"],
        "decisions": "logged" if isinstance(planner, LoggedDecisions) else "planned again",
        "seed": seed,
        "truncated": contents.truncated,
        "records": len(records) + 1,
        "ticks": sum(r["kind"] == "tick" for r in records),
        "plans": sum(r["kind"] == "plan" for r in records),
        "mismatches": len(mismatches),
        "first_mismatches": mismatches[:MAX_LISTED_MISMATCHES],
        "U": controller.end["U"],
        "logged_U": None if logged_end is None else logged_end["U"],
        "ended_by": controller.end["reason"],
        "time": controller.end["time"],
        "per_target_logdet": controller.end["per_target_logdet"],
        "detections": dict(
            zip(scenario.target_ids, map(int, record.detection_counts()), strict=True)
        ),
        "accepted": controller.end["accepted"],
        "rejected": controller.end["rejected"],
        "tracking": controller.end.get("tracking"),
        **(
            {
                key: controller.end[key]
                for key in (
                    "separation_m",
                    "min_separation_m",
                    "min_reference_separation_m",
                    "yields",
                )
            }
            if team
            else {}
        ),
        "adapter": [
            {k: v for k, v in r.items() if k not in ("seq",)}
            for r in adapter
            if r["kind"] in ("safety", ABORT)
        ],
    }
    summary["never_started"] = never_started(header, records)
    if summary["never_started"] is not None:
        summary.update(U=None, ended_by=None, time=None, per_target_logdet={})
    controller.close()
    return ReplayResult(controller, record, summary)
