"""The paper's real flight (two targets 20 m apart, ``examples/paper-flight.yaml``) over many seeds.

Every planner flies the example once per seed (the seed draws the measurement and process noise
and the planner's stream); ``mcts`` variants (``--variants``, options as JSON with ``--define``)
fly at each planning time per decision (``--levels``, s). Rows are appended to a CSV as they
finish, and a re-run skips what is there, so a stopped run resumes. ``--report`` writes, from the
CSV, the mean ``U`` per planner with its standard error, the paired difference from ``greedy``,
the share of the greedy-to-``clairvoyant`` gap closed, how many seeds measure both targets in at
least three separate visits each (the paper's "keeps alternating between two targets"), and a
figure.

    python3 benchmarks/paper_flight.py --seeds 20 --levels 0.05,1 --csv results/paper-flight.csv
    python3 benchmarks/paper_flight.py --report --csv results/paper-flight.csv \\
        --out docs/results/paper-flight
"""

from __future__ import annotations

import argparse
import csv
import importlib.util
import json
import math
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np

SCENARIO = Path(__file__).resolve().parents[1] / "examples/paper-flight.yaml"
VARIANTS = {"paper": {"preset": "paper"}, "improved": {"preset": "improved"}}
"""``mcts`` options of each variant."""
BASELINES = ("greedy", "clairvoyant")
VISIT_GAP_S = 2.0
"""A detection after at least this long without one starts a new visit, s."""
FIELDS = ("planner", "variant", "level_s", "seed", "planner_settings", "U", "logdets", "visits")


