"""Policies that drive the lawn environments: the delivery-value expert ``dv-mpc``, the paper's
AO-MPC expert and its exact solution ``rg-mpc``, the paper's baselines, a
scripted heuristic, and wrappers for learned policies. ``make_policy(name, config)`` builds any
of them (``trained_config(name)``: a learned agent's training scenario); ``POLICIES`` is the
registry (:mod:`agents.registry`: one entry per name, ``register`` adds one); ``rollout(env, policy, seed)``
runs one episode."""

from pathlib import Path

from lawn_env import kernel_cache

kernel_cache.register(Path(__file__).parent)  # before any kernel here: they compile lawn_env's equations in


from lawn_env.rollouts import Episode, Step, rollout

from .anchors import ANCHORS, AnchorPolicy, anchor_name
from .ao import AOSettings, AOSolver, expected_cost
from .base import Planner
from .dv_mpc import DeliverySettings, DeliveryValuePlanner
from .global_mpc import GlobalPlanner
from .learned import trained_config
from .policies import BENCHMARK_POLICIES, PAPER_POLICIES, POLICIES, Policy, make_policy, policy_names
from .problem import Plan
from .registry import PolicyEntry, register, unregister
from .rg_mpc import ReducedGradientPlanner, ReducedSettings
from .scripted import HeuristicPolicy

__all__ = [
    "ANCHORS",
    "AnchorPolicy",
    "anchor_name",
    "AOSettings",
    "AOSolver",
    "Plan",
    "Planner",
    "expected_cost",
    "Policy",
    "POLICIES",
    "PAPER_POLICIES",
    "BENCHMARK_POLICIES",
    "PolicyEntry",
    "register",
    "unregister",
    "ReducedGradientPlanner",
    "ReducedSettings",
    "DeliveryValuePlanner",
    "DeliverySettings",
    "GlobalPlanner",
    "make_policy",
    "trained_config",
    "policy_names",
    "HeuristicPolicy",
    "rollout",
    "Episode",
    "Step",
]
