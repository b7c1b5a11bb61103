"""``lawn sweep``: a grid of config fields x policies x seeds into a tidy, resumable table."""

from __future__ import annotations

import argparse
from pathlib import Path

from evaluation.sweep import load_spec, run_sweep, summarize_sweep

from .common import command


def add(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> argparse.ArgumentParser:
    sw = command(sub, "sweep", "workers", "quiet", "backend")
    sw.add_argument("spec", help="sweep spec (YAML or JSON)")
    sw.add_argument("--out", required=True, help="table (CSV); finished rows are skipped on rerun")
    sw.add_argument("--extend", action="store_true",
                    help="keep rows of the table that this spec would not produce (another spec or version)")
    return sw


def run(args: argparse.Namespace) -> int:
    spec = load_spec(args.spec)
    rows = run_sweep(spec, Path(args.out), workers=args.workers, backend=args.backend, progress=not args.quiet,
                     extend=args.extend)
    print(f"lawn sweep {spec.name}: {len(rows)} rows in {args.out}; mean ± 95 % interval")
    print(summarize_sweep(rows, list(spec.grid)))
    return 0
