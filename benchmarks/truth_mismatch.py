"""Planners whose beliefs assume constant velocity, flown against targets that truly move
otherwise (`hptrack.models.truth_motion`): the cost of the mismatch.

Each episode is a homogeneous random scenario of the paper (``--targets``, seeds ``0..N-1``)
with its ``truth_motion`` replaced by one of `TRUTHS`; every planner flies the same scenarios
(``mcts`` with the default preset at ``--iterations`` simulations per decision, so the rows are
reproducible; each row names its planner's canonical settings, part of its identity). Rows are
appended to a CSV as they finish, and a re-run skips those there, so a stopped run resumes;
``--report`` writes the mean ``U`` with its standard error and the targets never detected per
planner, truth and ``n``, and the paired difference of ``mcts`` from ``greedy`` (``table.md``,
``summary.json``). ``mcts_told`` is ``mcts`` told the true model where a belief can hold it
(the linear-Gaussian truths of `TOLD`: the scenario's ``motion:`` block is the truth's), with
its paired difference from ``mcts``; its ``U`` is its own beliefs', so the targets never
detected compare across belief models better than ``U`` does.

    python3 benchmarks/truth_mismatch.py --targets 6,12 --seeds 10 --csv results/mismatch.csv
    python3 benchmarks/truth_mismatch.py --report --csv results/mismatch.csv \\
        --out docs/results/truth-mismatch
"""

from __future__ import annotations

import argparse
import csv
import importlib.util
import json
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

TRUTHS: dict[str, dict | None] = {
    "constant_velocity": None,
    "turn_0.02": {"model": "coordinated_turn", "turn_rate": 0.02},
    "turn_random_0.02": {"model": "coordinated_turn", "turn_rate": 0.0, "turn_rate_sd": 0.02},
    "random_walk_5": {"model": "random_walk", "diffusion": 5.0},
    "ou_0.01": {"model": "ornstein_uhlenbeck", "damping": 0.01},
    "singer_0.002": {"model": "singer", "damping": 0.02, "acceleration_std": 0.002},
    "ca_0.001": {
        "model": "constant_acceleration",
        "jerk_intensity": 1e-8,
        "acceleration_std": 0.001,
    },
}
"""The truth motions flown, by the name the table gives them."""
TOLD = ("random_walk_5", "ou_0.01", "singer_0.002", "ca_0.001")
"""The truths a belief motion can hold (`hptrack.models.belief_motion`)."""
PLANNERS = ("mcts", "greedy", "clairvoyant", "mcts_told")
"""The planners flown (``mcts_told``: ``mcts`` with the true model, on `TOLD` only)."""
REGISTERED = {"mcts_told": "mcts"}
"""The registered planner each variant of `PLANNERS` flies (the others are their own)."""
FIELDS = ("planner", "planner_settings", "truth", "n", "seed", "U", "never_detected")
"""A row: its identity (the planner and its canonical settings, the truth, ``n``, the seed) and
its results."""


