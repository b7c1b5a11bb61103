"""``lawn dataset create``: a policy's episodes as a Minari dataset (data extra)."""

from __future__ import annotations

import argparse

from lawn_env import presets
from training.datasets import create_dataset

from .common import command, count, policy_help, policy_name


def add(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> argparse.ArgumentParser:
    ds = command(sub, "dataset", "quiet", "seed")
    ds.add_argument("action", choices=["create"])
    ds.add_argument("--policy", required=True, type=policy_name, help=policy_help("any policy: "))
    ds.add_argument("--env", required=True, choices=["lawn/Joint-v1", "lawn/Comm-v1"],
                    help="the env the episodes run on")
    ds.add_argument("--episodes", type=count, required=True, help="episodes, seeds --seed..")
    ds.add_argument("--dataset-id", required=True, metavar="ID",
                    help="Minari id, e.g. lawn/comm/rg-mpc-v0; stored under MINARI_DATASETS_PATH")
    ds.add_argument("--task", default="default", choices=presets.names(), help="scenario preset (default: %(default)s)")
    return ds


def run(args: argparse.Namespace) -> int:
    dataset = create_dataset(args.policy, args.env, args.episodes, args.seed, args.dataset_id, task=args.task,
                             progress=not args.quiet)
    steps = int(dataset.total_steps)
    print(f"lawn dataset create: {args.dataset_id}: {args.episodes} episodes (seeds {args.seed}-"
          f"{args.seed + args.episodes - 1}) of {args.policy} on {args.env}, task {args.task}, {steps} steps")
    run_name = "".join(c if c.isalnum() or c in "-_." else "-" for c in args.dataset_id.rsplit("/", 1)[-1])
    print(f"load it with minari.load_dataset({args.dataset_id!r}); clone it with lawn train --algo bc --env {args.env} "
          f"--preset {args.task} --dataset {args.dataset_id} --timesteps {steps} --out runs/bc-{run_name}"
          + ("" if args.policy == "rg-mpc" else f" --hp expert={args.policy} (DAgger relabels with the same policy)"))
    return 0
