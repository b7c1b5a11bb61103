"""What every environment runs: the one env-step template over the one simulation core.

:class:`Engine` holds B scenarios (:class:`~lawn_env.core.Simulation`), the observation layout, the
interface and the role (a strategy: :class:`JointRole`, the actions decide everything;
:class:`CommRole`, the outage-aware MPC decides the increments). :meth:`Engine.step` is the step's
stages in order for every environment: decode the actions and let the role decide the rest
(:meth:`Engine.decide`), advance the core with the slot's draws (the scenarios of a mask), then the
rewards, termination and truncation (:meth:`Engine.outcome`); the info (:meth:`Engine.info`) and
the observations (:meth:`Engine.observe`) are read after it. ``lawn/Joint-v1`` and ``lawn/Comm-v1``
(:class:`LawnEnv`) and the PettingZoo env are B = 1 engines behind their APIs, the native vector
envs B = N ones.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any, NamedTuple

import gymnasium as gym
import numpy as np

from ..config import ScenarioConfig
from ..core import (
    Decisions,
    Simulation,
    SlotDraws,
    SlotRecord,
    Snapshot,
    Trail,
    buffer_queue,
    later_increments,
    link_success,
)
from ..dynamics import POSITION
from ..entities import EntityLayout
from ..interface import InterfaceLike, RLInterface, action_codec, resolve_interface
from ..mpc import DEFAULT_BACKEND, OutageAwareMPC
from ..presets import ConfigLike, resolve_config
from ..spaces import ObservationLayout, check_action
from ..tail import DeliveryLaw

__all__ = ["Engine", "EngineAccess", "JointRole", "CommRole", "ROLE_TYPES", "LawnEnv", "SlotResult", "INFO_KEYS",
           "COMM_INFO_KEYS"]


#: The info keys every step and reset of the central environments (and the parallel env's "drone")
#: carry, with fixed shapes and numpy dtypes; ``lawn/Comm-v1`` adds its MPC's keys
#: (``COMM_INFO_KEYS``); the step that ends an episode adds ``episode_metrics`` (a dict of MODEL.md §6).
INFO_KEYS = ("slot", "stage_cost", "reward_tracking", "reward_effort", "delivered",
             "outage_probability", "power_w", "drone_position", "applied_increment")
COMM_INFO_KEYS = ("mpc_iterations", "mpc_fallbacks", "success_probability_planned")


class JointRole:
    """``lawn/Joint-v1``'s role: the actions decide the increments, the powers and the drone."""

    name = "joint"

    def reset(self, which: np.ndarray | None = None) -> None:
        """New episodes for the scenarios ``which`` (all when None)."""

    def decide(self, sim: Simulation, decision: Decisions, windows: np.ndarray | None
               ) -> tuple[Decisions, dict[str, Any]]:
        """The slot's decisions for the decoded actions (they are), and the role's info keys."""
        return decision, {}

    def reset_info(self, sim: Simulation) -> dict[str, Any]:
        return {}


