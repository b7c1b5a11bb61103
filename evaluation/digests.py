"""The README table's rows replay their recorded episodes: two seeded episodes of every row
(:data:`README_ROWS`) on the default task, each as its control cost and a digest of its per-slot costs
(:func:`episode_record`), recorded in ``episode_digests.json`` beside this module, so a change of any
policy's episodes is deliberate or a test failure. ``python -m evaluation.digests`` compares,
``--write-digests`` records."""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TypedDict

from agents import BENCHMARK_POLICIES
from agents.base import JOINT
from lawn_env import ScenarioConfig

from .run import REFERENCE_ROWS, run_episode

__all__ = ["README_ROWS", "DIGESTS", "DIGEST_SEEDS", "episode_record", "digest_records", "main"]

#: The rows of the README's table: lawn benchmark's default policies and the reference rows.
README_ROWS = (*BENCHMARK_POLICIES, *REFERENCE_ROWS)
#: Their recorded episodes (seeds DIGEST_SEEDS of the default task on lawn/Joint-v1).
DIGESTS = Path(__file__).resolve().parent / "episode_digests.json"
DIGEST_SEEDS = (0, 1)


class Digest(TypedDict):
    """One recorded episode of a README row: its seed, control cost (10 significant digits) and the
    digest of its per-slot costs, outage rate and RMSE."""

    seed: int
    control_cost: float
    digest: str


def episode_record(policy: str, seed: int) -> Digest:
    """One seeded episode of a README row on the default task: its digest and its control cost."""
    r = run_episode(policy, JOINT, ScenarioConfig(), seed)
    values = [f"{float(x):.10g}" for x in (*(r.stage_costs if r.stage_costs is not None else ()), r.outage_rate,
                                           r.rmse_m)]
    return {"seed": seed, "control_cost": float(f"{r.control_cost:.10g}"),
            "digest": hashlib.sha256(" ".join(values).encode()).hexdigest()[:16]}


def digest_records(rows: Sequence[str] = README_ROWS) -> dict[str, list[Digest]]:
    """Every row's episodes (:func:`episode_record`), by row name."""
    return {name: [episode_record(name, s) for s in DIGEST_SEEDS] for name in rows}


def main(argv: list[str] | None = None) -> int:
    """``python -m evaluation.digests [--write-digests]``: compare the README rows' episodes
    with the recorded ones (exit 1 naming the rows that changed), or record them."""
    parser = argparse.ArgumentParser(prog="python -m evaluation.digests",
                                     description=str(main.__doc__).split(":")[0])
    parser.add_argument("--write-digests", action="store_true", help=f"rewrite {DIGESTS.name}")
    args = parser.parse_args(argv)
    now = digest_records()
    if args.write_digests:
        tmp = DIGESTS.with_suffix(".tmp")
        tmp.write_text(json.dumps(now, indent=1) + "\n")
        tmp.replace(DIGESTS)
        print(f"wrote {DIGESTS}: {len(now)} rows x {len(DIGEST_SEEDS)} episodes")
        return 0
    recorded = json.loads(DIGESTS.read_text()) if DIGESTS.exists() else {}
    changed = [name for name in now if recorded.get(name) != now[name]]
    print("unchanged" if not changed else f"changed: {', '.join(changed)}")
    return 1 if changed else 0


if __name__ == "__main__":
    sys.exit(main())
