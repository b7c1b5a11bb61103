"""Reference rows of the benchmark that are not deployable policies: headroom and noise floor.

A **limit row** plays the best expert (:data:`~training.score.SCORE_HIGH`, ``dv-mpc``) on its task
with one field of the scenario lifted (docs/benchmark.md, "Headroom rows"):

* ``limit:fast-drone``: the drone's speed bound ``drone.max_speed_mps`` raised to the largest value
  the configuration accepts (its validated upper bound): how much of the cost the drone's reach
  decides. The expert's drone grid is capped at 1,000 points there (its default cap, 10,000, lays
  the whole area at 2 m spacing for a 150 m reach: about six times the time for a headroom within
  the same interval, ``python benchmarks/fast_drone_grid.py``, measured on ``rg-mpc``);
* ``limit:perfect-links``: ``channel.perfect_links`` on, every command delivered: how much of the
  cost the links decide.

Neither is a strict bound on what a policy can reach on the unmodified task: the expert plans per
slot, not the episode, so a better planner at 15 m/s over imperfect links may beat the expert with
the limit lifted; and the planner is run as it is (its drone grid caps the points it searches, so a
larger reach is searched more coarsely). They say how much a task leaves to the drone and to the
links under the expert's own planning. (With every command delivered, ``dv-mpc`` and ``rg-mpc``
plan the same increments: both are the MPC at psi = 1.)

A **noise-floor row** plays an expert against itself under a harmless setting change (its drone
grid 1.4 m instead of 1.5 m): a paired difference between two policies that does not exceed the
noise row's is within what an immaterial change of the planner moves. ``noise:dv-mpc`` is the
tables' (the best expert's); ``noise:rg-mpc`` is ``rg-mpc``'s, for comparisons against it.

All three are played by :func:`training.evaluate.run_episode` under their own names; their
configs differ from the task's only in the field each lifts (:func:`limit_config`).
"""

from __future__ import annotations

from typing import Any, Mapping

from annotated_types import Le

from lawn_env import ScenarioConfig
from lawn_env.config import DroneConfig

from .score import SCORE_HIGH

__all__ = ["LIMITS", "LIMIT_SETTINGS", "NOISE", "REFERENCE_ROWS", "is_reference_row", "limit_config", "resolve"]


def _max_speed() -> float:
    """The validated upper bound of ``drone.max_speed_mps`` (the config's maximum)."""
    field = DroneConfig.__pydantic_fields__["max_speed_mps"]
    return float(next(m.le for m in field.metadata if isinstance(m, Le)))


#: name -> the lifted field (a dotted config key) and its value.
LIMITS: dict[str, tuple[str, Any]] = {
    "limit:fast-drone": ("drone.max_speed_mps", _max_speed()),
    "limit:perfect-links": ("channel.perfect_links", True),
}
#: name -> the settings of the expert a limit row plays with (bounded time per decision).
LIMIT_SETTINGS: dict[str, dict[str, Any]] = {
    "limit:fast-drone": {"max_drone_points": 1_000},
}
#: name -> the expert a noise-floor row plays and its settings that differ (harmlessly) from its defaults.
NOISE: dict[str, tuple[str, dict[str, Any]]] = {
    f"noise:{SCORE_HIGH}": (SCORE_HIGH, {"drone_spacing_m": 1.4}),
    "noise:rg-mpc": ("rg-mpc", {"drone_spacing_m": 1.4}),
}
#: Every reference row the tables show, in their order: the best expert's noise floor and the limits.
REFERENCE_ROWS: tuple[str, ...] = (f"noise:{SCORE_HIGH}", *LIMITS)


def is_reference_row(name: str) -> bool:
    """True for a limit or noise-floor row's name."""
    return name in LIMITS or name in NOISE


def limit_config(name: str, config: ScenarioConfig) -> ScenarioConfig:
    """The task ``config`` with the field of limit row ``name`` lifted (nothing else changes)."""
    if name not in LIMITS:
        raise ValueError(f"unknown limit row {name!r}; valid: {', '.join(LIMITS)}")
    key, value = LIMITS[name]
    return config.override({key: value})


def resolve(name: str, config: ScenarioConfig, policy_kwargs: Mapping[str, Any] | None = None
            ) -> tuple[str, ScenarioConfig, dict[str, Any]]:
    """(policy to build, config to play, policy settings) of a row name: a limit row becomes the
    best expert on its config with its settings, a noise-floor row its expert with its settings; any
    other name is returned as given."""
    kwargs = dict(policy_kwargs or {})
    if name in LIMITS:
        return SCORE_HIGH, limit_config(name, config), {**LIMIT_SETTINGS.get(name, {}), **kwargs}
    if name in NOISE:
        expert, settings = NOISE[name]
        return expert, config, {**settings, **kwargs}
    return name, config, kwargs