class CommRole:
    """``lawn/Comm-v1``'s role: the actions decide the powers and the drone; every AGV's increment
    is the first one of the outage-aware MPC (QP P3) at its link's planned success probability,
    solved for all B x K links at once (the compiled exact solver, warm-started per scenario).

    The MPC plans from the state a planner on the drone has, the measured one (``x_obs``: the
    snapshot's, every expert's; the true state without measurement noise), as does the RL
    interface's anchor, which shares this MPC (one per env). Under the buffered actuator the packets
    carry the rest of each AGV's planned sequence (MODEL.md §3)."""

    name = "comm"

    def __init__(self, mpc: OutageAwareMPC, law: str = "paper", planning_state: str = "measured",
                 delivery: DeliveryLaw | None = None):
        self.mpc = mpc
        # control.law: the QP at the planned psi ("paper"), at psi = 1 ("delivery-certainty-equivalent"), or
        # the loss-aware tail's command (``delivery``, the law of "delivery")
        self.law = law
        if law == "delivery" and delivery is None:
            raise ValueError("control.law='delivery': pass delivery=, the AGVs' DeliveryLaw")
        self.delivery = delivery
        self.planning_state = planning_state  # "true": lawn/Comm-v0's MPC, which plans from the true state
        self.last_solve_time_s = float("nan")

    def reset(self, which: np.ndarray | None = None) -> None:
        self.mpc.reset(which)  # a new episode starts without the old one's warm starts
        if self.delivery is not None:
            self.delivery.reset(which)

    def decide(self, sim: Simulation, decision: Decisions, windows: np.ndarray | None
               ) -> tuple[Decisions, dict[str, Any]]:
        assert windows is not None  # the engine passes them to a role that plans
        x = sim.x_obs if self.planning_state == "measured" else sim.x_aug
        psi = link_success(x, decision.drone_next, decision.power_w, sim.params.planning_link)
        if self.delivery is not None:  # control.law="delivery": the loss-aware tail's command
            queue = buffer_queue(sim.buffer, sim.buffer_age) if sim.params.buffer_length else None
            solution = self.delivery.solve(x, windows, psi, sim.slot, queue)
        else:  # the QP at the planned psi, or as if delivered
            solution = self.mpc.solve(x, windows, psi if self.law == "paper" else np.ones_like(psi), sim.slot)
        self.last_solve_time_s = solution.solve_time_s  # not in info: infos must be deterministic
        extra = {"mpc_iterations": solution.iterations.astype(np.int64),
                 "mpc_fallbacks": np.count_nonzero(solution.status, axis=-1).astype(np.int64),
                 "success_probability_planned": np.asarray(psi, dtype=np.float64)}
        length = sim.params.buffer_length  # the buffered actuator's plan: the sequence after the command
        plan = later_increments(solution.increments, length) if length else None
        return Decisions(solution.increments[..., 0, :], decision.power_w, decision.drone_next, plan), extra

    def reset_info(self, sim: Simulation) -> dict[str, Any]:
        b, k = sim.num_envs, sim.num_agvs
        return {"mpc_iterations": np.zeros((b, k), dtype=np.int64), "mpc_fallbacks": np.zeros(b, dtype=np.int64),
                "success_probability_planned": link_success(
                    sim.x_obs if self.planning_state == "measured" else sim.x_aug, sim.drone_position,
                    sim.last_power_w, sim.params.planning_link)}


#: The roles by name: what the actions decide (:data:`lawn_env.spaces.ROLES`).
ROLE_TYPES = {"joint": JointRole, "comm": CommRole}


#: The state the Comm role's MPC plans from: "measured" (what every planner has: the true state
#: without measurement noise) or "true" (``lawn/Comm-v1``'s, kept for its episodes).
PLANNING_STATES = ("measured", "true")


class SlotResult(NamedTuple):
    """What :meth:`Engine.step` returns for B scenarios: the core's record, the role's info keys,
    the rewards (B, M), and which scenarios terminate and are truncated (B,)."""

    record: SlotRecord
    extra: dict[str, Any]
    reward: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray


