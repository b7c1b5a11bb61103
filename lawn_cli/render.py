"""``lawn render``: one seeded episode of any policy as an animation (GIF or MP4)."""

from __future__ import annotations

import argparse
from pathlib import Path

import lawn_env
from evaluation.render import render_episode

from .common import command, config_of, count, parse_overrides, policy_help, policy_name


def add(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> argparse.ArgumentParser:
    re = command(sub, "render", "quiet", "one_seed", "config", "policy_arg", "overwrite")
    re.add_argument("--policy", default="rg-mpc", type=policy_name, help=policy_help("default: rg-mpc; "))
    re.add_argument("--env", default=None, choices=[*lawn_env.ENV_IDS, *lawn_env.RL_ENV_IDS],
                    help="default: lawn/Joint-v1, or the env a trained agent was trained on")
    re.add_argument("--out", required=True, help="the animation: FILE.gif or FILE.mp4 (MP4 needs the video extra)")
    re.add_argument("--fps", type=float, default=8.0, help="frames per second (default: %(default)s; a slot is 0.5 s)")
    re.add_argument("--every", type=count, default=1, help="keep every n-th slot's frame (default: %(default)s)")
    return re


def run(args: argparse.Namespace) -> int:
    result = render_episode(args.policy, Path(args.out), env_id=args.env, seed=args.seed,
                            config=config_of(args), fps=args.fps, every=args.every, progress=not args.quiet,
                            **parse_overrides(args.policy_arg, "--policy-arg"))
    print(f"lawn render: {args.policy} on {result['env_id']}, seed {args.seed}: control cost "
          f"{result['control_cost']:.1f}, {result['frames']} frames")
    print(f"wrote {result['out']}")
    return 0
