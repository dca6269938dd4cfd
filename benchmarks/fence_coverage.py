"""The coverage estimator's chance of a find when a no-fly circle covers part of the belief,
against its Monte Carlo (the paper's experiment of Table I with a fence).

For each random case of the paper's distributions (`draw_case`) and departure delay, a no-fly
circle is laid at a random offset from where the coverage starts, of a random radius (both in
units of the belief's largest position standard deviation there), at a random angle
(``--placement belief``) or on the straight path back to the agent's start (``--placement
path``: the zone lies across the intercept, and clips the spiral when it holds the belief's
centre or comes within the spiral's first turns of it): the spiral's waypoints inside
it are flown around by the fenced vehicle, and the belief mass it can neither fly over nor see
is lost. Each case is planned and simulated three ways on the same sampled trajectories: in open
space, and fenced with the estimate corrected by the share of the searched ellipse the footprint
can see (`hptrack.models.mission.visible_find`) and without the correction (the open-space
estimate on the fenced flight). Writes ``table.md`` and ``summary.json``::

    python3 benchmarks/fence_coverage.py --cases 300 --runs 2000 --out docs/results/fence-coverage
    python3 benchmarks/fence_coverage.py --cases 150 --runs 2000 --placement path \
        --out docs/results/fence-coverage-path
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from hptrack.experiments.coverage_validation import draw_case, first_detections, plan_coverage
from hptrack.interface import MissionSpec
from hptrack.models.fence import FenceSpec
from hptrack.models.state import positions

DELAYS_S = (0.0, 100.0, 200.0)


PLACEMENTS = ("belief", "path")
"""Where the circle goes: at a random angle about the coverage's start (``belief``), or on the
straight path from the agent's start to it (``path``: the zone lies across the intercept)."""


def fenced_case(
    index: int, seed: int, delay_s: float, runs: int, placement: str = "belief"
) -> dict:
    """One case and delay: estimates and simulated chances of a find, open and fenced."""
    case = draw_case(index, seed)
    open_space = MissionSpec()
    steps = round(delay_s / open_space.time_step)
    plain = plan_coverage(case, steps, open_space)
    start = plain.path[plain.intercept_steps]
    sigma = math.sqrt(float(np.linalg.eigvalsh(plain.covariance[:2, :2]).max()))
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(index, 7, steps)))
    angle = rng.uniform(0.0, 2.0 * math.pi)
    offset = rng.uniform(0.0, 1.5) * sigma
    radius = max(rng.uniform(0.5, 1.5) * sigma, 10.0)
    agent = np.zeros(2)
    if placement == "path":
        angle = math.atan2(agent[1] - start[1], agent[0] - start[0])
    centre = start + offset * np.array([math.cos(angle), math.sin(angle)])
    if math.dist(centre, agent) <= radius + 1.0:  # keep the agent's start free
        centre = agent + (radius + 1.0) * (centre - agent) / max(math.dist(centre, agent), 1e-9)
    fenced = replace(open_space, fence=FenceSpec(circles=((*centre.tolist(), radius),)))
    plan = plan_coverage(case, steps, fenced)

    def simulated(p, mission) -> float:
        draws = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(index, 1 + steps)))
        first_any, _ = first_detections(p, case.q, mission, runs, draws)
        return float(np.mean(first_any >= 0))

    return {
        "case": index,
        "delay": delay_s,
        "sigma": sigma,
        "radius_sigma": radius / sigma,
        "offset_sigma": float(math.dist(centre, start)) / sigma,
        "centre": centre.tolist(),
        "coverage_start": start.tolist(),
        "open_est": plain.estimate.p_find,
        "open_emp": simulated(plain, open_space),
        "fenced_est": plan.estimate.p_find,
        "uncorrected_est": plain.estimate.p_find,
        "sharp_open_est": plain.sharp.p_find,
        "sharp_fenced_est": plan.sharp.p_find,
        "sharp_uncorrected_est": plain.sharp.p_find,
        "fenced_emp": simulated(plan, fenced),
        "mean_x": float(positions(case.mean)[0]),
    }


ESTIMATORS = {"paper": "", "sharp": "sharp_"}
"""The estimators compared, by the prefix of their columns."""


def table(rows: list[dict]) -> tuple[str, dict]:
    """The markdown table and the summary by estimator and delay."""
    lines = [
        "| estimator | t_d (s) | cases | simulated P_find, open | fenced | open: mean error "
        "| within 0.03 | fenced, corrected: mean error | largest | within 0.03 "
        "| fenced, uncorrected: mean error | within 0.03 |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    summary: dict = {}
    for name, prefix in ESTIMATORS.items():
        for delay in DELAYS_S:
            at = [r for r in rows if r["delay"] == delay]
            if not at:
                continue
            errors = {
                key: np.abs(np.array([r[prefix + est] - r[emp] for r in at]))
                for key, est, emp in (
                    ("open", "open_est", "open_emp"),
                    ("corrected", "fenced_est", "fenced_emp"),
                    ("uncorrected", "uncorrected_est", "fenced_emp"),
                )
            }
            s = {
                "cases": len(at),
                "simulated_open": float(np.mean([r["open_emp"] for r in at])),
                "simulated_fenced": float(np.mean([r["fenced_emp"] for r in at])),
            }
            for key, e in errors.items():
                s[f"{key}_mean_error"] = float(e.mean())
                s[f"{key}_largest_error"] = float(e.max())
                s[f"{key}_within_0.03"] = float(np.mean(e <= 0.03))
            summary.setdefault(name, {})[f"{delay:g}"] = s
            lines.append(
                f"| {name} | {delay:g} | {len(at)} | {s['simulated_open']:.3f} "
                f"| {s['simulated_fenced']:.3f} | {s['open_mean_error']:.4f} "
                f"| {100 * s['open_within_0.03']:.1f} % | {s['corrected_mean_error']:.4f} "
                f"| {s['corrected_largest_error']:.4f} | {100 * s['corrected_within_0.03']:.1f} % "
                f"| {s['uncorrected_mean_error']:.4f} "
                f"| {100 * s['uncorrected_within_0.03']:.1f} % |"
            )
    return "\n".join(lines) + "\n", summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=300)
    parser.add_argument("--runs", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--placement",
        choices=PLACEMENTS,
        default="belief",
        help="the circle about the coverage's start at a random angle, or across the intercept",
    )
    parser.add_argument("--out", type=Path, default=Path("docs/results/fence-coverage"))
    parser.add_argument(
        "--tables-only", action="store_true", help="rewrite the tables from OUT/cases.json"
    )
    args = parser.parse_args()
    if args.tables_only:
        rows = json.loads((args.out / "cases.json").read_text())
    else:
        rows = [
            fenced_case(i, args.seed, delay, args.runs, args.placement)
            for i in range(args.cases)
            for delay in DELAYS_S
        ]
    text, summary = table(rows)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "table.md").write_text(text)
    (args.out / "summary.json").write_text(
        json.dumps(
            {
                "cases": args.cases,
                "runs": args.runs,
                "seed": args.seed,
                "placement": args.placement,
                **summary,
            },
            indent=2,
        )
        + "\n"
    )
    (args.out / "cases.json").write_text(json.dumps(rows) + "\n")
    print(text)


if __name__ == "__main__":
    main()
