"""The front door of evaluation from Python: play policies on the same seeds and get typed episode
results and their paired statistics back, as ``lawn evaluate`` and ``lawn benchmark`` do from the
command line (Stable-Baselines3's ``evaluate_policy`` for one policy; this compares several)::

    from evaluation.api import compare

    result = compare(["dv-mpc", "rg-mpc", "epa"], config="steady", seeds=range(20))
    result.geometric["rg-mpc"]          # rg-mpc against dv-mpc: geometric mean of per-seed cost ratios
    result.of("epa")[0].control_cost    # one EpisodeResult per seed (evaluation.episode)

Every episode is a full one of the unmodified scenario (:func:`.run.run_episode`); the policies are
any name ``lawn evaluate --policy`` takes (experts, baselines, anchors, reference rows, learned agents).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from agents.base import JOINT
from lawn_env.presets import ConfigLike, resolve_config

from .episode import TRANSIENT_SLOTS, EpisodeResult, EpisodeSpec
from .run import build_policy, evaluate
from .stats import Geometric, paired_geometric

__all__ = ["EpisodeResult", "EpisodeSpec", "Comparison", "compare"]


@dataclass(frozen=True)
class Comparison:
    """The results of :func:`compare` and the paired statistics against ``reference``: ``geometric[p]``
    is policy p's geometric mean of per-seed cost ratios against the reference with its bootstrap
    interval and the share of seeds won (:class:`.stats.Geometric`)."""

    results: list[EpisodeResult]
    reference: str
    geometric: dict[str, Geometric]

    def of(self, policy: str) -> list[EpisodeResult]:
        """The results of one policy, in seed order."""
        return sorted((r for r in self.results if r.policy == policy), key=lambda r: r.seed)

    def costs(self, policy: str) -> dict[int, float]:
        """Seed -> control cost of one policy (what the paired statistics take)."""
        return {r.seed: r.control_cost for r in self.of(policy)}


def compare(policies: Sequence[str], config: ConfigLike = None, seeds: Iterable[int] = range(10),
            env: str = JOINT, reference: str | None = None, settings: Mapping[str, Mapping[str, Any]] | None = None,
            workers: int = 1, progress: bool = False) -> Comparison:
    """Play every policy of ``policies`` on ``seeds`` of ``config`` (a :class:`lawn_env.ScenarioConfig`,
    a dict or a preset name) on ``env`` and compare each with ``reference`` (default: the first policy)
    per seed. ``settings`` maps a policy name to its settings (``lawn evaluate --policy-arg``);
    ``workers`` processes play the episodes (the results do not depend on them)."""
    names = list(dict.fromkeys(policies))
    if not names:
        raise ValueError("policies is empty: name at least one policy (lawn evaluate --policy takes the same names)")
    reference = names[0] if reference is None else reference
    if reference not in names:
        names.append(reference)
    unknown = sorted(set(settings or {}) - set(names))
    if unknown:
        raise ValueError(f"settings for {unknown}, which are not among the policies {names}")
    cfg, seed_list = resolve_config(config), [int(s) for s in seeds]
    for p in names:  # a bad name or setting, or an agent trained elsewhere, fails before any episode
        build_policy(p, cfg, env, (settings or {}).get(p))
    specs = [EpisodeSpec(p, env, cfg, s, dict((settings or {}).get(p, {}))) for p in names for s in seed_list]
    results = evaluate(specs, workers=workers, progress=progress, desc="compare", transient_slots=TRANSIENT_SLOTS)
    out = Comparison(results, reference, {})
    base = out.costs(reference)
    out.geometric.update({p: paired_geometric(out.costs(p), base) for p in names if p != reference})
    return out
