"""What every ``lawn`` subcommand shares: the shared flags (:func:`command`), the argument types
(counts, seeds, policy names: one type for every subcommand), ``KEY=VALUE`` overrides and the config
they make."""

from __future__ import annotations

import argparse
import json
import os
from collections.abc import Callable
from typing import Any

import lawn_env
from agents.learned import learned_name_forms
from agents.policies import is_policy_name, policy_names
from agents.runs import read_run
from evaluation.episode import TRANSIENT_SLOTS
from evaluation.run import REFERENCE_ROWS, is_reference_row
from lawn_env import presets

__all__ = ["command", "count", "seed", "comparison_env", "policy_name", "policy_help", "parse_overrides", "config_of",
           "included"]


def _int_at_least(low: int) -> Callable[[str], int]:
    """argparse type: an integer >= ``low``, with the bound in the message."""

    def parse(value: str) -> int:
        try:
            number = int(value)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{value!r} is not an integer") from None
        if number < low:
            raise argparse.ArgumentTypeError(f"{number} must be >= {low}")
        return number

    parse.__name__ = f"integer >= {low}"
    return parse


#: argparse types: a count (>= 1) and a seed (>= 0).
count, seed = _int_at_least(1), _int_at_least(0)


def comparison_env(value: str) -> str:
    """argparse type of ``evaluate`` and ``benchmark``'s ``--env``: an id of ``lawn_env.ENV_IDS``.
    Comparisons play full episodes of the unmodified scenario; an RL id's termination and bounded
    reward would change them (``lawn render`` shows an episode on any id)."""
    if value in lawn_env.ENV_IDS:
        return value
    if value in lawn_env.RL_ENV_IDS:
        raise argparse.ArgumentTypeError(
            f"{value!r} is the RL interface of {lawn_env.RL_ENV_IDS[value]!r}: comparisons play full episodes of the "
            f"unmodified scenario, so pass --env {lawn_env.RL_ENV_IDS[value]} (an agent trained on {value} plays it "
            "through its own interface); lawn render shows an episode on either id")
    raise argparse.ArgumentTypeError(f"unknown env id {value!r}; valid: {', '.join(lawn_env.ENV_IDS)}")


comparison_env.__name__ = "env id"


def policy_name(value: str) -> str:
    """argparse type: a registered policy, a learned agent's name (``zoo:``, ``sb3:``, ...) or a
    benchmark reference row (``limit:...``, ``noise:...``, ``actuator:buffer``;
    :mod:`evaluation.run`)."""
    if not (is_policy_name(value) or is_reference_row(value)):
        raise argparse.ArgumentTypeError(
            f"unknown policy {value!r}; valid: {', '.join(policy_names())}, the reference rows "
            f"{', '.join(REFERENCE_ROWS)}, or {learned_name_forms()}")
    return value


def policy_help(prefix: str = "") -> str:
    """The policy names a ``--policy`` flag takes, for its help."""

    return (f"{prefix}{', '.join(policy_names())}, or {learned_name_forms(' / ')} for learned agents; "
            f"the benchmark's reference rows {', '.join(REFERENCE_ROWS)} (docs/benchmark.md)")


def _shared_flags() -> dict[str, list[tuple[str, dict[str, Any]]]]:
    """The shared flags by name: each one's ``add_argument`` flag and options."""

    return {
        "debug": [("--debug", {"action": "store_true", "default": argparse.SUPPRESS,  # also after the subcommand
                               "help": "on an error, show the traceback"})],
        "workers": [("--workers", {"type": count, "default": min(2, os.cpu_count() or 1),
                                   "help": "processes (default: %(default)s)"})],
        "quiet": [("--quiet", {"action": "store_true", "help": "no progress bar"})],
        "seed": [("--seed", {"type": seed, "default": 0, "help": "first seed; episode i uses seed + i (default: 0)"})],
        "one_seed": [("--seed", {"type": seed, "default": 0, "help": "the episode's seed (default: 0)"})],
        "config": [("--preset", {"default": "default", "choices": presets.names(),
                                 "help": "scenario preset (default: %(default)s)"}),
                   ("--set", {"action": "append", "default": [], "metavar": "KEY=VALUE",
                              "help": "config override with a dotted key, e.g. --set channel.blocklength=256 "
                                      "(repeatable)"})],
        "split": [("--transient-slots", {
            "type": _int_at_least(1), "default": TRANSIENT_SLOTS, "metavar": "N",
            "help": "the transient/sustained split of each episode's control cost: slots 0..N-1 and N on "
                    "(default: %(default)s)"})],
        "policy_arg": [("--policy-arg", {
            "action": "append", "default": [], "metavar": "KEY=VALUE",
            "help": "policy setting, e.g. --policy-arg power_levels=60 for rg-mpc or tolerance=1e-3 for ao-mpc "
                    "(repeatable; the fields of agents.DeliverySettings for dv-mpc, agents.ReducedSettings for "
                    "rg-mpc, agents.AOSettings for the AO planners)"})],
        "overwrite": [("--overwrite", {
            "action": "store_true",
            "help": "replace the results an earlier run left at --out (without it, such an --out is refused, and a "
                    "default one becomes a new numbered path)"})],
        "backend": [("--backend", {"choices": ["process", "ray"], "default": "process",
                                   "help": "a process pool (default) or Ray (local, or the cluster at $RAY_ADDRESS)"})],
    }


def command(sub: argparse._SubParsersAction[argparse.ArgumentParser], name: str, *shared: str,
            **kwargs: Any) -> argparse.ArgumentParser:
    """The parser of subcommand ``name`` with ``--debug`` and the named shared flags (``"workers"``,
    ``"quiet"``, ``"seed"`` (a first seed), ``"one_seed"`` (one episode's), ``"config"``, ``"split"``,
    ``"policy_arg"``, ``"overwrite"``, ``"backend"``), each with one meaning everywhere."""
    from . import COMMAND_HELP

    parser = sub.add_parser(name, help=COMMAND_HELP[name], **kwargs)
    flags = _shared_flags()
    for key in ("debug", *shared):
        for flag, options in flags[key]:
            parser.add_argument(flag, **options)
    return parser


def parse_overrides(items: list[str], flag: str = "--set") -> dict[str, Any]:
    """``key=value`` pairs with dotted keys; values parsed as JSON when possible."""
    out = {}
    for item in items:
        key, _, raw = item.partition("=")
        if not _ or not key.strip():
            raise ValueError(f"{flag} expects KEY=VALUE (e.g. channel.blocklength=256), got {item!r}")
        try:
            out[key] = json.loads(raw)
        except json.JSONDecodeError:
            out[key] = raw
    return out


def config_of(args: argparse.Namespace) -> lawn_env.ScenarioConfig:
    """The scenario of ``--preset`` with the ``--set`` overrides."""
    cfg = presets.get(args.preset)
    return cfg.override(parse_overrides(args.set)) if args.set else cfg


def included(paths: list[str]) -> list[str]:
    """Policy names for trained run directories: marl:, bc: or sb3: by what run.json says."""
    return [read_run(path, "--include").policy_name for path in paths]
