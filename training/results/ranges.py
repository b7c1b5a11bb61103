"""Learned agents on two disjoint ranges of test seeds, with the tail: how one range moves to the
next, and how bad the worst seeds are, beside the geometric comparison.

A 100-seed interval on one range understates how much the next range differs (the fleet networks
moved from +2 % to +9 % between ranges), so every learned-agent comparison reports both
(:data:`TEST_RANGES`), and a target is *met* only when it holds on each. The tail is the share of
seeds costing over :data:`TAIL_RATIO` times the reference and the worst seed's ratio: a network
that loses an AGV on one seed in twenty is not hidden by a geometric mean.

* :func:`test_seeds` the seeds of both ranges; :func:`range_of` which range a seed is in.
* :func:`compare_ranges` a :class:`RangeComparison` of per-seed costs against a reference.
* :func:`fleet_table` (the fleet networks on K = 3..64) and :func:`distil_table` (the distilled
  agents on the steady suite tasks), the Markdown of the two protocols of :mod:`training.benchmark`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .cells import fmt_geometric, fmt_num, markdown_table
from .report import mean_cell
from .run import policy_env
from .stats import SCORE_HIGH, Geometric, costs_of, paired_geometric

__all__ = ["TEST_RANGES", "TAIL_RATIO", "test_seeds", "range_of", "RangeComparison", "compare_ranges",
           "FLEET_TARGETS", "FLEET_WORST", "fleet_table", "distil_table"]

#: The first seed of each test range: 0.. (the learned protocol's) and 100,000.. (disjoint from it,
#: from the validation seeds 500,000.. and from the training seeds 1,000,000..).
TEST_RANGES: tuple[int, ...] = (0, 100_000)
#: A seed is in the tail when it costs over this many times the reference.
TAIL_RATIO = 1.5
#: The fleet networks' targets against dv-mpc: the upper bound of the geometric interval, per K
#: (None: reported), on every range; and no seed over FLEET_WORST times dv-mpc's cost.
FLEET_TARGETS: dict[int, float | None] = {3: 0.05, 4: 0.05, 8: 0.05, 16: 0.10, 32: 0.10, 64: None}
FLEET_WORST = 3.0
_NOISE = f"noise:{SCORE_HIGH}"


def test_seeds(n: int) -> list[int]:
    """The first ``n`` seeds of every test range."""
    return [base + i for base in TEST_RANGES for i in range(int(n))]


def range_of(seed: int) -> int:
    """The index of the test range ``seed`` is in."""
    return max(i for i, base in enumerate(TEST_RANGES) if seed >= base)


@dataclass(frozen=True)
class RangeComparison:
    """Per-seed costs against a reference: the geometric comparison on each range, the share of all
    seeds over :data:`TAIL_RATIO` times the reference, and the worst seed and its ratio."""

    ranges: tuple[Geometric, ...]
    tail: float
    worst: float
    worst_seed: int

    def below(self, bound: float) -> bool:
        """Every range's upper interval bound on the ratio is at most ``bound`` (1.05: +5 %)."""
        return all(math.isfinite(g.high) and g.high <= bound for g in self.ranges)

    def cell(self) -> str:
        """One geometric cell per range, separated by slashes."""
        return " / ".join(fmt_geometric(g, wins=False) for g in self.ranges)

    def tail_cell(self) -> str:
        return f"{self.tail * 100:.0f} %"

    def worst_cell(self) -> str:
        return f"{self.worst:.2f}× (seed {self.worst_seed})"


def compare_ranges(costs: Mapping[int, float], reference: Mapping[int, float]) -> RangeComparison:
    """:class:`RangeComparison` of ``costs`` against ``reference`` on the seeds both hold."""
    seeds = sorted(s for s in costs if s in reference)
    if not seeds:
        raise ValueError("compare_ranges: the costs and the reference share no seed")
    groups = [[s for s in seeds if range_of(s) == i] for i in range(len(TEST_RANGES))]
    ranges = tuple(paired_geometric({s: costs[s] for s in g}, {s: reference[s] for s in g}) for g in groups if g)
    ratio = np.array([costs[s] / reference[s] for s in seeds])
    worst = int(np.argmax(ratio))
    return RangeComparison(ranges, float(np.mean(ratio > TAIL_RATIO)), float(ratio[worst]), seeds[worst])


def _decision_ms(rows: Sequence[Mapping[str, Any]], policy: str, env: str, task: str) -> float:
    return 1e3 * float(np.median(list(costs_of(rows, policy, env, task, "decision_time_median_s").values())))


