"""Which targets a planner keeps, and what each costs: ``U`` split target by target.

Each planner of `scale_benchmark.VARIANTS` (``--variants``; ``NAME@ITERATIONS`` runs a search at
that many simulations per search) flies the homogeneous random scenarios of ``--targets``
(seeds ``0..N-1``); the searches run at their presets' default effort (simulations, not time,
so the rows do not depend on the machine's load). At the end, every target is one of three
kinds:

- *never detected*: its prior grown to the budget's end, exactly what it adds to ``U``;
- *lost*: detected, but not in the last ``--final-share`` of the budget;
- *kept*: detected in it.

Per planner and n: how many targets of each kind an episode has, the mean ``log det
Sigma^xy`` of a target of each kind, and, against the clairvoyant reference on the same
scenarios, the gap ``U - U_clairvoyant`` split by the kind the planner left each target in (the
sum over a kind of the target's ``log det`` minus the reference's for that target). Episodes are
written to ``--cache`` (JSON lines) as they finish and a re-run skips them. Writes ``table.md``
and ``summary.json``::

    python3 benchmarks/target_mix.py --targets 12,20 --seeds 20 \\
        --variants revisit,revisit@100000,improved,tour,greedy,clairvoyant --workers 2 \\
        --cache results/target-mix.jsonl --out docs/results/target-mix
"""

from __future__ import annotations

import argparse
import importlib.util
import json
from concurrent.futures import FIRST_COMPLETED, wait
from pathlib import Path
from typing import NamedTuple

import numpy as np

from hptrack.experiments.benchmark import planner_for, scenario_for
from hptrack.experiments.report import mean_se, write_tables
from hptrack.experiments.store import EpisodeKey
from hptrack.experiments.workers import stop_workers, worker_pool
from hptrack.models.beliefs import position_logdet
from hptrack.registry import planner_settings
from hptrack.sim.episode import run_episode

KINDS = ("never", "lost", "kept")
"""The kinds of target at the end of an episode, in the tables' order."""

REFERENCE = "clairvoyant"
"""The planner the gap is measured against."""


