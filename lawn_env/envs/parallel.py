"""The multi-agent view: a PettingZoo ``ParallelEnv`` over the same simulation core."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeVar

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from pettingzoo import AECEnv, ParallelEnv
from pettingzoo.utils.conversions import parallel_to_aec

from ..core import Snapshot
from ..entities import MAX_AGVS
from ..interface import InterfaceLike
from ..mpc import DEFAULT_BACKEND
from ..presets import ConfigLike, resolve_config
from ..spaces import check_action
from .base import RENDER_MODES, Engine, EngineAccess, check_render_mode

__all__ = ["LawnParallelEnv", "parallel_env", "raw_env", "env"]

_T = TypeVar("_T")


class LawnParallelEnv(EngineAccess, ParallelEnv):  # type: ignore[misc]  # pettingzoo ships no type information
    """
    ## Description

    The system of ``lawn/Joint-v1`` with one agent per decision maker: ``"drone"`` chooses the
    power split and its move, ``"agv_0"`` ... ``"agv_{K-1}"`` each choose their own acceleration
    increment. All act simultaneously each slot; the AGVs' commands then cross the links as in
    the central environments.

    ## Action Spaces

    * ``"drone"``: ``Box(-1, 1, (K + 2,))``: K power weights, then the velocity (scalings of
      ``lawn/Comm-v1``).
    * ``"agv_k"``: ``Box(-1, 1, (2,))``: the increment, ``a * Delta-a_max`` m/s^2, saturated to
      the acceleration bound. Under ``control.actuator="buffer"`` (direct actions) ``(2 N_p,)``: the
      increment, then the rest of its planned sequence, which its packet carries (MODEL.md §3).
    * With ``interface={"layout": "entities", ...}``: ``"drone"`` ``Box(-1, 1, (2,))``, its move;
      ``"agv_k"`` ``Box(-1, 1, (3,))``, its row of the entity action (the increment, then its
      power weight: the power split is normalised over the AGVs; under the buffered actuator its
      plan after them, ``(3 + 2 (N_p - 1),)``), so that the spaces do not depend on K
      (:mod:`lawn_env.entities`).

    ## Observation Spaces

    * ``"drone"``: the central observation of ``lawn/Joint-v1``.
    * ``"agv_k"``: AGV k's block of that observation followed by the 3 global features (drone
      position, time): ``agv_features + 3`` floats.
    * With the entity layout, every agent: the central entity observation (``agvs``, ``globals``,
      ``mask``) and ``me``, a one-hot of which entity it is (index 0 the drone, 1 + k AGV k), in
      one ``Dict`` space for all agents; ``state()`` stays the flat central observation.

    ## Rewards

    ``"agv_k"``: minus its own realized stage cost; ``"drone"``: minus the total (the central
    environments' reward). ``infos[agent]["reward_tracking"]`` and ``["reward_effort"]`` split each. With
    ``interface="rl"`` each reward is bounded and scaled (``-min(cost, 100) / 10``), the AGVs'
    actions are residuals on the outage-aware MPC and the drone's are anchored as in
    ``lawn/Comm-v1`` (:mod:`lawn_env.interface`).

    ## Episode End

    Truncation for every agent after ``num_slots`` slots; ``agents`` is then empty. With
    ``interface="rl"``, every agent terminates when an AGV is more than 25 m off its track, each
    with the reward floor of the remaining slots added.

    ## Arguments

    ``lawn_env.parallel_env(config=None, render_mode=None, interface=None, max_cycles=None,
    **overrides)`` as for ``gym.make``; ``max_cycles`` is PettingZoo's name for ``num_slots``. The
    AEC form: ``lawn_env.env(...)`` / ``lawn_env.raw_env(...)``. ``state()`` is the central
    observation, in ``state_space``. Infos have the same keys, shapes and dtypes at reset and at
    every step (``lawn_env.envs.base.INFO_KEYS``, flat, as TorchRL's PettingZoo wrapper needs);
    ``episode_metrics()`` gives MODEL.md §6's metrics of the episode so far.

    ## Version History

    * v0: initial version; the ``interface`` keyword (opt-in) added later. Later changes that leave
      its episodes as they were: infos share one flat schema at reset and every step
      (``reward_tracking`` and ``reward_effort`` replace the nested ``reward_terms``), as TorchRL's
      PettingZoo wrapper needs; the one simulation core of the central environments (under the same
      decisions the drone's observations, rewards and infos equal ``lawn/Joint-v1``'s bit for bit);
      ``render()`` frames as ``lawn/Joint-v1``'s history says; the opt-in entity layout
      (``interface={"layout": "entities"}``: spaces that do not depend on K, the power split decided
      by the AGVs' own power weights); the opt-in buffered actuator (``control.actuator="buffer"``: the
      AGVs' actions carry their plans).
    """

    metadata = {"name": "lawn_v0", "render_modes": list(RENDER_MODES), "render_fps": 4, "is_parallelizable": True}

    def __init__(self, config: ConfigLike = None, render_mode: str | None = None,
                 interface: InterfaceLike = None, max_cycles: int | None = None,
                 **overrides: Any):
        if max_cycles is not None:  # PettingZoo's name for the episode length
            if "num_slots" in overrides and overrides["num_slots"] != max_cycles:
                raise ValueError(f"max_cycles={max_cycles!r} and num_slots={overrides['num_slots']!r} disagree; "
                                 "give one of them (max_cycles is PettingZoo's name for num_slots)")
            overrides = {**overrides, "num_slots": max_cycles}
        check_render_mode(render_mode)
        self.config = resolve_config(config, **overrides)
        self.render_mode = render_mode
        self.engine = Engine(self.config, "joint", interface, 1, DEFAULT_BACKEND)
        self.sim = self.engine.kept_trail.view
        self.layout, self.interface, self.actions = self.engine.layout, self.engine.interface, self.engine.actions
        self.max_cycles = self.config.num_slots
        k = self.config.num_agvs
        self.possible_agents = ["drone"] + [f"agv_{i}" for i in range(k)]
        self.agents: list[str] = []
        self._agv_index = {f"agv_{i}": i for i in range(k)}
        self._plan = self.actions.plan_size // k  # an AGV's plan entries under the buffered actuator (else 0)
        if self.entities is None:
            self._flat_spaces(k)
        else:
            self._entity_spaces(k)
        self.state_space = self.interface.observation_space(self.layout.size)
        self._np_random, _ = seeding.np_random()
        self._agv_terms = (np.zeros(k), np.zeros(k))

    def _flat_spaces(self, k: int) -> None:
        agv_size = self.layout.agv_features + self.layout.global_features
        self._observation_spaces: dict[str, gym.spaces.Space[Any]] = {
            "drone": self.interface.observation_space(self.layout.size),
            **{a: self.interface.observation_space(agv_size) for a in self._agv_index},
        }
        self._action_spaces = {
            "drone": gym.spaces.Box(-1.0, 1.0, shape=(k + 2,), dtype=np.float32),
            **{a: gym.spaces.Box(-1.0, 1.0, shape=(2 + self._plan,), dtype=np.float32) for a in self._agv_index},
        }

    def _entity_spaces(self, k: int) -> None:
        """Every agent sees the entity observation and which entity it is (``me``: one-hot, the
        drone first, then the AGVs' rows); an AGV acts with its entity row, the drone with its move."""
        entities = self.entities
        assert entities is not None  # the entity layout's spaces
        space = gym.spaces.Dict({**entities.observation_space.spaces,
                                 "me": gym.spaces.Box(0.0, 1.0, shape=(MAX_AGVS + 1,), dtype=np.float32)})
        self._observation_spaces = dict.fromkeys(self.possible_agents, space)
        self._me = {a: np.eye(MAX_AGVS + 1, dtype=np.float32)[j] for j, a in enumerate(self.possible_agents)}
        for me in self._me.values():
            me.flags.writeable = False
        self._action_spaces = {
            "drone": gym.spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32),
            **{a: gym.spaces.Box(-1.0, 1.0, shape=(entities.per_agv,), dtype=np.float32) for a in self._agv_index},
        }

    def observation_space(self, agent: str) -> gym.spaces.Space[Any]:
        return self._lookup(self._observation_spaces, agent)

    def action_space(self, agent: str) -> gym.spaces.Box:
        return self._lookup(self._action_spaces, agent)

    def _lookup(self, table: dict[str, _T], agent: str) -> _T:
        try:
            return table[agent]
        except KeyError:
            raise ValueError(f"unknown agent {agent!r}; agents: {', '.join(self.possible_agents)}") from None

    # ------------------------------------------------------------------ API
    def reset(self, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[dict[str, np.ndarray], dict[str, dict[str, Any]]]:
        if seed is not None:
            self._np_random, _ = seeding.np_random(seed)
        # ``options`` is accepted for API compatibility (PettingZoo's test passes some); none is used.
        self.engine.reset([self._np_random])
        self._agv_terms = (np.zeros(self.config.num_agvs), np.zeros(self.config.num_agvs))
        self.agents = list(self.possible_agents)
        observations = self._observations()
        if self.render_mode == "human":
            self.render()
        return observations, self._infos(self.engine.info(i=0))

    @property
    def np_random(self) -> np.random.Generator:
        """The env's generator (seeded by ``reset(seed=...)``): every draw of an episode."""
        return self._np_random

    def _infos(self, info: dict[str, Any]) -> dict[str, Any]:
        """Per-agent infos with the same keys, shapes and dtypes at reset and at every step: the
        drone's are the central environments' (``INFO_KEYS``); each AGV's the same keys for its own
        link, as scalars (``applied_increment`` (2,)) and its own stage cost."""
        central = info
        infos = {"drone": central}
        terms = self._agv_terms
        for agent, i in self._agv_index.items():
            infos[agent] = {
                "slot": central["slot"],
                "stage_cost": np.float64(terms[0][i] + terms[1][i]),
                "reward_tracking": np.float64(-terms[0][i]),
                "reward_effort": np.float64(-terms[1][i]),
                "delivered": np.asarray(central["delivered"][i], dtype=bool),
                "outage_probability": np.asarray(central["outage_probability"][i], dtype=np.float64),
                "power_w": np.asarray(central["power_w"][i], dtype=np.float64),
                "drone_position": central["drone_position"],
                "applied_increment": central["applied_increment"][i],
            }
        return infos

    def step(self, actions: dict[str, np.ndarray]
             ) -> tuple[dict[str, Any], dict[str, Any], dict[str, Any], dict[str, Any], dict[str, Any]]:
        if not self.agents:
            raise RuntimeError("the episode has ended (or reset() was never called); call reset() before step()")
        if not isinstance(actions, Mapping):
            raise TypeError(f"actions must be a dict from agent name to action (agents: {self.agents}); "
                            f"got {type(actions).__name__}")
        missing = [a for a in self.agents if a not in actions]
        unknown = [a for a in actions if a not in self._action_spaces]
        if missing or unknown:
            raise ValueError(f"actions: missing agents {missing}, unknown agents {unknown}; expected {self.agents}")
        engine = self.engine
        result = engine.step(self._central_action(actions)[None], engine.sim.draw(self._np_random), per_agent=True)
        record, agent_rewards = result.record, result.reward
        terminated, truncated = bool(result.terminated[0]), bool(result.truncated[0])
        rewards = {"drone": float(agent_rewards[0, 0])}
        for agent, i in self._agv_index.items():
            rewards[agent] = float(agent_rewards[0, i + 1])
        self._agv_terms = (record.tracking_cost[0], record.effort_cost[0])
        infos = self._infos(engine.info(record, result.extra, i=0))
        observations = self._observations()
        terminations = dict.fromkeys(self.agents, terminated)
        truncations = dict.fromkeys(self.agents, truncated)
        if truncated or terminated:
            self.agents = []
        if self.render_mode == "human":
            self.render()
        return observations, rewards, terminations, truncations, infos

    def _central_action(self, actions: Mapping[str, np.ndarray]) -> np.ndarray:
        """The central action of the agents' (checked): flat, increments then the drone's part."""
        k = self.config.num_agvs
        if self.entities is not None:
            entity = np.zeros(self.entities.action_space.shape)
            c = self.entities.per_agv
            entity[-2:] = check_action(actions["drone"], 2, name="actions['drone']")
            for agent, i in self._agv_index.items():
                entity[c * i : c * i + c] = check_action(actions[agent], c, name=f"actions[{agent!r}]")
            return self.entities.to_flat_actions(entity)
        joint, plan = np.empty(self.actions.size), self._plan
        joint[2 * k : 3 * k + 2] = check_action(actions["drone"], k + 2, name="actions['drone']")
        for agent, i in self._agv_index.items():
            own = check_action(actions[agent], 2 + plan, name=f"actions[{agent!r}]")
            joint[2 * i : 2 * i + 2] = own[:2]
            joint[3 * k + 2 + plan * i : 3 * k + 2 + plan * (i + 1)] = own[2:]
        return joint

    def _observations(self) -> dict[str, Any]:
        if self.entities is not None:  # fresh arrays every step, shared read-only by the agents (not K + 1 copies)
            entity_obs = self.engine.observe()
            assert isinstance(entity_obs, dict)  # the entity layout's observation
            shared = {key: value[0] for key, value in entity_obs.items()}
            for value in shared.values():
                value.flags.writeable = False
            return {a: {**shared, "me": self._me[a]} for a in self.possible_agents}
        central = self.engine.observe_flat()[0]
        blocks = self.layout.agv_blocks(central)
        glob = central[-self.layout.global_features :]
        obs = {"drone": central}
        for agent, i in self._agv_index.items():
            obs[agent] = np.concatenate([blocks[i], glob])
        return obs

    # ------------------------------------------------------------------ extras
    def state(self) -> np.ndarray:
        """Global state: the central observation (an element of ``state_space``)."""
        if not self.engine.sim.started:
            raise RuntimeError("call reset() before state()")
        state: np.ndarray = self.engine.observe_flat()[0]
        return state

    def episode_metrics(self) -> dict[str, Any]:
        """MODEL.md §6's metrics of the episode so far (the central envs put them in the last info)."""
        return self.sim.episode_metrics().as_dict()

    def snapshot(self) -> Snapshot:
        """Full system state for external planners (see :class:`lawn_env.core.Snapshot`)."""
        return self.engine.snapshot()

    def trajectories(self) -> dict[str, Any]:
        """The current episode's drone (n+1, 2), AGV (n+1, K, 2) and reference (n+1, K, 2) positions."""
        return self.engine.kept_trail.trajectories()

    def render(self, *args: Any, **kwargs: Any) -> np.ndarray | None:
        """As the central environments' ``render()``; extra arguments (RLlib's
        ``ParallelPettingZooEnv.render()`` passes a mode) are ignored: ``render_mode`` decides."""
        return self.engine.render(self.render_mode)

    def close(self) -> None:
        self.engine.close()


def parallel_env(config: ConfigLike = None, render_mode: str | None = None,
                 interface: InterfaceLike = None, max_cycles: int | None = None,
                 **overrides: Any) -> LawnParallelEnv:
    """Create the PettingZoo parallel environment (see :class:`LawnParallelEnv`); ``max_cycles``
    is PettingZoo's name for ``num_slots``."""
    return LawnParallelEnv(config, render_mode=render_mode, interface=interface, max_cycles=max_cycles, **overrides)


def raw_env(config: ConfigLike = None, render_mode: str | None = None,
            interface: InterfaceLike = None, max_cycles: int | None = None,
            **overrides: Any) -> AECEnv:
    """The same environment through PettingZoo's AEC API (agents act in turn, ``"drone"`` first;
    the slot advances once every agent has acted): ``parallel_to_aec`` of :func:`parallel_env`."""
    return parallel_to_aec(parallel_env(config, render_mode, interface, max_cycles, **overrides))


def env(config: ConfigLike = None, render_mode: str | None = None,
        interface: InterfaceLike = None, max_cycles: int | None = None,
        **overrides: Any) -> AECEnv:
    """PettingZoo's conventional AEC constructor: :func:`raw_env` (already order-enforcing; actions
    out of their box raise ``ValueError``, so no clipping wrapper is added)."""
    return raw_env(config, render_mode, interface, max_cycles, **overrides)