def _sibling(name: str):
    """Another script of ``benchmarks/``, as a module."""
    spec = importlib.util.spec_from_file_location(name, Path(__file__).with_name(f"{name}.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def visits(detections: np.ndarray, time_step: float) -> list[int]:
    """Separate visits per target: runs of detections split by gaps of at least
    :data:`VISIT_GAP_S` (``detections`` is ``(steps, n)`` bool)."""
    gap = max(1, math.ceil(VISIT_GAP_S / time_step))
    out = []
    for column in np.asarray(detections, dtype=bool).T:
        steps = np.flatnonzero(column)
        out.append(int(steps.size > 0) + int(np.sum(np.diff(steps) >= gap + 1)))
    return out


def jobs(seeds: int, levels: list[float], variants: list[str]) -> list[tuple]:
    """``(planner, variant, level, seed, canonical settings)`` of every episode, seeds
    outermost."""
    from hptrack.planning.hierarchical import MctsSettings
    from hptrack.settings import NoSettings

    out = []
    for seed in range(seeds):
        for level in levels:
            for v in variants:
                s = MctsSettings.from_options("mcts", {**VARIANTS[v], "time_limit": level})
                out.append(("mcts", v, level, seed, s.canonical()))
        out += [(b, b, 0.0, seed, NoSettings().canonical()) for b in BASELINES]
    return out


def run(job: tuple) -> dict:
    """Fly one episode (a top-level function for worker processes)."""
    import hptrack
    from hptrack.registry import planner_entry

    planner_name, variant, level, seed, canonical = job
    entry = planner_entry(planner_name)
    planner = entry.factory(entry.settings_type.from_canonical(canonical))
    scenario = hptrack.load_scenario(SCENARIO)
    record = hptrack.run_episode(scenario, planner, seed=seed)
    return {
        "planner": planner_name,
        "variant": variant,
        "level_s": level,
        "seed": seed,
        "planner_settings": canonical,
        "U": repr(float(record.uncertainty)),
        "logdets": json.dumps([float(x) for x in record.per_target_logdet]),
        "visits": json.dumps(visits(record.detections, record.time_step)),
    }


def identity(row: dict) -> tuple:
    return (row["planner"], row["planner_settings"], int(row["seed"]))


def read(path: Path) -> list[dict]:
    if not path.exists():
        return []
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def fly(path: Path, todo: list[tuple], workers: int) -> None:
    done = {identity(r) for r in read(path)}
    todo = [j for j in todo if (j[0], j[4], j[3]) not in done]
    path.parent.mkdir(parents=True, exist_ok=True)
    new = not path.exists()
    with path.open("a", newline="") as f, ProcessPoolExecutor(workers) as pool:
        writer = csv.DictWriter(f, FIELDS)
        if new:
            writer.writeheader()
        futures = [pool.submit(run, j) for j in todo]
        for k, future in enumerate(as_completed(futures), 1):
            row = future.result()
            writer.writerow(row)
            f.flush()
            print(
                f"[{k}/{len(todo)}] {row['variant']} @ {row['level_s']} seed {row['seed']}: "
                f"U {float(row['U']):.2f} visits {row['visits']}",
                flush=True,
            )


def mean_se(values) -> tuple[float, float]:
    a = np.asarray(values, dtype=float)
    return float(a.mean()), (float(a.std(ddof=1) / math.sqrt(a.size)) if a.size > 1 else math.nan)


def report(path: Path, out: Path) -> None:
    """Write ``table.md``, ``episodes.csv`` and ``paper-flight.png`` to ``out``."""
    from hptrack.viz.style import new_figure, save_figure, style_axes

    rows = read(path)
    found: dict[tuple, dict[int, dict]] = {}
    for r in rows:
        found.setdefault((r["variant"], float(r["level_s"])), {})[int(r["seed"])] = r
    first = list(dict.fromkeys(v for v, _ in found))  # the variants in the order they ran

    def order(cell: tuple) -> tuple:
        v, level = cell
        return (v not in BASELINES, BASELINES.index(v) if v in BASELINES else first.index(v), level)

    groups = {cell: found[cell] for cell in sorted(found, key=order)}
    greedy = groups.get(("greedy", 0.0), {})
    clair = groups.get(("clairvoyant", 0.0), {})
    lines = [
        f"`{SCENARIO.name}` over seeds (U: sum over targets of log det Σxy at the budget's end); "
        "paired differences and the gap closed on the seeds both planners flew; alternating: "
        "both targets measured in at least three separate visits (gaps of at least "
        f"{VISIT_GAP_S:g} s).",
        "",
        "| planner | time, s | seeds | mean U | minus greedy | gap closed, % | alternating |",
        "|---|---|---|---|---|---|---|",
    ]
    for (variant, level), by_seed in groups.items():
        u = {s: float(r["U"]) for s, r in by_seed.items()}
        m, se = mean_se(list(u.values()))
        common = sorted(set(u) & set(greedy))
        if common and variant != "greedy":
            d, dse = mean_se([u[s] - float(greedy[s]["U"]) for s in common])
            diff = f"{d:+.2f} +- {dse:.2f}"
        else:
            diff = ""
        both = sorted(set(u) & set(greedy) & set(clair))
        if both and variant not in BASELINES:
            g = np.mean([float(greedy[s]["U"]) for s in both])
            c = np.mean([float(clair[s]["U"]) for s in both])
            gap = f"{100.0 * (g - np.mean([u[s] for s in both])) / (g - c):.0f}"
        else:
            gap = ""
        alternating = sum(min(json.loads(r["visits"])) >= 3 for r in by_seed.values())
        time = "-" if variant in BASELINES else f"{level:g}"
        lines.append(
            f"| {variant} | {time} | {len(u)} | {m:.2f} +- {se:.2f} | {diff} | {gap} | "
            f"{alternating} of {len(u)} |"
        )
    out.mkdir(parents=True, exist_ok=True)
    (out / "table.md").write_text("\n".join(lines) + "\n")
    with (out / "episodes.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, FIELDS)
        writer.writeheader()
        writer.writerows(sorted(rows, key=lambda r: (r["variant"], r["level_s"], int(r["seed"]))))
    fig = new_figure(1.2 + 0.9 * len(groups), 3.6)
    ax = fig.add_subplot()
    names = [f"{v}" if v in BASELINES else f"{v}\n@ {lv:g} s" for v, lv in groups]
    ax.boxplot(
        [[float(r["U"]) for r in g.values()] for g in groups.values()],
        tick_labels=names,
        showmeans=True,
        meanprops={"marker": "D", "mfc": "white", "mec": "k", "ms": 4.5},
    )
    ax.set_ylabel("U (sum over targets of log det Σxy)")
    style_axes(ax, f"{SCENARIO.name}: U over {max(len(g) for g in groups.values())} seeds")
    save_figure(fig, out / "paper-flight.png")
    print(f"written to {out}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--levels", default="0.05,1", help="seconds per decision")
    parser.add_argument("--variants", default="paper,improved")
    parser.add_argument("--define", action="append", default=[], metavar="NAME=JSON")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--csv", type=Path, default=Path("results/paper-flight.csv"))
    parser.add_argument("--report", action="store_true", help="only write the report")
    parser.add_argument("--out", type=Path, default=Path("results/paper-flight"))
    args = parser.parse_args()
    variants = _sibling("quality_vs_time").chosen_variants(parser, args, VARIANTS)
    if args.report:
        report(args.csv, args.out)
        return
    levels = [float(x) for x in args.levels.split(",")]
    fly(args.csv, jobs(args.seeds, levels, variants), args.workers)


if __name__ == "__main__":
    main()
