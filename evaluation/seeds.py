"""The seed ranges, in one place: what the learners train on, what model selection validates on and
what every comparison tests on never meet.

=========================  ======================================================================
test seeds                 ``TEST_RANGES``: 0.. (the learned protocol's first ``TEST_EPISODES``)
                           and 100,000.. (the second, disjoint range a target must also hold on)
validation seeds           ``VALIDATION_SEED_BASE + i`` (500,000..): model selection, early stopping
training seeds             ``TRAIN_SEED_BASE + 1000 s + ...`` (1,000,000..): the training envs of run s
=========================  ======================================================================
"""

from __future__ import annotations

__all__ = ["TRAIN_SEED_BASE", "VALIDATION_SEED_BASE", "TEST_EPISODES", "TEST_RANGES", "test_seeds", "range_of"]

#: Training environments of seed s start at TRAIN_SEED_BASE + 1000 s (disjoint from the test seeds).
TRAIN_SEED_BASE = 1_000_000
#: Validation (model selection) episodes use VALIDATION_SEED_BASE + i.
VALIDATION_SEED_BASE = 500_000
#: Test episodes of the learned protocol: seeds 0..TEST_EPISODES-1. Per-seed relative differences
#: between agents have a standard deviation of 10-20 %, so a +-3 % interval needs about 100 seeds.
TEST_EPISODES = 100
#: The first seed of each test range: 0.. (the learned protocol's) and 100,000.. (disjoint from it,
#: from the validation seeds 500,000.. and from the training seeds 1,000,000..). A 100-seed interval
#: on one range understates how much the next differs (the fleet networks moved from +2 % to +9 %
#: between ranges), so a learned agent's target is met only when it holds on each.
TEST_RANGES: tuple[int, ...] = (0, 100_000)


def test_seeds(n: int) -> list[int]:
    """The first ``n`` seeds of every test range."""
    return [base + i for base in TEST_RANGES for i in range(int(n))]


def range_of(seed: int) -> int:
    """The index of the test range ``seed`` is in."""
    return max(i for i, base in enumerate(TEST_RANGES) if seed >= base)
