"""Policies that drive the lawn environments: the AO-MPC expert, the paper's baselines and
wrappers for learned policies (later issues), plus a scripted heuristic for demos."""

from .scripted import HeuristicPolicy

__all__ = ["HeuristicPolicy"]