def _sibling(name: str):
    """Another script of ``benchmarks/``, as a module."""
    spec = importlib.util.spec_from_file_location(name, Path(__file__).with_name(f"{name}.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def scenario(n: int, seed: int, truth: str, told: bool = False):
    """The homogeneous random scenario ``(n, seed)`` with ``truth``'s motion (``told``: as the
    beliefs' motion too)."""
    from hptrack.scenario.model import Scenario
    from hptrack.scenario.random import random_scenario

    base = random_scenario(n, seed=seed, homogeneous=True)
    spec = TRUTHS[truth]
    if spec is None:
        return base
    field = "motion" if told else "truth_motion"
    return Scenario.model_validate({**base.model_dump(exclude_none=True), field: spec})


def settings_of(planner: str, iterations: int):
    """The validated settings a planner flies with (``mcts``: the improved preset at
    ``iterations`` simulations per decision)."""
    from hptrack.registry import planner_settings

    registered = REGISTERED.get(planner, planner)
    return planner_settings(
        registered,
        {"preset": "improved", "iterations": iterations} if registered == "mcts" else None,
    )


def episode(job: tuple) -> dict:
    """One row: ``job`` is ``(planner, truth, n, seed, iterations)``."""
    from hptrack.registry import planner_entry
    from hptrack.sim.episode import run_episode

    planner, truth, n, seed, iterations = job
    settings = settings_of(planner, iterations)
    told = planner == "mcts_told"
    record = run_episode(
        scenario(n, seed, truth, told), planner_entry("mcts" if told else planner).factory(settings)
    )
    never = int((~record.detections.any(axis=0)).sum())
    values = (planner, settings.canonical(), truth, n, seed, repr(record.uncertainty), never)
    return dict(zip(FIELDS, values, strict=True))


def run(args: argparse.Namespace) -> None:
    path = Path(args.csv)
    done = set()
    if path.exists():
        with path.open() as f:
            rows = csv.DictReader(f)
            done = {
                (r["planner"], r["planner_settings"], r["truth"], int(r["n"]), int(r["seed"]))
                for r in rows
            }
    counts = [int(n) for n in args.targets.split(",")]
    jobs = [
        (planner, truth, n, seed, args.iterations)
        for n in counts
        for seed in range(args.seeds)
        for truth in (args.truths.split(",") if args.truths else TRUTHS)
        for planner in args.planners.split(",")
        if planner != "mcts_told" or truth in TOLD
        if (planner, settings_of(planner, args.iterations).canonical(), truth, n, seed) not in done
    ]
    path.parent.mkdir(parents=True, exist_ok=True)
    new = not path.exists()
    with path.open("a", newline="") as f, ProcessPoolExecutor(args.workers) as pool:
        writer = csv.DictWriter(f, FIELDS)
        if new:
            writer.writeheader()
        for future in as_completed([pool.submit(episode, job) for job in jobs]):
            writer.writerow(future.result())
            f.flush()
    print(f"{len(jobs)} episodes run, {len(done)} were there: {path}")


def report(args: argparse.Namespace) -> None:
    mean_se = _sibling("quality_vs_time").mean_se
    with Path(args.csv).open() as f:
        rows = list(csv.DictReader(f))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    lines = [
        "| n | truth | planner | scenarios | mean U | std. error | never detected |",
        "|---|---|---|---|---|---|---|",
    ]
    summary = []
    for n in sorted({int(r["n"]) for r in rows}):
        for truth in TRUTHS:
            for planner in PLANNERS:
                sel = [r for r in rows if int(r["n"]) == n and r["truth"] == truth]
                sel = [r for r in sel if r["planner"] == planner]
                if not sel:
                    continue
                u = [float(r["U"]) for r in sel]
                mean, se = mean_se(u)
                never = sum(int(r["never_detected"]) for r in sel) / len(sel)
                lines.append(
                    f"| {n} | {truth} | {planner} | {len(u)} | {mean:.2f} | {se:.2f} | "
                    f"{never:.2f} |"
                )
                summary.append(
                    {
                        "n": n,
                        "truth": truth,
                        "planner": planner,
                        "scenarios": len(u),
                        "mean_U": mean,
                        "se": se,
                        "never_detected": never,
                    }
                )
    lines += [
        "",
        "| n | truth | mcts - greedy, paired mean | std. error |",
        "|---|---|---|---|",
    ]
    for n in sorted({int(r["n"]) for r in rows}):
        for truth in TRUTHS:
            by_seed: dict[int, dict[str, float]] = {}
            for r in rows:
                if int(r["n"]) == n and r["truth"] == truth:
                    by_seed.setdefault(int(r["seed"]), {})[r["planner"]] = float(r["U"])
            diffs = [
                u["mcts"] - u["greedy"] for u in by_seed.values() if {"mcts", "greedy"} <= set(u)
            ]
            if len(diffs) < 2:
                continue
            mean, se = mean_se(diffs)
            lines.append(f"| {n} | {truth} | {mean:+.2f} | {se:.2f} |")
    told_lines = []
    for n in sorted({int(r["n"]) for r in rows}):
        for truth in TOLD:
            pairs: dict[int, dict[str, dict]] = {}
            for r in rows:
                if int(r["n"]) == n and r["truth"] == truth:
                    pairs.setdefault(int(r["seed"]), {})[r["planner"]] = r
            both = [p for p in pairs.values() if {"mcts", "mcts_told"} <= set(p)]
            if len(both) < 2:
                continue
            du, _ = mean_se([float(p["mcts_told"]["U"]) - float(p["mcts"]["U"]) for p in both])
            dn, se = mean_se(
                [
                    int(p["mcts_told"]["never_detected"]) - int(p["mcts"]["never_detected"])
                    for p in both
                ]
            )
            told_lines.append(f"| {n} | {truth} | {len(both)} | {du:+.2f} | {dn:+.2f} | {se:.2f} |")
    if told_lines:
        lines += [
            "",
            "| n | truth | scenarios | mcts_told - mcts: U | never detected | std. error |",
            "|---|---|---|---|---|---|",
            *told_lines,
        ]
    (out / "table.md").write_text("\n".join(lines) + "\n")
    (out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    print("\n".join(lines))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--targets", default="6,12", help="comma-separated target counts")
    parser.add_argument("--seeds", type=int, default=10, help="scenario seeds 0..N-1")
    parser.add_argument("--iterations", type=int, default=2000, help="mcts simulations/decision")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--planners", default=",".join(PLANNERS), help="comma-separated")
    parser.add_argument(
        "--truths", default="", help=f"comma-separated, of {', '.join(TRUTHS)} (default all)"
    )
    parser.add_argument("--csv", required=True, help="the episodes' CSV (appended, resumed)")
    parser.add_argument("--report", action="store_true", help="write the table from the CSV")
    parser.add_argument("--out", default="docs/results/truth-mismatch")
    args = parser.parse_args()
    unknown = set(args.truths.split(",")) - set(TRUTHS) if args.truths else set()
    if unknown:
        parser.error(f"--truths {','.join(sorted(unknown))}: not among {', '.join(TRUTHS)}")
    report(args) if args.report else run(args)


if __name__ == "__main__":
    main()
