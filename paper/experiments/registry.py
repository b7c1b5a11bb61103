"""Every experiment by name (:data:`EXPERIMENTS`), in the order of the reproduction page."""

from __future__ import annotations

from . import blocklength, cdf, ce, convergence, disturbance, paths, rate
from .base import Experiment

__all__ = ["EXPERIMENTS"]

EXPERIMENTS: dict[str, Experiment] = {
    m.EXPERIMENT.name: m.EXPERIMENT for m in (convergence, ce, cdf, rate, blocklength, paths, disturbance)
}
