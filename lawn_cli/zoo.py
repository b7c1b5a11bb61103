"""``lawn zoo``: the shipped learned agents: list them, train their recipes, benchmark and export."""

from __future__ import annotations

import argparse
from pathlib import Path

from agents.errors import MissingExtra
from paper.learned import build_zoo
from training.train import train_recipes
from training.zoo import format_zoo_list

from .common import command

#: Where ``lawn zoo build`` exports the agents.
ZOO_HINT = "agents/zoo/<name>/ (policy.zip, normalizer.npz, agent.json)"


def add(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> argparse.ArgumentParser:
    zo = command(sub, "zoo", "workers", "quiet")
    zo.add_argument("action", nargs="?", default="list", choices=["list", "train", "build"],
                    help="list the shipped agents (default), train their recipes, or build the zoo from the runs")
    zo.add_argument("--runs", default="runs/agents", help="training runs, one folder per recipe (default: %(default)s)")
    zo.add_argument("--only", nargs="+", metavar="NAME",
                    help="train only these recipes; build: rebuild only the sections of docs/LEARNED.md they are in "
                         "(the fleet networks' block, or the main tables), keeping the rest of the page")
    zo.add_argument("--doc", default="docs/LEARNED.md", help="build: the table's document (default: %(default)s)")
    return zo


def run(args: argparse.Namespace) -> int:
    if args.action == "list":
        print(format_zoo_list())
        return 0
    try:
        import stable_baselines3  # noqa: F401
    except ImportError:
        raise MissingExtra("lawn zoo train/build need the rl extra: bash scripts/setup.sh full") from None
    if args.action == "train":
        dirs = train_recipes(Path(args.runs), args.only, workers=args.workers, progress=not args.quiet)
        print(f"lawn zoo train: {len(dirs)} runs in {args.runs}")
        return 0
    table = build_zoo(Path(args.runs), Path(args.doc), workers=args.workers, progress=not args.quiet, only=args.only)
    print(table)
    print(f"wrote {args.doc} and {ZOO_HINT}")
    return 0
