"""Do the learned-agents table's figures still hold at the current code? Re-evaluate and compare.

The learned-agents table (README, docs/LEARNED.md) is built by ``lawn zoo build`` from the training
runs, which live outside the repository; its per-episode costs are committed in
``docs/learned/episodes.csv``. This script re-evaluates, at the current code, what the repository
holds: ``rg-mpc``, ``epa`` and the anchors (``anchor:NAME``) on both envs and every shipped agent (``zoo:NAME``, the training seed
the table calls shipped) on the table's test seeds (the steady-task agents on each of their tasks'
seeds, ``docs/learned/distil.csv``), and prints, per policy, the largest relative
change of an episode's control cost against the committed row. A change of the code that moves
them beyond the table's precision (three significant digits) means the table must be rebuilt
(``bash scripts/refresh_docs.sh --only learned --train``).

Usage: ``python benchmarks/zoo_drift.py [--workers 2] [--markdown out.md]``
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

import numpy as np

from evaluation.episode import EpisodeSpec
from evaluation.run import evaluate
from lawn_env import ScenarioConfig, presets

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--markdown", help="also write the table of this run to this file")
    args = parser.parse_args(argv)
    old = {(r["policy"], r["env"], int(r["seed"])): float(r["control_cost"])
           for r in csv.DictReader(open(ROOT / "docs" / "learned" / "episodes.csv"))}
    seeds = sorted({s for _, _, s in old})
    fixed = sorted({(p, e) for p, e, _ in old if ":" not in p or p.startswith("anchor:")}, key=lambda x: (x[1], x[0]))
    pairs = [(name, env, name) for name, env in fixed]  # the references and the anchors
    for agent in sorted((ROOT / "agents" / "zoo").glob("*/agent.json")):
        meta = json.loads(agent.read_text())
        name, env, shipped = meta["name"], meta["evaluated_on"], meta["shipped_seed"]
        if "tasks" in meta.get("benchmark", {}):
            continue  # a steady-task agent: its episodes are in distil.csv (_distil_drift)
        recorded = sorted({p for p, e, _ in old if e == env and p.endswith(f"/{name}/seed-{shipped}")})
        if len(recorded) != 1:
            raise SystemExit(f"{agent}: no single recorded run for {name} seed {shipped} in episodes.csv")
        pairs.append((f"zoo:{name}", env, recorded[0]))
    config = ScenarioConfig()
    tasks = [EpisodeSpec(policy, env, config, s, {}) for policy, env, _ in pairs for s in seeds]
    rows = evaluate(tasks, workers=args.workers, progress=False)
    new = {(r.policy, r.env, r.seed): r.control_cost for r in rows}
    lines = [f"{len(seeds)} test seeds; the largest relative change of an episode's control cost against "
             "docs/learned/episodes.csv:", "", "| policy | env | max relative change | mean cost (recorded → now) |",
             "|---|---|---|---|"]
    worst = 0.0
    for policy, env, recorded in pairs:
        a = np.array([old[(recorded, env, s)] for s in seeds])
        b = np.array([new[(policy, env, s)] for s in seeds])
        change = float(np.max(np.abs(b / a - 1.0)))
        worst = max(worst, change)
        lines.append(f"| {policy} | {env} | {change:.1e} | {a.mean():.2f} → {b.mean():.2f} |")
    for policy, env, a, b in _distil_drift(args.workers):
        change = float(np.max(np.abs(b / a - 1.0)))
        worst = max(worst, change)
        lines.append(f"| {policy} | {env} | {change:.1e} | {a.mean():.2f} → {b.mean():.2f} |")
    ok = worst < 5e-4  # below half a unit of the table's third significant digit
    lines += ["", f"* [{'PASS' if ok else 'FAIL'}] every episode within 5e-4 of its recorded cost "
              f"(largest change {worst:.1e}): the learned-agents table holds at this code"]
    print("\n".join(lines))
    if args.markdown:
        Path(args.markdown).write_text("\n".join(lines) + "\n")
    return 0 if ok else 1


def _distil_drift(workers: int) -> list[tuple[str, str, np.ndarray, np.ndarray]]:
    """The steady-task agents (a record with per-task figures), each task of each one played again on
    the seeds of ``docs/learned/distil.csv``: (policy, env and task, recorded costs, costs now)."""
    path = ROOT / "docs" / "learned" / "distil.csv"
    old = list(csv.DictReader(path.read_text().splitlines())) if path.exists() else []
    out = []
    for agent in sorted((ROOT / "agents" / "zoo").glob("*/agent.json")):
        meta = json.loads(agent.read_text())
        if "tasks" not in meta.get("benchmark", {}):
            continue
        name, env, shipped = meta["name"], meta["evaluated_on"], meta["shipped_seed"]
        recorded = {r["policy"] for r in old if r["policy"].endswith(f"/{name}/seed-{shipped}")}
        if len(recorded) != 1:
            raise SystemExit(f"{agent}: no single recorded run for {name} seed {shipped} in {path}")
        law = {"control.law": ScenarioConfig.from_dict(meta["config"]).control.law}
        for task in meta["benchmark"]["tasks"]:
            then = {int(r["seed"]): float(r["control_cost"]) for r in old if r["policy"] in recorded
                    and r["task"] == task}
            config = presets.get(task).override(law)
            rows = evaluate([EpisodeSpec(f"zoo:{name}", env, config, s, {}) for s in sorted(then)], workers=workers,
                            progress=False)
            now = {r.seed: r.control_cost for r in rows}
            out.append((f"zoo:{name}", f"{env}, {task}", np.array([then[s] for s in sorted(then)]),
                        np.array([now[s] for s in sorted(then)])))
    return out


if __name__ == "__main__":
    sys.exit(main())
