"""The names the training modules import from here; they live in :mod:`training.results.stats`
(import them from there)."""

from .results.stats import mean_ci, paired_difference

__all__ = ["mean_ci", "paired_difference"]
