"""The default search on many targets: what a search holds and what it wins at n = 20 .. 80.

Homogeneous random scenarios of the paper (``--targets``, seeds ``0..N-1``), flown by the default
``mcts`` at ``--time-limit`` s per decision, by ``tour`` (its defaults) and by ``greedy``. Each
``mcts`` episode runs in a fresh process, so its peak resident memory (``ru_maxrss``) is that of
one mission; per search it logs the simulations run and ``tree_bytes``, the memory the tree's
arrays hold. The report: per n, the searches, their simulations and tree memory, the peak RSS,
and the mean U (with its standard error) of each planner.

    python3 benchmarks/large_n.py --targets 20,30,40,80 --seeds 3 --time-limit 1 --workers 1 \\
        --out docs/results/large-n
"""

from __future__ import annotations

import argparse
import csv
import json
import multiprocessing
import resource
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from hptrack.experiments.report import mean_se, write_tables
from hptrack.registry import make_planner
from hptrack.scenario.random import random_scenario
from hptrack.sim.episode import run_episode


def _episode(planner, n: int, seed: int) -> tuple[float, float, dict]:
    """U, targets never detected and the planner's episode info of one scenario."""
    scenario = random_scenario(n, seed=seed, homogeneous=True)
    record = run_episode(scenario, planner, belief_stride=scenario.n_steps)
    return record.uncertainty, record.metrics()["targets_never_detected"], record.info


def mcts_episode(n: int, seed: int, time_limit: float) -> dict:
    """One ``mcts`` episode (the improved preset at ``time_limit`` s per decision), run in a
    process of its own: U, its searches' simulations and tree bytes, the peak RSS (bytes)."""
    planner = make_planner("mcts", {"preset": "improved", "time_limit": time_limit})
    u, never, info = _episode(planner, n, seed)
    return {
        "n": n,
        "seed": seed,
        "U": u,
        "never_detected": never,
        "simulations": [s["simulations"] for s in info["searches"]],
        "tree_bytes": [s["tree_bytes"] for s in info["searches"]],
        "peak_rss_bytes": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024,
    }


def report(mcts: list[dict], others: dict[str, dict], out: Path, command: str) -> None:
    """Write ``table.md``, ``summary.json`` (with every episode) and ``rows.csv`` (the table's
    rows, for quotes)."""
    counts = sorted({r["n"] for r in mcts})
    lines = [
        "Homogeneous random scenarios (seeds from 0); `mcts` the improved preset at the planning",
        "time per decision given, one process per episode; `tour` and `greedy` at their defaults.",
        "",
        "```bash",
        command,
        "```",
        "",
        "Per n: the searches of all episodes, their simulations (median, least: a search late in",
        "the budget runs many more), the memory held by",
        "the tree's arrays (`tree_bytes`, mean and largest), the largest peak resident memory of",
        "an episode's process, mean U +- standard error (episodes) of each planner, the paired",
        "differences mcts - other on the same scenarios (negative: mcts is better), and the",
        "targets `mcts` never detected per episode.",
        "",
        "| n | episodes | searches | simulations, median (least) | tree MB, mean (largest) | "
        "peak RSS, MB | mcts U | tour U | greedy U | mcts - tour | mcts - greedy | "
        "mcts never detected |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    episodes = [
        r | {f"{name}_U": by_key[r["n"], r["seed"]] for name, by_key in others.items()}
        for r in mcts
    ]
    summary: dict = {"command": command, "rows": [], "episodes": episodes}
    for n in counts:
        rows = [r for r in mcts if r["n"] == n]
        seeds = [r["seed"] for r in rows]
        sims = np.concatenate([r["simulations"] for r in rows])
        tree = np.concatenate([r["tree_bytes"] for r in rows]) / 1e6
        rss = max(r["peak_rss_bytes"] for r in rows) / 1e6
        u = {"mcts": mean_se(np.array([r["U"] for r in rows]))}
        paired = {}
        for name, by_key in others.items():
            theirs = np.array([by_key[n, s] for s in seeds])
            u[name] = mean_se(theirs)
            paired[name] = mean_se(np.array([r["U"] for r in rows]) - theirs)
        never = float(np.mean([r["never_detected"] for r in rows]))
        cells = " | ".join(f"{m:.2f} +- {se:.2f}" for m, se in u.values())
        cells += " | " + " | ".join(f"{m:+.2f} +- {se:.2f}" for m, se in paired.values())
        lines.append(
            f"| {n} | {len(rows)} | {sims.size} | {np.median(sims):.0f} ({sims.min()}) | "
            f"{tree.mean():.1f} ({tree.max():.1f}) | {rss:.0f} | {cells} | {never:.2f} |"
        )
        summary["rows"].append(
            {
                "n": n,
                "episodes": len(rows),
                "searches": int(sims.size),
                "median_simulations": float(np.median(sims)),
                "least_simulations": int(sims.min()),
                "mean_tree_mb": float(tree.mean()),
                "largest_tree_mb": float(tree.max()),
                "peak_rss_mb": rss,
                **{f"{name}_mean_U": m for name, (m, _) in u.items()},
                **{f"{name}_se_U": se for name, (_, se) in u.items()},
                **{f"mcts_minus_{name}": m for name, (m, _) in paired.items()},
                **{f"mcts_minus_{name}_se": se for name, (_, se) in paired.items()},
                "mcts_never_detected": never,
            }
        )
    write_tables(out, lines, summary)
    with open(out / "rows.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(summary["rows"][0]))
        writer.writeheader()
        writer.writerows(summary["rows"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--targets", default="20,30,40,80", help="numbers of targets")
    parser.add_argument("--seeds", type=int, default=3, help="scenarios per n (seeds 0..N-1)")
    parser.add_argument("--time-limit", type=float, default=1.0, help="mcts, s per decision")
    parser.add_argument("--workers", type=int, default=1, help="mcts episodes at once")
    parser.add_argument("--out", type=Path, default=Path("results/large-n"))
    parser.add_argument(
        "--report-only", action="store_true", help="rewrite the report from --out's summary"
    )
    args = parser.parse_args()
    if args.report_only:
        summary = json.loads((args.out / "summary.json").read_text())
        names = ("tour", "greedy")
        others = {
            name: {(r["n"], r["seed"]): r[f"{name}_U"] for r in summary["episodes"]}
            for name in names
        }
        theirs = {f"{name}_U" for name in names}
        mcts = [{k: v for k, v in r.items() if k not in theirs} for r in summary["episodes"]]
        report(mcts, others, args.out, summary["command"])
        return
    counts = tuple(int(t) for t in args.targets.split(",") if t)
    keys = [(n, s) for n in counts for s in range(args.seeds)]
    command = (
        f"python3 benchmarks/large_n.py --targets {args.targets} --seeds {args.seeds} "
        f"--time-limit {args.time_limit:g} --workers {args.workers} --out {args.out}"
    )
    pool = ProcessPoolExecutor(
        args.workers, multiprocessing.get_context("spawn"), max_tasks_per_child=1
    )
    with pool:
        futures = [pool.submit(mcts_episode, n, s, args.time_limit) for n, s in keys]
        mcts = [f.result() for f in futures]
    others = {
        name: {(n, s): _episode(make_planner(name), n, s)[0] for n, s in keys}
        for name in ("tour", "greedy")
    }
    report(mcts, others, args.out, command)


if __name__ == "__main__":
    main()