def _scale_variants() -> dict[str, tuple[str, dict]]:
    path = Path(__file__).with_name("scale_benchmark.py")
    spec = importlib.util.spec_from_file_location("scale_benchmark", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.VARIANTS


def variant_key(name: str, n: int, seed: int, variants: dict) -> EpisodeKey:
    """The episode of variant ``name`` (``NAME`` or ``NAME@ITERATIONS``) on scenario ``seed``."""
    base, _, iterations = name.partition("@")
    planner, options = variants[base]
    if iterations:
        options = {**options, "iterations": int(iterations)}
    settings = planner_settings(planner, options)
    return EpisodeKey(planner, n, seed, "homogeneous", settings.canonical())


class TargetOutcome(NamedTuple):
    """One target's end of an episode.

    Attributes:
        logdet: ``log det Sigma^xy`` at the budget's end (its share of ``U``).
        never_logdet: the same had it never been measured (its prior grown to the end).
        last_detection_s: time of its last detection, s; ``None`` if never detected.
    """

    logdet: float
    never_logdet: float
    last_detection_s: float | None


def kind(outcome: TargetOutcome, budget_s: float, final_share: float) -> str:
    """``"never"``, ``"lost"`` or ``"kept"`` (detected in the last ``final_share`` of the
    budget)."""
    if outcome.last_detection_s is None:
        return "never"
    return "kept" if outcome.last_detection_s >= (1.0 - final_share) * budget_s else "lost"


def fly(key: EpisodeKey) -> dict:
    """Fly one episode; its key and every target's outcome (a top-level function, for the
    worker processes)."""
    scenario = scenario_for(key)
    record = run_episode(scenario, planner_for(key), belief_stride=scenario.n_steps)
    _, grown = scenario.motion_model().predict(
        scenario.means(),
        scenario.covariances(),
        scenario.process_noise(),
        scenario.n_steps * scenario.time_step,
    )
    seen = record.detections
    last = [
        float(np.flatnonzero(seen[:, i])[-1] * record.time_step) if seen[:, i].any() else None
        for i in range(seen.shape[1])
    ]
    return {
        "key": [key.planner, key.n_targets, key.seed, key.setting, key.planner_settings],
        "budget_s": float(scenario.budget),
        "logdet": record.per_target_logdet.tolist(),
        "never_logdet": position_logdet(grown).tolist(),
        "last_detection_s": last,
    }


def outcomes(entry: dict) -> list[TargetOutcome]:
    """The targets' outcomes of a cached episode."""
    return [
        TargetOutcome(a, b, c)
        for a, b, c in zip(
            entry["logdet"], entry["never_logdet"], entry["last_detection_s"], strict=True
        )
    ]


def run(keys: list[EpisodeKey], cache: Path, workers: int) -> dict[EpisodeKey, dict]:
    """Every episode of ``keys``, flying those not in ``cache`` and appending them to it."""
    done: dict[EpisodeKey, dict] = {}
    if cache.exists():
        for line in cache.read_text().splitlines():
            entry = json.loads(line)
            done[EpisodeKey(*entry["key"])] = entry
    todo = [k for k in dict.fromkeys(keys) if k not in done]
    cache.parent.mkdir(parents=True, exist_ok=True)
    with open(cache, "a") as fh:

        def keep(entry: dict) -> None:
            done[EpisodeKey(*entry["key"])] = entry
            fh.write(json.dumps(entry) + "\n")
            fh.flush()
            print(
                f"{len(done)} episodes: {entry['key'][0]} n={entry['key'][1]} "
                f"seed={entry['key'][2]}",
                flush=True,
            )

        if workers <= 1:
            for key in todo:
                keep(fly(key))
            return done
        pool = worker_pool(workers)
        try:
            queue, pending = iter(todo), set()
            while True:
                while len(pending) < workers and (key := next(queue, None)) is not None:
                    pending.add(pool.submit(fly, key))
                if not pending:
                    break
                ready, pending = wait(pending, return_when=FIRST_COMPLETED)
                for future in ready:
                    keep(future.result())
        except BaseException:
            stop_workers(pool)
            raise
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
    return done


def summarise(episodes: dict[str, dict[int, dict]], final_share: float) -> list[dict]:
    """Per variant of ``{variant: {seed: cached episode}}`` (one n): targets of each kind per
    episode, the mean ``log det`` of a target of each kind, and the gap to `REFERENCE` on the
    shared scenarios split by kind (each per episode)."""
    reference = episodes.get(REFERENCE, {})
    rows = []
    for variant, by_seed in episodes.items():
        counts = {k: [] for k in KINDS}
        logdets: dict[str, list[float]] = {k: [] for k in KINDS}
        gaps: dict[str, list[float]] = {k: [] for k in KINDS}
        totals = []
        for seed, entry in sorted(by_seed.items()):
            mine = outcomes(entry)
            kinds = [kind(o, entry["budget_s"], final_share) for o in mine]
            totals.append(sum(o.logdet for o in mine))
            for k in KINDS:
                counts[k].append(kinds.count(k))
            for o, k in zip(mine, kinds, strict=True):
                logdets[k].append(o.logdet)
            if seed in reference:
                theirs = outcomes(reference[seed])
                for k in KINDS:
                    gaps[k].append(
                        sum(
                            o.logdet - r.logdet
                            for o, r, ok in zip(mine, theirs, kinds, strict=True)
                            if ok == k
                        )
                    )
        mean_u, se_u = mean_se(totals)
        row = {"planner": variant, "episodes": len(totals), "mean_U": mean_u, "se_U": se_u}
        for k in KINDS:
            row[f"{k}_per_episode"] = float(np.mean(counts[k]))
            row[f"{k}_mean_logdet"] = float(np.mean(logdets[k])) if logdets[k] else None
            row[f"{k}_gap"] = mean_se(gaps[k]) if gaps[k] and variant != REFERENCE else None
        rows.append(row)
    return rows


def _cell(value: float | None, digits: int = 2) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def report(by_n: dict[int, list[dict]], command: str, final_share: float, out: Path) -> None:
    """Write ``table.md`` and ``summary.json``."""
    lines = [
        "Homogeneous random scenarios (seeds from 0), the searches at their presets' default",
        "effort (`NAME@K`: K simulations per search). A target is *never* detected, *lost*",
        f"(detected, but not in the last {final_share:.0%} of the budget) or *kept* (detected",
        "in it).",
        "",
        "```bash",
        command,
        "```",
        "",
        "Targets of each kind per episode, and the mean `log det Sigma^xy` of a target of each",
        "kind at the end (its share of U).",
        "",
        "| n | planner | episodes | mean U | never | lost | kept | log det, never | lost | kept |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for n, rows in by_n.items():
        for r in rows:
            lines.append(
                f"| {n} | {r['planner']} | {r['episodes']} | {r['mean_U']:.2f} +- "
                f"{r['se_U']:.2f} | "
                + " | ".join(f"{r[f'{k}_per_episode']:.2f}" for k in KINDS)
                + " | "
                + " | ".join(_cell(r[f"{k}_mean_logdet"]) for k in KINDS)
                + " |"
            )
    lines += [
        "",
        f"The gap to the {REFERENCE} reference on the same scenarios, U - U_{REFERENCE}, split",
        "by the kind each target ends in under the planner: the sum over the targets of that",
        f"kind of their `log det` minus the {REFERENCE}'s for the same target, per episode, mean",
        "+- standard error.",
        "",
        "| n | planner | gap, never | lost | kept | whole gap |",
        "|---|---|---|---|---|---|",
    ]
    for n, rows in by_n.items():
        for r in rows:
            if r["never_gap"] is None:
                continue
            parts = [r[f"{k}_gap"] for k in KINDS]
            whole = sum(p[0] for p in parts)
            lines.append(
                f"| {n} | {r['planner']} | "
                + " | ".join(f"{m:+.2f} +- {se:.2f}" for m, se in parts)
                + f" | {whole:+.2f} |"
            )
    rows = {str(n): r for n, r in by_n.items()}
    write_tables(out, lines, {"command": command, "final_share": final_share, "rows": rows})


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--targets", default="12,20", help="numbers of targets, comma-separated")
    parser.add_argument("--seeds", type=int, default=20, help="scenarios per n (seeds 0..N-1)")
    parser.add_argument(
        "--variants",
        default="revisit,improved,tour,greedy,clairvoyant",
        help="scale_benchmark's variants, NAME@K for K simulations per search",
    )
    parser.add_argument(
        "--final-share",
        type=float,
        default=0.25,
        help="a target detected in this last share of the budget is kept (0..1)",
    )
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--cache", type=Path, default=Path("results/target-mix.jsonl"))
    parser.add_argument("--out", type=Path, default=Path("results/target-mix"))
    args = parser.parse_args()
    variants = _scale_variants()
    names = args.variants.split(",")
    for name in names:
        base, _, iterations = name.partition("@")
        if base not in variants:
            parser.error(f"--variants: unknown {base!r} (known: {', '.join(variants)})")
        if iterations and (not iterations.isdigit() or variants[base][0] != "mcts"):
            parser.error(f"--variants: {name!r}: @K needs a search and a whole number K")
    if not 0.0 < args.final_share < 1.0:
        parser.error(f"--final-share: {args.final_share} is not between 0 and 1")
    targets = [int(t) for t in args.targets.split(",")]
    keys = {
        (name, n, seed): variant_key(name, n, seed, variants)
        for n in targets
        for seed in range(args.seeds)
        for name in names
    }
    done = run(list(keys.values()), args.cache, args.workers)
    by_n = {
        n: summarise(
            {name: {s: done[keys[name, n, s]] for s in range(args.seeds)} for name in names},
            args.final_share,
        )
        for n in targets
    }
    command = (
        f"python3 benchmarks/target_mix.py --targets {args.targets} --seeds {args.seeds} "
        f"--variants {args.variants} --final-share {args.final_share:g}"
    )
    report(by_n, command, args.final_share, args.out)


if __name__ == "__main__":
    main()
