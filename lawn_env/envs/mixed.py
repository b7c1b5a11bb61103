"""Mixed fleets: one environment whose every episode draws its fleet size K.

:class:`MixedFleetEnv` holds one central environment per fleet size, all in the entity layout
(:mod:`lawn_env.entities`), whose spaces do not depend on K; each ``reset`` draws K from the env's
generator and plays that episode on the env of that size. A network that reads the entity layout
(``agents.fleet.FleetPolicy``) trains on it once for every K it will meet.
"""

from __future__ import annotations

import numbers
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from ..entities import MAX_AGVS
from ..interface import InterfaceLike, resolve_interface
from ..presets import ConfigLike, resolve_config
from .base import LawnEnv, Observation

__all__ = ["MixedFleetEnv"]


def _fleet_sizes(fleet_sizes: Any) -> list[int]:
    """The distinct sizes of ``fleet_sizes``, sorted, after checking that it is a non-empty sequence
    of integers K in [1, MAX_AGVS] (the entity layout's rows; within the config's bounds of num_agvs)."""
    allowed = f"a non-empty list of integers in [1, {MAX_AGVS}] (the fleet sizes K, at most MAX_AGVS={MAX_AGVS})"
    if isinstance(fleet_sizes, (str, bytes, Mapping)) or not isinstance(fleet_sizes, Iterable):
        raise ValueError(f"fleet_sizes={fleet_sizes!r}: expected {allowed}")
    given = [k.item() if isinstance(k, np.generic) else k for k in fleet_sizes]  # numpy scalars as Python's
    bad = [k for k in given
           if isinstance(k, bool) or not isinstance(k, numbers.Integral) or not 1 <= int(k) <= MAX_AGVS]
    if not given:
        raise ValueError(f"fleet_sizes={fleet_sizes!r} is empty; expected {allowed}")
    if bad:
        what = f"the entries {bad!r} are" if len(bad) > 1 else f"the entry {bad[0]!r} is"
        raise ValueError(f"fleet_sizes={given!r}: {what} not allowed; expected {allowed}")
    return sorted({int(k) for k in given})


class MixedFleetEnv(gym.Env):
    """Episodes of ``env_id`` (``lawn/Joint-v1`` or ``lawn/Comm-v1``) with K drawn uniformly from
    ``fleet_sizes`` at every reset; ``interface`` is any interface (its layout is set to
    ``entities``), ``config`` and ``overrides`` as for ``gym.make`` (``num_agvs`` is the draw's).
    ``info["num_agvs"]`` carries the episode's K."""

    metadata = {"render_modes": []}

    def __init__(self, env_id: str = "lawn/Joint-v1", fleet_sizes: Sequence[int] = tuple(range(3, 17)),
                 interface: InterfaceLike = "rl", config: ConfigLike = None, **overrides: Any):
        if not isinstance(env_id, str) or env_id not in ("lawn/Joint-v1", "lawn/Comm-v1"):
            raise ValueError(f"env_id={env_id!r}; valid: 'lawn/Joint-v1', 'lawn/Comm-v1'")
        sizes = _fleet_sizes(fleet_sizes)
        if "num_agvs" in overrides:
            raise ValueError(f"num_agvs={overrides['num_agvs']!r}: MixedFleetEnv draws K from fleet_sizes at every "
                             "reset; give the sizes as fleet_sizes=[...] instead")
        iface = resolve_interface(interface).to_dict() | {"layout": "entities"}
        base = resolve_config(config, **overrides)
        self.fleet_sizes = tuple(sizes)
        self.envs: dict[int, LawnEnv] = {
            k: gym.make(env_id, config=base.override(num_agvs=k), interface=iface).unwrapped  # type: ignore[misc]
            for k in sizes}
        first = self.envs[sizes[0]]  # the entity layout's spaces do not depend on K
        self.observation_space, self.action_space = first.observation_space, first.action_space
        self.env = first

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[Observation, dict[str, Any]]:
        super().reset(seed=seed)
        k = int(self.np_random.choice(self.fleet_sizes))
        self.env = self.envs[k]
        obs, info = self.env.reset(seed=int(self.np_random.integers(2**31)), options=options)
        return obs, {**info, "num_agvs": k}

    def step(self, action: np.ndarray) -> tuple[Observation, float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, reward, terminated, truncated, {**info, "num_agvs": self.env.num_agvs}

    def close(self) -> None:
        for env in self.envs.values():
            env.close()
