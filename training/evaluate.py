"""The names the training modules import from here; they live in :mod:`training.results.run` and
:mod:`training.pool` (import them from there)."""

from .pool import pool_map
from .results.run import episode_row, evaluate

__all__ = ["episode_row", "evaluate", "pool_map"]
