"""The entity layout: observations and actions per AGV, padded to :data:`MAX_AGVS` rows.

``gym.make(id, interface={"layout": "entities"})`` (any central id, single or native vector; the RL
ids with ``interface={"base": "rl", "layout": "entities"}``) gives every AGV a row
of the same features as the flat layout's AGV block (:class:`~lawn_env.spaces.ObservationLayout`:
its state, tracking error, reference window, position relative to the drone, last outage,
delivery and power), the drone and the scenario a row of globals, and a mask of the rows present,
so that one set or graph network reads any fleet size K <= MAX_AGVS:

* observation: ``Dict(agvs=Box((MAX_AGVS, F)), globals=Box((4,)), mask=Box((MAX_AGVS,)))``,
  float32, F = ``agv_features``; the globals are the drone's position, slot n / N and
  K / MAX_AGVS; padded rows are zero and their mask 0;
* action: ``Box(-1, 1, (MAX_AGVS * c + 2,))``: per AGV row i its ``c`` entries (``joint``:
  increment x, y and power weight, then, with the direct actions of the buffered actuator, the
  2 (N_p - 1) entries of its plan; ``comm``: power weight), then the drone's two. Padded rows are
  ignored; the entries of the present AGVs and the drone are the flat action's, decoded by the
  same action codec (the power split over the AGVs present).

The features and the decode are the flat layout's, rearranged: nothing is computed twice.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import gymnasium as gym
import numpy as np

from .spaces import ROLES, ObservationLayout

if TYPE_CHECKING:
    from .config import ScenarioConfig

__all__ = ["MAX_AGVS", "GLOBALS", "EntityLayout"]

#: The rows of the entity layout: the largest fleet it holds.
MAX_AGVS = 64
#: The globals' names: the flat layout's, then K / MAX_AGVS.
GLOBALS = (*ObservationLayout.GLOBAL_FEATURES, "fleet_frac")


class EntityLayout:
    """The entity observation and action of one role for a config (module docstring); ``bound``
    is the observation's bound and ``scheme`` the action scheme (the interface's): Joint's direct
    actions under the buffered actuator end with the AGVs' plans
    (:attr:`lawn_env.spaces.DirectActions.plan_size`), which each AGV's row then carries."""

    def __init__(self, config: ScenarioConfig, role: str, bound: float, scheme: str = "direct"):
        if role not in ROLES:
            raise ValueError(f"role={role!r}; valid: {', '.join(ROLES)}")
        k = config.num_agvs
        if k > MAX_AGVS:
            raise ValueError(f"num_agvs={k}: the entity layout holds at most MAX_AGVS={MAX_AGVS} AGVs; "
                             "use the interface's layout='flat' for larger fleets")
        self.num_agvs, self.role = k, role
        self.flat = ObservationLayout(config)
        self.agv_features = self.flat.agv_features

        def box(shape: tuple[int, ...], lo: float = -bound, hi: float = bound) -> gym.spaces.Box:
            return gym.spaces.Box(lo, hi, shape=shape, dtype=np.float32)

        self.observation_space = gym.spaces.Dict({
            "agvs": box((MAX_AGVS, self.agv_features)), "globals": box((len(GLOBALS),)),
            "mask": box((MAX_AGVS,), 0.0, 1.0)})
        plan = 2 * config.control.buffer_length if scheme == "direct" and role == "joint" else 0
        c = self.per_agv = 3 + plan if role == "joint" else 1
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(MAX_AGVS * self.per_agv + 2,), dtype=np.float32)
        rows = np.arange(k)
        drone = MAX_AGVS * self.per_agv + np.arange(2)
        if role == "joint":  # flat: increments (2K), powers (K), drone (2), plans (2K(N_p - 1) or none)
            increments = np.stack([c * rows, c * rows + 1], axis=1).reshape(-1)
            plans_at = (c * rows[:, None] + 3 + np.arange(plan)[None, :]).reshape(-1)
            self.gather = np.concatenate([increments, c * rows + 2, drone, plans_at])
        else:  # flat: powers (K), drone (2)
            self.gather = np.concatenate([rows, drone])
        self.fleet_frac = np.float32(k / MAX_AGVS)
        self._mask = (np.arange(MAX_AGVS) < k).astype(np.float32)[None]

    def observe(self, flat: np.ndarray) -> dict[str, np.ndarray]:
        """The entity observations of flat ones (B, size) float32: ``agvs`` (B, MAX_AGVS, F),
        ``globals`` (B, 4), ``mask`` (B, MAX_AGVS), new arrays."""
        num, k, f = flat.shape[0], self.num_agvs, self.agv_features
        agvs = np.zeros((num, MAX_AGVS, f), dtype=np.float32)
        agvs[:, :k] = flat[:, : k * f].reshape(num, k, f)
        glob = np.empty((num, len(GLOBALS)), dtype=np.float32)
        glob[:, :-1] = flat[:, k * f :]
        glob[:, -1] = self.fleet_frac
        return {"agvs": agvs, "globals": glob, "mask": np.repeat(self._mask, num, axis=0)}

    def to_flat_actions(self, actions: np.ndarray) -> np.ndarray:
        """The flat actions (..., flat size) of checked entity actions (..., MAX_AGVS c + 2): the
        entries of the AGVs present and the drone's."""
        return np.ascontiguousarray(np.asarray(actions)[..., self.gather])

    def to_entity_actions(self, flat: np.ndarray) -> np.ndarray:
        """The entity actions (..., MAX_AGVS c + 2) float32 of flat ones, padded rows zero."""
        flat = np.asarray(flat)
        out = np.zeros(flat.shape[:-1] + self.action_space.shape, dtype=np.float32)
        out[..., self.gather] = flat
        return out
