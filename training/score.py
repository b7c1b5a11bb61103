"""The names the training modules import from here; they live in :mod:`training.results.stats`
(import them from there)."""

from .results.stats import SCORE_HIGH, SCORE_LOW

__all__ = ["SCORE_HIGH", "SCORE_LOW"]
