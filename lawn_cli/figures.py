"""``lawn figures``: the paper's experiments from tidy tables (running missing sweeps), their
claims' results, and with ``--docs`` the reproduction page."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from paper.experiments.claims import format_claims, write_claims
from paper.experiments.registry import EXPERIMENTS
from paper.experiments.reproduction import write_reproduction
from paper.experiments.runner import check_claims, make_figures, read_mode

from .common import command


def add(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> argparse.ArgumentParser:
    fg = command(sub, "figures", "workers", "quiet", "overwrite")
    fg.add_argument("names", nargs="*", choices=[[], *EXPERIMENTS], metavar="NAME",
                    help=f"figures to make (default: all): {', '.join(EXPERIMENTS)}")
    fg.add_argument("--out", default=None,
                    help="output directory (default: runs/figures, runs/figures-quick with --quick); a rerun of the "
                         "same mode there resumes (its tables are kept, the figures redrawn from them), another mode "
                         "is refused without --overwrite")
    fg.add_argument("--quick", action="store_true", help="reduced seeds, grids and episode length (tests)")
    fg.add_argument("--docs", default=None, metavar="DIR",
                    help="also write DIR/REPRODUCTION.md and copy the figures to DIR/figures/reproduction/")
    fg.set_defaults(default_out=lambda args: Path("runs/figures-quick" if args.quick else "runs/figures"),
                    holds_results=holds_results)
    return fg


def holds_results(args: argparse.Namespace, out: Path) -> bool:
    """Whether ``out`` holds figures of the other mode (``--quick`` or the full set, ``mode.json``): a
    rerun of the same mode resumes there, so its results are not replaced."""
    if not out.is_dir() or not any(out.iterdir()):
        return False
    return read_mode(out) != ("quick" if args.quick else "full")


def run(args: argparse.Namespace) -> int:
    if args.docs and args.quick:
        raise ValueError("--docs writes the published reproduction; it takes the full set, not --quick")
    start = time.perf_counter()
    out = Path(args.out)
    timings = make_figures(args.names, out, quick=args.quick, workers=args.workers, progress=not args.quiet)
    for name, seconds in timings.items():
        print(f"  {name:<12}{seconds:8.1f} s   {args.out}/{name}.png, .pdf, data/{name}.csv")
    print(f"lawn figures: {len(timings)} figures in {time.perf_counter() - start:.1f} s"
          + (" (--quick)" if args.quick else ""))
    claims = check_claims(out)  # every experiment whose tables are in OUT: what the reproduction page reads
    write_claims(claims, out)
    print(format_claims([c for c in claims if not args.names or c.figure in args.names]))
    if args.docs:
        print(f"wrote {write_reproduction(out, Path(args.docs))}")
    return 0