class Engine:
    """B scenarios of one config, one role and one interface (module docstring). ``trail_row``:
    the scenario whose positions are kept slot by slot (:class:`~lawn_env.core.Trail`: what
    :meth:`render` draws and :meth:`trajectories` returns); None keeps none."""

    def __init__(self, config: ScenarioConfig, role: str, interface: InterfaceLike = None, num_envs: int = 1,
                 qp_backend: str = DEFAULT_BACKEND, trail_row: int | None = 0, planning_state: str = "measured"):
        if role not in ROLE_TYPES:
            raise ValueError(f"role={role!r}; valid: {', '.join(ROLE_TYPES)}")
        self.config = config
        self.interface: RLInterface = resolve_interface(interface)
        self.sim = Simulation(config, num_envs)
        self.num_envs = self.sim.num_envs
        self.layout = ObservationLayout(config)
        self.actions = action_codec(config, role, self.interface, mpc_backend=qp_backend)
        if planning_state not in PLANNING_STATES:
            raise ValueError(f"planning_state={planning_state!r}; valid: {', '.join(PLANNING_STATES)}")
        self.role: JointRole | CommRole = JointRole()
        if role == "comm":  # one MPC per env: the anchor's when it has one
            mpc = self.actions.mpc or OutageAwareMPC.from_config(config, backend=qp_backend)
            law = config.control.law
            self.role = CommRole(mpc, law, planning_state,
                                 DeliveryLaw(config, backend=qp_backend) if law == "delivery" else None)
        self.needs_windows = role == "comm" or self.actions.needs_reference
        self.slot_table = self.layout.slot_table(self.sim.params.fixed_reference)
        self._no_termination = np.zeros(self.num_envs, dtype=bool)
        #: The entity layout of the interface's ``layout="entities"`` (:mod:`lawn_env.entities`); None: flat.
        self.entities = (EntityLayout(config, role, self.interface.obs_bound, self.interface.action_scheme)
                         if self.interface.layout == "entities" else None)
        self.trail: Trail | None = None
        if trail_row is not None:
            self.keep_trail(trail_row)
        self._renderer: Any = None

    def keep_trail(self, row: int) -> None:
        """Keep scenario ``row``'s positions slot by slot from its next reset (:attr:`trail`)."""
        self.trail = Trail(self.sim.row(row))

    @property
    def kept_trail(self) -> Trail:
        """The trail (:meth:`keep_trail`); an engine without one raises ``RuntimeError``."""
        if self.trail is None:
            raise RuntimeError("this engine keeps no trail: render_mode=None (or trail_row=None)")
        return self.trail

    @property
    def observation_space(self) -> gym.spaces.Space[Any]:
        """One scenario's observation space in the interface's layout."""
        if self.entities is None:
            return self.interface.observation_space(self.layout.size)
        return self.entities.observation_space

    @property
    def action_space(self) -> gym.spaces.Box:
        """One scenario's action space in the interface's layout."""
        return self.actions.space if self.entities is None else self.entities.action_space

    def reset(self, rngs: Sequence[np.random.Generator], which: np.ndarray | None = None) -> None:
        """New episodes for the scenarios ``which`` (all when None), scenario i from ``rngs[i]``."""
        self.sim.reset(rngs, which)
        self.actions.reset(which)
        self.role.reset(which)
        if self.trail is not None and (which is None or which[self.trail.view.i]):
            self.trail.restart()

    def check(self, actions: Any, name: str = "action", batch: bool = True) -> np.ndarray:
        """Actions in the interface's layout checked (:func:`~lawn_env.spaces.check_action`): the
        batch's (B, size), or with ``batch=False`` one scenario's (size,); returned as the flat
        actions the codec decodes, float64 (B, flat size) or (flat size,)."""
        a = check_action(actions, self.action_space.shape[0], name, self.num_envs if batch else None)
        return a if self.entities is None else self.entities.to_flat_actions(a)

    def decide(self, actions: np.ndarray) -> tuple[Decisions, dict[str, Any]]:
        """The slot's decisions of every scenario for checked actions (B, size), and the role's info."""
        sim = self.sim
        windows = sim.reference_windows() if self.needs_windows else None
        decision = self.actions.decode(actions, sim.x_obs, windows, sim.drone_position, sim.slot)
        return self.role.decide(sim, decision, windows)

    def step(self, actions: np.ndarray, draws: SlotDraws, active: np.ndarray | None = None,
             per_agent: bool = False) -> SlotResult:
        """The step's stages for checked actions (B, size) and the slot's draws: the decisions
        (:meth:`decide`), one slot of the core for the scenarios ``active`` (a (B,) mask; all when
        None: the others, restarted this step, keep their first slot, their rewards and flags zero
        and their warm starts cold), the trail, then the rewards, termination and truncation
        (:meth:`outcome`) of the stage costs (B, 1), or with ``per_agent`` of the stage cost and
        each AGV's (B, 1 + K), as the multi-agent env rewards its agents."""
        decisions, extra = self.decide(actions)
        record = self.sim.step(decisions, draws, active)
        if active is not None and not active.all():
            cold = ~active
            self.actions.reset(cold)
            self.role.reset(cold)
        if self.trail is not None and (active is None or active[self.trail.view.i]):
            self.trail.record()
        costs = record.stage_cost
        if per_agent:
            costs = np.concatenate([costs, record.tracking_cost + record.effort_cost], axis=1)
        reward, terminated, truncated = self.outcome(costs)
        if active is not None:
            reward[~active] = 0.0
            terminated, truncated = terminated & active, truncated & active
        return SlotResult(record, extra, reward, terminated, truncated)

    def outcome(self, costs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rewards for the slot's stage costs (B, M) (M = 1 for the central envs, 1 + K for the
        multi-agent one), which scenarios terminate (B,) (the RL interface's tracking-error bound)
        and which are truncated (B,) (``num_slots`` slots run, not terminated); the reward floor of
        the slots not played is added to every reward of a terminating scenario. The one place of
        reward, termination and truncation for every env."""
        iface, sim = self.interface, self.sim
        reward = iface.rewards_from_costs(costs)
        ended = sim.state.slot >= sim.num_slots
        if iface.termination_distance_m is None:
            return reward, self._no_termination, ended
        terminated = iface.terminates(sim.state.tracking_error[..., POSITION])
        if terminated.any():
            reward[terminated] += iface.terminal_penalties(sim.num_slots - sim.state.slot[terminated])[:, None]
        return reward, terminated, ended & ~terminated

    def info(self, record: SlotRecord | None = None, extra: dict[str, Any] | None = None,
             i: int | None = None) -> dict[str, Any]:
        """The info keys (``INFO_KEYS`` and the role's) of every scenario with a leading B axis, or
        of scenario ``i`` alone: ``slot`` int64, ``stage_cost`` and its split ``reward_tracking`` +
        ``reward_effort`` (negated) float64, ``delivered`` (K,) bool, ``outage_probability`` and
        ``power_w`` (K,), ``drone_position`` (2,), ``applied_increment`` (K, 2) float64 per scenario;
        zero costs and increments (and the role's reset values) without a record."""
        st = self.sim.state
        if record is None:
            costs = np.zeros((self.num_envs, 3))
            applied = np.zeros((self.num_envs, self.sim.num_agvs, 2))
            extra = self.role.reset_info(self.sim)
        else:
            costs, applied = record.costs, record.applied_increment
        at = slice(None) if i is None else i
        info = {
            "slot": st.slot.copy() if i is None else st.slot[i],
            "stage_cost": costs[at, 2],
            "reward_tracking": -costs[at, 0],
            "reward_effort": -costs[at, 1],
            "delivered": st.last_delivered[at],
            "outage_probability": st.last_outage_probability[at],
            "power_w": st.last_power_w[at],
            "drone_position": st.drone_position[at],
            "applied_increment": applied[at],
        }
        for key, value in (extra or {}).items():
            info[key] = value[at]
        return info

    def observe_flat(self) -> np.ndarray:
        """Every scenario's flat observation as the agent sees it (B, size) float32."""
        return self.layout.encode(self.sim, self.interface.obs_bound, self.slot_table)

    def observe(self) -> Observation:
        """Every scenario's observation in the interface's layout: (B, size) float32, or the entity
        layout's dict of (B, ...) arrays."""
        flat = self.observe_flat()
        return flat if self.entities is None else self.entities.observe(flat)


    # ------------------------------------------------------------------ one scenario's view
    def snapshot(self) -> Snapshot:
        """The trail's scenario's full state for external planners (:class:`lawn_env.core.Snapshot`)."""
        if not self.sim.started:
            raise RuntimeError("call reset() before snapshot()")
        return self.kept_trail.view.snapshot()

    def render(self, render_mode: str | None, human_ok: bool = True) -> np.ndarray | None:
        """An RGB frame (H, W, 3) of the trail's scenario: area, references, trails, links coloured
        by outage probability (``render_mode`` "rgb_array"; "human" shows it in a window)."""
        if render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array'"
                            + (" or 'human'" if human_ok else ""))
            return None
        if not self.sim.started:
            raise RuntimeError("call reset() before render()")
        if self._renderer is None:
            from ..render import Renderer

            self._renderer = Renderer(self.config, human=render_mode == "human")
        trail = self.kept_trail
        frame: np.ndarray | None = self._renderer.draw(trail.view, trail)
        return frame

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


#: The render modes of the single and multi-agent envs.
RENDER_MODES = ("human", "rgb_array")
#: An observation in the interface's layout: a flat array, or the entity layout's dict of arrays.
Observation = np.ndarray | dict[str, np.ndarray]


def check_render_mode(render_mode: str | None, valid: Sequence[str] = RENDER_MODES) -> None:
    if render_mode is not None and render_mode not in valid:
        raise ValueError(f"render_mode={render_mode!r}; valid: {list(valid)} or None")


class EngineAccess:
    """What every env over an :class:`Engine` (``self.engine``) exposes of it, single and vector
    alike: the MPC of ``lawn/Comm-v1``'s role, its last solve time, the entity layout."""

    engine: Engine

    @property
    def last_mpc_solve_time_s(self) -> float:
        """Wall-clock time of the last step's MPC solves (``lawn/Comm-v1``; NaN otherwise)."""
        return getattr(self.engine.role, "last_solve_time_s", float("nan"))

    @property
    def entities(self) -> EntityLayout | None:
        """The entity layout (``interface={"layout": "entities"}``); None for the flat one."""
        return self.engine.entities

    @property
    def mpc(self) -> OutageAwareMPC | None:
        """The MPC that drives the AGVs of every scenario (``lawn/Comm-v1``; None otherwise)."""
        return getattr(self.engine.role, "mpc", None)


#: The benchmark interface's observation bound (every v0 feature fits inside it).
_BENCHMARK_BOUND = resolve_interface(None).obs_bound


class LawnEnv(EngineAccess, gym.Env):
    """``lawn/Joint-v1`` and ``lawn/Comm-v1`` (their classes set ``role``): an engine of one
    scenario behind Gymnasium's API."""

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 4}
    role = "joint"
    planning_state = "measured"

    def __init__(self, config: ConfigLike = None, render_mode: str | None = None,
                 interface: InterfaceLike = None, qp_backend: str = DEFAULT_BACKEND, **overrides: Any):
        check_render_mode(render_mode)
        self.config = resolve_config(config, **overrides)
        self.render_mode = render_mode
        self.engine = Engine(self.config, self.role, interface, 1, qp_backend, planning_state=self.planning_state)
        self.sim = self.engine.kept_trail.view
        self.layout, self.interface, self.actions = self.engine.layout, self.engine.interface, self.engine.actions
        self.num_agvs = self.config.num_agvs
        self.observation_space, self.action_space = self.engine.observation_space, self.engine.action_space
        self._done = True

    @property
    def spec(self) -> gym.envs.registration.EnvSpec | None:
        """The ``EnvSpec`` ``gym.make`` gave this env, with ``max_episode_steps`` = ``num_slots``:
        the episode length, which the env enforces itself (truncation at ``num_slots``)."""
        return self.__dict__.get("_spec")

    @spec.setter
    def spec(self, value: gym.envs.registration.EnvSpec | None) -> None:
        if value is not None and value.max_episode_steps is None:
            value = dataclasses.replace(value, max_episode_steps=self.config.num_slots)
        self.__dict__["_spec"] = value

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[Observation, dict[str, Any]]:
        super().reset(seed=seed)
        # ``options`` is accepted for API compatibility (PettingZoo's test passes some); none is used.
        self.engine.reset([self.np_random])
        self._done = False
        if self.render_mode == "human":
            self.render()
        return self._observation(), self.engine.info(i=0)

    def step(self, action: np.ndarray) -> tuple[Observation, float, bool, bool, dict[str, Any]]:
        if self._done:
            raise RuntimeError("the episode has ended (or reset() was never called); call reset() before step()")
        engine = self.engine
        result = engine.step(engine.check(action, batch=False)[None], engine.sim.draw(self.np_random))
        obs = self._observation()
        terminated, truncated = bool(result.terminated[0]), bool(result.truncated[0])
        info = engine.info(result.record, result.extra, i=0)
        if truncated or terminated:
            self._done = True
            info["episode_metrics"] = self.sim.episode_metrics().as_dict()
        if self.render_mode == "human":
            self.render()
        return obs, float(result.reward[0, 0]), terminated, truncated, info

    def _observation(self) -> Observation:
        """This scenario's observation in the interface's layout."""
        obs = self.engine.observe()
        return {key: value[0] for key, value in obs.items()} if isinstance(obs, dict) else obs[0]

    def benchmark_observation(self) -> np.ndarray:
        """This scenario's observation as the benchmark interface gives it (the flat v0 layout,
        unclipped), whatever this env's interface: what the experts of ``agents`` act on."""
        if not self.engine.sim.started:
            raise RuntimeError("call reset() before benchmark_observation()")
        obs: np.ndarray = self.layout.encode(self.engine.sim, _BENCHMARK_BOUND, self.engine.slot_table)[0]
        return obs

    def snapshot(self) -> Snapshot:
        """Full system state for external planners (see :class:`lawn_env.core.Snapshot`)."""
        return self.engine.snapshot()

    def trajectories(self) -> dict[str, Any]:
        """The current episode's drone (n+1, 2), AGV (n+1, K, 2) and reference (n+1, K, 2) positions."""
        return self.engine.kept_trail.trajectories()

    def episode_metrics(self) -> dict[str, Any]:
        """MODEL.md §6's metrics of the episode so far, as the last step's ``info["episode_metrics"]``."""
        return self.sim.episode_metrics().as_dict()

    def render(self) -> np.ndarray | None:
        return self.engine.render(self.render_mode)

    def close(self) -> None:
        self.engine.close()
