"""Recorded episodes of every row of the README's benchmark table: a change of any policy's
episodes is deliberate or a test failure.

For each row of ``lawn benchmark``'s default table (the policies and the reference rows), two seeded
episodes of the default task are replayed and hashed: every slot's stage cost, the outage rate and the
RMSE, each to 10 significant digits (a last-bit difference of another machine's arithmetic does not
count; any change of what a policy does does). ``tests/data/episode_digests.json`` holds them;
``tests/test_digests.py`` replays them. A change that moves a row updates the file and the tables in
the same commit: ``python -m training.digests --write`` (``scripts/refresh_docs.sh --only benchmark``
runs it beside the README's table).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

__all__ = ["ROWS", "SEEDS", "DIGESTS", "episode_record", "records"]

ROOT = Path(__file__).resolve().parent.parent
DIGESTS = ROOT / "tests" / "data" / "episode_digests.json"
SEEDS = (0, 1)
ENV_ID = "lawn/Joint-v0"


def _rows() -> tuple[str, ...]:
    from agents import BENCHMARK_POLICIES

    from .results.run import REFERENCE_ROWS

    return (*BENCHMARK_POLICIES, *REFERENCE_ROWS)


def __getattr__(name: str):
    if name == "ROWS":  # the README table's rows: lawn benchmark's default policies and reference rows
        return _rows()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _digits(x: float) -> str:
    return f"{float(x):.10g}"


def episode_record(policy: str, seed: int) -> dict:
    """One seeded episode of a table row on the default task: its digest and its control cost."""
    from lawn_env import ScenarioConfig

    from .results.run import run_episode

    row = run_episode(policy, ENV_ID, ScenarioConfig(), seed)
    values = [_digits(c) for c in json.loads(row["stage_costs"])] + [_digits(row["outage_rate"]),
                                                                       _digits(row["rmse_m"])]
    return {"seed": seed, "control_cost": float(_digits(row["control_cost"])),
            "digest": hashlib.sha256(" ".join(values).encode()).hexdigest()[:16]}


def records(rows: tuple[str, ...] | None = None, seeds: tuple[int, ...] = SEEDS) -> dict[str, list[dict]]:
    """Every row's episodes (:func:`episode_record`), by row name."""
    return {name: [episode_record(name, s) for s in seeds] for name in (rows or _rows())}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help=f"rewrite {DIGESTS.relative_to(ROOT)}")
    args = parser.parse_args(argv)
    now = records()
    if args.write:
        DIGESTS.parent.mkdir(parents=True, exist_ok=True)
        tmp = DIGESTS.with_suffix(".tmp")
        tmp.write_text(json.dumps(now, indent=1) + "\n")
        tmp.replace(DIGESTS)
        print(f"wrote {DIGESTS.relative_to(ROOT)}: {len(now)} rows x {len(SEEDS)} episodes")
        return 0
    recorded = json.loads(DIGESTS.read_text()) if DIGESTS.exists() else {}
    changed = [name for name in now if recorded.get(name) != now[name]]
    print("unchanged" if not changed else f"changed: {', '.join(changed)}")
    return 1 if changed else 0


if __name__ == "__main__":
    sys.exit(main())
