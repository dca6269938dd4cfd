"""Negative information at ``Pd < 1``: the default search with the miss update against without.

Homogeneous random scenarios of the paper (``--targets``, seeds ``0..N-1``) whose sensor detects
a target inside its footprint with probability ``--detection-probability`` at each look, as in
``benchmarks/sensing_blind.py``. The default ``mcts`` (preset ``improved``, ``--iterations``
simulations per decision, so the rows are reproducible) flies each scenario three times on the
same worlds (the same truths, detector draws and noise; the paths differ with the decisions):

* ``off``: ``negative_information: false`` (today: a miss changes nothing);
* ``on``: ``negative_information: true``: the simulator's beliefs take the miss update and the
  planner's sub-task model the miss branch's scaled covariance;
* ``on_world``: the simulator's beliefs as ``on``, the planner told the mission without it (so
  ``on - on_world`` is what the planner's knowledge of it is worth, on beliefs of one kind).

``U`` is each world's own score of its beliefs, so ``on`` against ``off`` compares beliefs of
two kinds (the miss update narrows some and widens others); the truth-based columns compare
them on one footing: the position error of the means at the end (RMS over the targets, m) and
the share of the targets whose truth lies inside its belief's 99 % ellipse at the end
(consistency; ``chi^2_2`` 99 % = 9.21). Rows are stored in ``--store`` (JSON lines) as they
finish (a re-run resumes); the report is ``table.md`` and ``summary.json`` in ``--out``.

    python3 benchmarks/sensing_negative_information.py --targets 6,12 --seeds 12 --workers 2 \\
        --iterations 500 --store results/sensing-negative-information.jsonl \\
        --out docs/results/sensing-negative-information
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from hptrack.experiments.report import mean_se, write_tables
from hptrack.registry import make_planner, planner_settings
from hptrack.scenario import random_scenario
from hptrack.scenario.model import FootprintSensorSpec
from hptrack.sim.episode import run_episode

VARIANTS = ("off", "on", "on_world")
"""The runs of each scenario (module docstring)."""
CHI2_99 = 9.21034037197618
"""The 99 % quantile of ``chi^2`` with 2 degrees of freedom."""


def episode(job: tuple[str, int, int, float, int]) -> dict:
    """One row: ``(variant, n, seed, Pd, iterations)`` flown by the improved search."""
    variant, n, seed, pd, iterations = job
    sensor = FootprintSensorSpec(detection_probability=pd, negative_information=variant != "off")
    scenario = random_scenario(n, seed=seed, homogeneous=True, sensor=sensor)
    told = None
    if variant == "on_world":
        told = dataclasses.replace(scenario.mission_spec(), negative_information=False)
    planner = make_planner(
        "mcts", planner_settings("mcts", {"preset": "improved", "iterations": iterations})
    )
    record = run_episode(scenario, planner, planner_mission=told)
    truth = record.true_states[-1, :, :2]
    mean = record.belief_means[-1, :, :2]
    cov = record.belief_covariances[-1, :, :2, :2]
    err = truth - mean
    nees = np.einsum("ni,nij,nj->n", err, np.linalg.inv(cov), err)
    return {
        "variant": variant,
        "n": n,
        "seed": seed,
        "U": float(record.per_target_logdet.sum()),
        "rms_error_m": float(np.sqrt(np.mean(np.sum(err * err, axis=1)))),
        "inside_99": float(np.mean(nees <= CHI2_99)),
        "never_detected": int(np.sum(~record.detections.any(axis=0))),
    }


def report(rows: list[dict], out: Path, pd: float, iterations: int) -> None:
    """Write ``table.md`` and ``summary.json`` from the rows."""
    by = {(r["variant"], r["n"], r["seed"]): r for r in rows}
    counts = sorted({r["n"] for r in rows})
    lines = [
        f"Pd = {pd:g} at every look; mcts (preset improved) at {iterations:,} simulations per "
        "decision; the same worlds per scenario.",
        "",
        "| n | variant | episodes | mean U | std. error | RMS error at the end, m "
        "| truths inside the 99 % ellipse | targets never detected |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    summary: dict = {"detection_probability": pd, "iterations": iterations, "rows": []}
    for n in counts:
        for variant in VARIANTS:
            mine = [r for (v, m, _), r in sorted(by.items()) if v == variant and m == n]
            if not mine:
                continue
            u = np.array([r["U"] for r in mine])
            mean, se = mean_se(u)
            rms = float(np.mean([r["rms_error_m"] for r in mine]))
            inside = float(np.mean([r["inside_99"] for r in mine]))
            never = float(np.mean([r["never_detected"] for r in mine]))
            lines.append(
                f"| {n} | {variant} | {len(mine)} | {mean:.2f} | {se:.2f} | {rms:.1f} "
                f"| {inside:.2f} | {never:.2f} |"
            )
            summary["rows"].append(
                {
                    "n": n,
                    "variant": variant,
                    "episodes": len(mine),
                    "mean_U": mean,
                    "se_U": se,
                    "rms_error_m": rms,
                    "inside_99": inside,
                    "never_detected": never,
                }
            )
    lines += [
        "",
        "| n | pair | paired mean difference of U | std. error | scenarios | size / std. error |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    summary["paired"] = []
    for n in counts:
        for a, b in (("on", "on_world"), ("on", "off")):
            seeds = sorted(s for (v, m, s) in by if v == a and m == n and (b, n, s) in by)
            if len(seeds) < 2:
                continue
            diff = np.array([by[a, n, s]["U"] - by[b, n, s]["U"] for s in seeds])
            mean, se = mean_se(diff)
            lines.append(
                f"| {n} | {a} - {b} | {mean:.2f} | {se:.2f} | {len(seeds)} | {abs(mean) / se:.1f} |"
            )
            summary["paired"].append(
                {"n": n, "pair": f"{a} - {b}", "mean": mean, "se": se, "scenarios": len(seeds)}
            )
    write_tables(out, lines, summary)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--targets", default="6,12", help="numbers of targets, comma-separated")
    parser.add_argument("--seeds", type=int, default=12, help="scenarios per n (seeds 0..N-1)")
    parser.add_argument("--detection-probability", type=float, default=0.7)
    parser.add_argument("--iterations", type=int, default=500, help="mcts simulations")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument(
        "--store", type=Path, default=Path("results/sensing-negative-information.jsonl")
    )
    parser.add_argument("--out", type=Path, default=Path("results/sensing-negative-information"))
    args = parser.parse_args()
    targets = tuple(int(t) for t in args.targets.split(","))
    pd, iterations = args.detection_probability, args.iterations
    args.store.parent.mkdir(parents=True, exist_ok=True)
    rows = []
    if args.store.exists():
        rows = [json.loads(line) for line in args.store.read_text().splitlines() if line]
    done = {(r["variant"], r["n"], r["seed"]) for r in rows}
    jobs = [
        (variant, n, seed, pd, iterations)
        for seed in range(args.seeds)
        for n in targets
        for variant in VARIANTS
        if (variant, n, seed) not in done
    ]
    with ProcessPoolExecutor(max_workers=args.workers) as pool, args.store.open("a") as store:
        for row in pool.map(episode, jobs):
            store.write(json.dumps(row) + "\n")
            store.flush()
            rows.append(row)
            print(row, flush=True)
    report(rows, args.out, pd, iterations)


if __name__ == "__main__":
    main()