def _fleet_target(k: int, c: RangeComparison) -> str:
    target = FLEET_TARGETS.get(k)
    if target is None:
        return "reported"
    met = c.below(1.0 + target) and c.worst <= FLEET_WORST
    return f"≤ {target * 100:+.0f} %, ≤ {FLEET_WORST:g}×: {'met' if met else 'missed'}"


def fleet_table(rows: Sequence[Mapping[str, Any]], agents: Sequence[str], sizes: Mapping[int, int],
                targeted: set[str]) -> str:
    """Per env and K: the noise-floor row and every agent against dv-mpc on both test ranges, the
    tail, the worst seed, the target (for ``targeted``, the networks trained on mixed fleets) and
    the decision times."""
    table = []
    for env in dict.fromkeys(policy_env(a) for a in agents):
        for policy in [_NOISE, *(a for a in agents if policy_env(a) == env)]:
            for k in sizes:
                task = f"k{k}"
                mine, ref = costs_of(rows, policy, env, task), costs_of(rows, SCORE_HIGH, env, task)
                if not mine or not ref:
                    continue
                c = compare_ranges(mine, ref)
                ms, ref_ms = _decision_ms(rows, policy, env, task), _decision_ms(rows, SCORE_HIGH, env, task)
                table.append([policy, env, str(k), str(len(mine)), mean_cell(rows, policy, env, task, "control_cost"),
                              mean_cell(rows, SCORE_HIGH, env, task, "control_cost"), c.cell(), c.tail_cell(),
                              c.worst_cell(), _fleet_target(k, c) if policy in targeted else "–", f"{ms:.3g}",
                              f"{ref_ms / ms:.1f}×"])
    header = ["policy", "env", "K", "seeds", "control cost", f"{SCORE_HIGH} cost",
              f"vs {SCORE_HIGH}, geometric [95 %]: seeds {TEST_RANGES[0]}.. / {TEST_RANGES[1]}..",
              f"seeds > {TAIL_RATIO:g}× {SCORE_HIGH}", "worst seed", "target (both ranges)", "decision time (ms)",
              f"{SCORE_HIGH} / policy time"]
    return markdown_table(header, table)


#: The distilled agents' targets: the upper bound against rg-mpc below zero and against dv-mpc at
#: most +3 % on both ranges, and a decision in at most 1 ms (the median).
DISTIL_VS_RG, DISTIL_VS_DV, DISTIL_MS = 1.0, 1.03, 1.0


def distil_table(rows: Sequence[Mapping[str, Any]], agents: Mapping[str, tuple[str, str]], tasks: Sequence[str],
                 reference_env: str, targeted: set[str]) -> str:
    """Per agent (``{policy: (label, env)}``) and task: its cost against ``rg-mpc`` and ``dv-mpc``
    (played on ``reference_env``, the same scenario and seeds) on both ranges, the tail and worst
    seed against dv-mpc, the decision time and, for ``targeted`` (the clones of dv-mpc), the targets."""
    table = []
    for policy, (label, env) in agents.items():
        for task in tasks:
            mine = costs_of(rows, policy, env, task)
            if not mine:
                continue
            rg = compare_ranges(mine, costs_of(rows, "rg-mpc", reference_env, task))
            dv = compare_ranges(mine, costs_of(rows, SCORE_HIGH, reference_env, task))
            ms = _decision_ms(rows, policy, env, task)
            met = rg.below(DISTIL_VS_RG - 1e-12) and dv.below(DISTIL_VS_DV) and ms <= DISTIL_MS
            table.append([label, env, task, str(len(mine)), mean_cell(rows, policy, env, task, "control_cost"),
                          fmt_num(float(np.mean(list(costs_of(rows, SCORE_HIGH, reference_env, task).values())))),
                          rg.cell(), dv.cell(), dv.tail_cell(), dv.worst_cell(), f"{ms:.3g}",
                          ("met" if met else "missed") if policy in targeted else "–"])
    header = ["agent", "env", "task", "seeds", "control cost", f"{SCORE_HIGH} cost",
              f"vs rg-mpc, geometric [95 %]: seeds {TEST_RANGES[0]}.. / {TEST_RANGES[1]}..",
              f"vs {SCORE_HIGH}, same", f"seeds > {TAIL_RATIO:g}× {SCORE_HIGH}", f"worst seed vs {SCORE_HIGH}",
              "decision time (ms)", "target: < 0 vs rg-mpc, ≤ +3 % vs dv-mpc, ≤ 1 ms"]
    return markdown_table(header, table)
