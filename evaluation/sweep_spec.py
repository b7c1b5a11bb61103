"""A sweep's specification: the :class:`SweepSpec` record, read from a YAML or JSON file or a mapping
and checked (:func:`load_spec`), and its grid points (:func:`expand`, :func:`point_config`). The keys
are :mod:`evaluation.sweep`'s module docstring's."""

from __future__ import annotations

import itertools
import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeAlias

import lawn_env
from agents import make_policy
from lawn_env import presets

__all__ = ["SpecValue", "SweepSpec", "load_spec", "expand", "point_config"]

#: A value a spec gives a config field (``set``, ``grid``) or a policy argument: what YAML and JSON hold.
SpecValue: TypeAlias = "str | int | float | bool | list[SpecValue] | dict[str, SpecValue] | None"

_SPEC_KEYS = {"name", "env", "preset", "set", "grid", "policies", "seeds", "policy_args"}


@dataclass(frozen=True)
class SweepSpec:
    """A sweep specification (the module docstring's keys): the env and base scenario (``preset``
    with the fixed overrides ``set``), the grid (config key -> its values), the policies with their
    arguments (``policy_args``: policy -> keyword arguments) and the seeds. :func:`load_spec` checks
    one before a sweep runs it."""

    name: str = "sweep"
    env: str = "lawn/Joint-v1"
    preset: str = "default"
    set: Mapping[str, SpecValue] = field(default_factory=dict)
    grid: Mapping[str, Sequence[SpecValue]] = field(default_factory=dict)
    policies: tuple[str, ...] = ("rg-mpc",)
    seeds: tuple[int, ...] = tuple(range(5))
    policy_args: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)  # a policy's own keyword types

    @classmethod
    def from_mapping(cls, spec: Mapping[str, Any], source: str = "the sweep spec") -> SweepSpec:
        """The spec of a document's mapping (``source`` names it in errors): its keys, grid, policies
        and seeds checked, the others defaulted."""
        unknown = set(spec) - _SPEC_KEYS
        if unknown:
            raise ValueError(f"unknown sweep spec keys {sorted(unknown)}; valid: {', '.join(sorted(_SPEC_KEYS))}")
        grid = spec.get("grid", {})
        if not isinstance(grid, Mapping):
            raise ValueError(f"{source}: grid must map config keys to lists of values; got {grid!r}")
        for key, values in grid.items():
            if not isinstance(values, (list, tuple)) or not values:
                raise ValueError(f"{source}: grid key {key!r} must map to a non-empty list of values; got {values!r}")
        policies = spec.get("policies", ["rg-mpc"])
        if not isinstance(policies, (list, tuple)) or not policies or not all(isinstance(p, str) for p in policies):
            raise ValueError(f"{source}: policies must be a non-empty list of policy names; got {policies!r}")
        return cls(name=spec.get("name", "sweep"), env=spec.get("env", "lawn/Joint-v1"),
                   preset=spec.get("preset", "default"), set=dict(spec.get("set", {})),
                   grid={k: list(v) for k, v in grid.items()}, policies=tuple(policies),
                   seeds=tuple(_seed_list(spec.get("seeds", 5), source)), policy_args=dict(spec.get("policy_args", {})))


def _read_spec(spec: str | os.PathLike[str] | Mapping[str, Any]) -> tuple[Any, str]:
    """The spec's document (a YAML or JSON file, or the mapping itself) and how errors name it."""
    source = "the sweep spec"
    if not isinstance(spec, (Mapping, str, os.PathLike)):
        raise TypeError(f"spec must be a mapping or the path of a YAML/JSON file; got {type(spec).__name__}")
    if not isinstance(spec, Mapping):
        path = Path(spec)
        source = f"sweep spec {str(path)!r}"
        if not path.exists():
            raise ValueError(f"{source} does not exist")
        text = path.read_text()
        try:
            if path.suffix.lower() == ".json":
                spec = json.loads(text)
            else:
                import yaml

                spec = yaml.safe_load(text)
        except ValueError as exc:  # json.JSONDecodeError
            raise ValueError(f"{source} is not valid JSON: {exc}") from None
        except Exception as exc:  # yaml.YAMLError and its subclasses
            mark = getattr(exc, "problem_mark", None)
            where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
            raise ValueError(f"{source} is not valid YAML{where}: {getattr(exc, 'problem', None) or exc}") from None
    return spec, source



def _seed_list(seeds: Any, source: str) -> list[int]:
    """A spec's ``seeds``: a count (seeds 0..n-1) or a list of seeds >= 0."""
    if isinstance(seeds, bool) or not isinstance(seeds, (int, list, tuple)):
        raise ValueError(f"{source}: seeds must be a count >= 1 or a non-empty list of seeds >= 0; got {seeds!r}")
    if isinstance(seeds, int):
        if seeds < 1:
            raise ValueError(f"{source}: seeds={seeds} must be >= 1 (a count) or a non-empty list of seeds >= 0")
        return list(range(seeds))
    if not seeds or any(isinstance(s, bool) or not isinstance(s, int) or s < 0 for s in seeds):
        raise ValueError(f"{source}: seeds={seeds!r} must be a non-empty list of integers >= 0")
    return [int(s) for s in seeds]


def load_spec(spec: str | os.PathLike[str] | Mapping[str, Any] | SweepSpec) -> SweepSpec:
    """A sweep spec (a :class:`SweepSpec`, a mapping or a YAML/JSON file) checked: its keys, grid,
    policies, seeds and env, and every grid point's config and policy built once, so a bad spec
    fails before any episode runs."""
    if not isinstance(spec, SweepSpec):
        doc, source = _read_spec(spec)
        if not isinstance(doc, Mapping):
            raise ValueError(f"{source} must be a mapping of {', '.join(sorted(_SPEC_KEYS))}; got "
                             f"{type(doc).__name__ if doc is not None else 'an empty document'}")
        spec = SweepSpec.from_mapping(doc, source)
    if spec.env not in lawn_env.ENV_IDS:
        raise ValueError(f"sweep env {spec.env!r}; valid: {', '.join(lawn_env.ENV_IDS)}")
    for point in expand(spec):  # validate every grid point and policy before running anything
        cfg = point_config(spec, point)
        for name in spec.policies:
            make_policy(name, cfg, env_id=spec.env, **spec.policy_args.get(name, {}))
    return spec


def point_config(spec: SweepSpec, point: Mapping[str, SpecValue]) -> lawn_env.ScenarioConfig:
    """The scenario of one grid point: its ``preset`` (a grid key may switch presets) with the
    spec's fixed overrides, then the point's other values."""
    rest = {k: v for k, v in point.items() if k != "preset"}
    return presets.get(str(point.get("preset", spec.preset))).override(spec.set).override(rest)


def expand(spec: SweepSpec) -> list[dict[str, SpecValue]]:
    """Every grid point of ``spec`` (one point, ``{}``, without a grid)."""
    grid = spec.grid
    return [dict(zip(grid, values, strict=True)) for values in itertools.product(*grid.values())] or [{}]
