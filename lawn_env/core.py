"""The one simulation core every environment runs: B scenarios of one config at once.

Its parts, each in its module and re-exported here for the packages that use them:

* :mod:`lawn_env.state`: :class:`SimParams` (what the config fixes), :class:`SimState` (the episode
  state of B scenarios as plain arrays with a leading batch axis), :class:`Decisions`,
  :class:`SlotDraws` and :class:`SlotRecord` (what a slot takes and produces), :func:`draw_slot` (a
  slot's randomness, in one documented order), :func:`reset` (new episodes for chosen rows) and the
  buffered actuator's :func:`later_increments` and :func:`buffer_queue`;
* :mod:`lawn_env.slot`: :func:`step` (one slot of every scenario over one compiled kernel:
  ``step(params, state, decisions, draws)`` returns the new state and the slot's record, its arguments
  untouched) and :func:`step_rows`;
* :mod:`lawn_env.metrics`: the episode's running sums by name and the metrics of MODEL.md §6.

This module holds the environments' object over them: :class:`Simulation`, the params and the state
of B scenarios together (the single environments and the PettingZoo env are its B = 1 views, the
native vector envs its B = N views), :meth:`Simulation.row` (:class:`ScenarioView`: one scenario's
state as single-scenario arrays), the planners' :class:`Snapshot` and the renderer's :class:`Trail`.
It knows nothing about action or observation encodings; the environments do
(:mod:`lawn_env.spaces`, :mod:`lawn_env.interface`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import drone, metrics
from .config import ScenarioConfig
from .dynamics import POSITION
from .metrics import DIVERGENCE_DISTANCE_M, TOTALS, EpisodeMetrics, Totals
from .references import Curve
from .slot import step, step_rows
from .state import (
    SLOT_CONSTANTS,
    Decisions,
    SimParams,
    SimState,
    SlotDraws,
    SlotRecord,
    buffer_queue,
    draw_slot,
    empty_state,
    later_increments,
    link_outage,
    link_success,
    reset,
)

__all__ = ["SimParams", "SimState", "SlotDraws", "SlotRecord", "Decisions", "Snapshot", "Simulation", "ScenarioView",
           "Trail", "Totals", "draw_slot", "reset", "step", "step_rows", "episode_metrics", "control_costs",
           "link_outage", "buffer_queue", "later_increments", "link_success", "SLOT_CONSTANTS", "TOTALS",
           "DIVERGENCE_DISTANCE_M"]


def control_costs(state: SimState, rows: Any = slice(None)) -> np.ndarray:
    """The control cost so far of the scenarios ``rows`` (default: all, (B,)): the running sums of
    their tracking and effort costs."""
    return Totals(state.totals[rows]).control_cost


def episode_metrics(params: SimParams, state: SimState, rows: Sequence[int] | np.ndarray) -> list[EpisodeMetrics]:
    """Metrics of MODEL.md §6 over the slots each scenario of ``rows`` has run in its episode, one
    record per row (:func:`lawn_env.metrics.episode_metrics`; the decision time is the caller's)."""
    rows = np.asarray(rows, dtype=np.int64).reshape(-1)
    return metrics.episode_metrics(Totals(state.totals[rows]), state.slot[rows], params.command_period)


# ---------------------------------------------------------------------- the environments' object
@dataclass(frozen=True)
class Snapshot:
    """The full system state an external planner needs at the start of a slot.

    ``x_aug`` (K, 6): augmented AGV states [x, y, v_x, v_y, u_x[n-1], u_y[n-1]] (as measured);
    ``reference`` (K, N_p+1, 6): reference augmented states [x, y, v_x, v_y, a_x, a_y] at slots
    n..n+N_p; ``drone_position`` (2,): q[n-1], the position the drone moves from; ``slot``: n;
    ``config``: the scenario. Arrays are copies.
    """

    x_aug: np.ndarray
    reference: np.ndarray
    drone_position: np.ndarray
    slot: int
    config: ScenarioConfig
    last_power_w: np.ndarray | None = None  # the powers of slot n-1 (warm starts); None when unknown
    #: Under the buffered actuator, (K, N_p - 1, 2): the increments each AGV plays on its next slots
    #: without a packet, in order, zeros once its buffer is spent (:func:`buffer_queue`); None under hold.
    buffer: np.ndarray | None = None


class Simulation:
    """B scenarios of one config (``num_envs``, 1 for the single environments): the frozen
    :class:`SimParams` and the current :class:`SimState`, advanced by :func:`step` and restarted
    by :func:`reset`. The state's arrays read as attributes (``sim.x_aug`` (B, K, 6), ...)."""

    # the state's arrays, properties set after the class from STATE_ARRAYS (every scenario's)
    x_aug: np.ndarray
    tracking_error: np.ndarray
    x_obs: np.ndarray
    error_obs: np.ndarray
    applied: np.ndarray
    drone_position: np.ndarray
    last_power_w: np.ndarray
    last_delivered: np.ndarray
    last_outage_probability: np.ndarray
    reference: np.ndarray
    buffer: np.ndarray
    buffer_age: np.ndarray
    slot: np.ndarray
    paths: list[list[Curve] | None]

    def __init__(self, config: ScenarioConfig, num_envs: int = 1):
        if not isinstance(num_envs, (int, np.integer)) or isinstance(num_envs, bool) or num_envs < 1:
            raise ValueError(f"num_envs={num_envs!r}: must be an integer >= 1")
        self.params = SimParams.from_config(config)
        self.config = config
        self.num_envs = int(num_envs)
        self.num_agvs, self.num_slots, self.horizon = config.num_agvs, config.num_slots, config.control.horizon
        self.state = empty_state(self.params, self.num_envs)
        self.started = False
        self._window = np.arange(self.horizon + 1)

    def reset(self, rngs: Sequence[np.random.Generator], which: np.ndarray | None = None) -> None:
        """New episodes for the scenarios ``which`` (all when None), scenario i from ``rngs[i]``."""
        if not self.started and which is not None and not np.all(which):
            raise RuntimeError("the first reset must start every scenario")
        reset(self.params, self.state, rngs, which)
        self.started = True

    def draw(self, rng: np.random.Generator) -> SlotDraws:
        """This slot's randomness for every scenario (:func:`draw_slot`)."""
        return draw_slot(rng, self.params, self.num_envs)

    def step(self, decisions: Decisions, draws: SlotDraws, rows: np.ndarray | None = None) -> SlotRecord:
        """One slot of every scenario (:func:`step`), or of the scenarios ``rows`` (a mask) alone
        (:func:`step_rows`); the new state replaces the old."""
        if rows is None or rows.all():
            self.state, record = step(self.params, self.state, decisions, draws)
        else:
            self.state, record = step_rows(self.params, self.state, decisions, draws, rows)
        return record

    def reference_windows(self) -> np.ndarray:
        """Reference augmented states at slots n..n+N_p of every scenario: (B, K, N_p+1, 6)."""
        state = self.state
        if state.slot.size == 1:  # one scenario: a view
            n = int(state.slot[0])
            window: np.ndarray = state.reference[:, :, n : n + self.horizon + 1]
            return window
        idx = state.slot[:, None] + self._window[None, :]
        windows: np.ndarray = state.reference[np.arange(state.slot.size)[:, None], :, idx].transpose(0, 2, 1, 3)
        return windows

    def episode_metrics(self, rows: Sequence[int] | np.ndarray = (0,)) -> list[EpisodeMetrics]:
        """:func:`episode_metrics` of the scenarios ``rows`` (indices; a single env's is row 0),
        computed together."""
        return episode_metrics(self.params, self.state, rows)

    def row(self, i: int = 0) -> ScenarioView:
        return ScenarioView(self, i)


class ScenarioView:
    """Scenario ``i`` of a :class:`Simulation` as single-scenario arrays (views of row i): what
    the renderer, the planners' snapshots and the single environments' accessors read."""

    # the state's arrays, properties set after the class from STATE_ARRAYS (row i's)
    x_aug: np.ndarray
    tracking_error: np.ndarray
    x_obs: np.ndarray
    error_obs: np.ndarray
    applied: np.ndarray
    drone_position: np.ndarray
    last_power_w: np.ndarray
    last_delivered: np.ndarray
    last_outage_probability: np.ndarray
    reference: np.ndarray
    buffer: np.ndarray
    buffer_age: np.ndarray

    def __init__(self, sim: Simulation, i: int):
        self._sim, self.i = sim, int(i)
        p = sim.params
        self.config, self.area, self.num_agvs, self.num_slots, self.horizon = (
            p.config, p.area, p.num_agvs, p.num_slots, p.horizon)
        self.link, self.planning_link, self.model = p.link, p.planning_link, p.model

    @property
    def slot(self) -> int:
        return int(self._sim.state.slot[self.i])

    @property
    def paths(self) -> list[Curve] | None:
        return self._sim.state.paths[self.i]

    @property
    def control_cost(self) -> float:
        """The episode's control cost so far (:func:`control_costs` of this scenario)."""
        return float(control_costs(self._sim.state, self.i))

    @property
    def done(self) -> bool:
        """True once ``num_slots`` slots have run (the episode truncates)."""
        return self.slot >= self.num_slots

    def reference_window(self) -> np.ndarray:
        """Reference augmented states at slots n..n+N_p: (K, N_p+1, 6) (a view)."""
        n = self.slot
        return self._sim.state.reference[self.i, :, n : n + self.horizon + 1]

    def outage_probability(self, power_w: np.ndarray, drone_position: np.ndarray) -> np.ndarray:
        """Closed-form outage of the true link at the current AGV positions."""
        return link_outage(self.x_aug, np.asarray(drone_position, dtype=float), power_w, self.link)[1]

    def planning_success(self, power_w: np.ndarray, drone_position: np.ndarray) -> np.ndarray:
        """psi of the planners' link model (CSI-aware or not, see ChannelConfig) at the measured
        positions (what the planners, ``lawn/Comm-v1``'s MPC among them, plan from)."""
        return link_success(self.x_obs, np.asarray(drone_position, dtype=float), power_w, self.planning_link)

    def drone_target(self, velocity_mps: np.ndarray) -> np.ndarray:
        """Next drone position for a commanded velocity (speed-limited, kept in the area)."""
        p = self._sim.params
        return drone.move_drone(self.drone_position, velocity_mps, p.max_speed, p.slot_s, p.area)

    def snapshot(self) -> Snapshot:
        return Snapshot(
            x_aug=self.x_obs.copy(),  # measured state: what a planner would have
            reference=self.reference_window().copy(),
            drone_position=self.drone_position.copy(),
            slot=self.slot,
            config=self.config,
            last_power_w=self.last_power_w.copy(),
            buffer=buffer_queue(self.buffer, self.buffer_age) if self._sim.params.buffer_length else None,
        )

    def episode_metrics(self) -> EpisodeMetrics:
        """Metrics of MODEL.md §6 over the slots run so far (decision time is the caller's)."""
        return self._sim.episode_metrics([self.i])[0]


#: The state's arrays a :class:`Simulation` reads as attributes (``sim.x_aug`` (B, K, 6), ...) and a
#: :class:`ScenarioView` as its row's arrays (``view.x_aug`` (K, 6), ...): properties, not a
#: ``__getattr__`` (a failed attribute lookup costs a step microseconds).
STATE_ARRAYS = ("x_aug", "tracking_error", "x_obs", "error_obs", "applied", "drone_position", "last_power_w",
                "last_delivered", "last_outage_probability", "reference", "buffer", "buffer_age")


def _state_array(name: str) -> property:
    return property(lambda sim: getattr(sim.state, name), doc=f"``state.{name}`` of every scenario.")


def _row_array(name: str) -> property:
    return property(lambda view: getattr(view._sim.state, name)[view.i], doc=f"``state.{name}`` of this scenario.")


for _name in STATE_ARRAYS:
    setattr(Simulation, _name, _state_array(_name))
    setattr(ScenarioView, _name, _row_array(_name))
for _name in ("slot", "paths"):
    setattr(Simulation, _name, _state_array(_name))


class Trail:
    """The positions of one scenario's current episode, slot by slot: what the renderer draws
    behind the drone and the AGVs, and the paths a figure plots. ``restart`` at reset, ``record``
    after every step."""

    def __init__(self, view: ScenarioView):
        self.view = view
        self._states: list[SimState] = []

    def restart(self) -> None:
        self._states = []
        self.record()

    def record(self) -> None:
        # the state itself, not copies: a step makes a new state (it never writes into the old
        # one's arrays); a reset writes into the current one, after which the trail restarts
        self._states.append(self.view._sim.state)

    def trajectories(self) -> dict[str, np.ndarray]:
        """Drone (n+1, 2), AGV (n+1, K, 2) and reference (n+1, K, 2) positions of slots 0..n."""
        i, n = self.view.i, len(self._states)
        return {"drone_position": np.array([s.drone_position[i] for s in self._states]),
                "agv_position": np.array([s.x_aug[i, :, POSITION] for s in self._states]),
                "reference_position": np.swapaxes(self.view.reference[:, :n, POSITION], 0, 1)}
