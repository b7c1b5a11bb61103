"""The simulation's parameters and state: B scenarios of one config, their randomness and their restarts.

* :class:`SimParams`: everything fixed by the config (links, packed matrices, the area, the fixed
  path set's reference table, the disturbance mode), built once, frozen.
* :class:`SimState`: the episode state of B scenarios as plain arrays with a leading batch axis
  (augmented AGV states, drone positions, slots, references, the last slot's links, the episode's
  running sums for the metrics of MODEL.md §6, :class:`lawn_env.metrics.Totals`).
* :class:`Decisions`, :class:`SlotDraws`, :class:`SlotRecord`: what a slot takes and produces;
  :func:`later_increments` (what a buffered actuator's packet carries after its command) and
  :func:`buffer_queue` (what its AGVs play without a packet), for the planners and codecs that
  build or read those buffers without the simulation's object.
* :func:`draw_slot`: a slot's randomness for B scenarios from one generator, in one documented
  order; :func:`reset`: new episodes for chosen rows, each drawing from its own generator.

The slot itself (:func:`lawn_env.slot.step`) is in :mod:`lawn_env.slot`; the environments' object
over both (:class:`lawn_env.core.Simulation`) in :mod:`lawn_env.core`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from . import channel, dynamics, references
from .config import DisturbanceConfig, ScenarioConfig
from .dynamics import POSITION, PredictionModel, initial_state, measure, packed_step_matrices
from .metrics import Totals

__all__ = ["SimParams", "SimState", "SlotDraws", "SlotRecord", "Decisions", "SLOT_CONSTANTS", "draw_slot",
           "empty_state", "reset", "link_outage", "link_success", "buffer_queue", "later_increments"]


def link_outage(x_aug: np.ndarray, drone_xy: np.ndarray, power_w: np.ndarray,
                link: channel.LinkParams) -> tuple[np.ndarray, np.ndarray]:
    """The outage argument x (Prop. 1) and the outage probability of the links from the drone at
    ``drone_xy`` (..., 2) to the AGVs (x_aug (..., K, 6)) with powers (..., K)."""
    x = link.outage_argument_sq(power_w, link.distance_sq(drone_xy[..., None, :], x_aug[..., POSITION]))
    return x, link.outage_at(x)


def link_success(x_aug: np.ndarray, drone_xy: np.ndarray, power_w: np.ndarray, link: channel.LinkParams) -> np.ndarray:
    """The success probability psi of the links from the drone at ``drone_xy`` (..., 2) to the AGVs
    (x_aug (..., K, 6)) with powers (..., K): the planners' psi when ``link`` is their link model
    (``LinkParams.from_config(config, planning=True)``)."""
    return link.success_sq(power_w, link.distance_sq(drone_xy[..., None, :], x_aug[..., POSITION]))


#: What the slot kernel reads of the config, by name (a record: it passes into compiled code as cheaply
#: as one array): the actuator lag's alpha (-1: no lag), the acceleration bound, the true link's H^2,
#: c_d, c_ce (:attr:`lawn_env.channel.LinkParams.coefficients`) and m, the packed transition and stage
#: cost on rows [x~, du] of :func:`lawn_env.dynamics.packed_step_matrices` and A~'s acceleration
#: columns (the actuator lag's correction), transposed.
SLOT_CONSTANTS = np.dtype([("lag_alpha", "f8"), ("accel_max", "f8"), ("altitude_sq", "f8"), ("c_d", "f8"),
                           ("c_ce", "f8"), ("m", "f8"), ("step_t", "f8", (8, 8)), ("cost_w", "f8", (8, 2)),
                           ("accel_effect_t", "f8", (2, 4))])


# ---------------------------------------------------------------------- parameters, state, draws
def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class SimParams:
    """What the config fixes for every episode: sizes, the links (true and planning), the packed
    transition and cost matrices, the area, the fixed path set's reference table (None for random
    paths), the disturbance mode. Build with :meth:`from_config`."""

    config: ScenarioConfig
    num_agvs: int
    num_slots: int
    horizon: int
    steps: int  # reference slots per episode: num_slots + horizon + 1
    slot_s: float
    model: PredictionModel
    link: channel.LinkParams
    planning_link: channel.LinkParams
    area: tuple[float, float, float, float]
    area_lo: np.ndarray
    area_hi: np.ndarray
    max_speed: float
    power_budget_w: float
    drone_start: np.ndarray  # (2,)
    envelope: references.Envelope | None  # None: the paths are not fitted into the AGVs' envelope
    fixed_paths: list[references.Curve] | None
    fixed_reference: np.ndarray | None  # (K, T, 6) of the fixed path set
    disturbance: DisturbanceConfig
    disturbed: bool
    lag_alpha: float  # exp(-slot / lag) under actuator lag, else -1.0 (no lag)
    constants: np.ndarray  # (1,) of SLOT_CONSTANTS: the scalars and the packed matrices the slot kernel reads
    every_slot: np.ndarray  # (1,) True: the ``send`` of a config whose every slot sends its commands
    buffer_length: int  # L = N_p - 1 later increments a packet carries under the buffered actuator; 0 under hold

    @classmethod
    def from_config(cls, config: ScenarioConfig) -> SimParams:
        if not isinstance(config, ScenarioConfig):
            raise TypeError(f"config must be a ScenarioConfig, got {type(config).__name__}")
        k, horizon, slots = config.num_agvs, config.control.horizon, config.num_slots
        steps = slots + horizon + 1
        model = PredictionModel.from_config(config)
        q1 = np.asarray(config.control.q1_diag, dtype=float)
        q2 = np.asarray(config.control.q2_diag, dtype=float)
        packed_t, packed_w = packed_step_matrices(model.a_aug, model.b_aug, q1, q2)
        x0, x1, y0, y1 = config.area_m
        area = (float(x0), float(x1), float(y0), float(y1))
        envelope = references.Envelope.from_config(config, steps)
        fixed_paths = references.paper_paths(k, area, envelope) if config.uses_paper_paths else None
        fixed = references.reference_table(fixed_paths, steps, config.slot_s) if fixed_paths is not None else None
        d = config.disturbance
        link = channel.LinkParams.from_config(config)
        lag_alpha = dynamics.lag_alpha(config.slot_s, d.actuator_lag_s)
        return cls(
            config=config, num_agvs=k, num_slots=slots, horizon=horizon, steps=steps, slot_s=config.slot_s,
            model=model, link=link,
            planning_link=channel.LinkParams.from_config(config, planning=True),
            area=area, area_lo=np.array([area[0], area[2]]), area_hi=np.array([area[1], area[3]]),
            max_speed=config.drone.max_speed_mps,
            power_budget_w=config.power_budget_w, drone_start=np.array(config.drone.start_m, dtype=float),
            envelope=envelope, fixed_paths=fixed_paths, fixed_reference=fixed,
            disturbance=d, disturbed=d.active,
            lag_alpha=lag_alpha,
            constants=_readonly(np.array([(lag_alpha, config.control.accel_max_mps2, link.altitude_sq,
                                           *link.coefficients, link.m, packed_t, packed_w,
                                           model.a_aug[0:4, dynamics.ACCELERATION].T)], dtype=SLOT_CONSTANTS)),
            every_slot=np.ones(1, dtype=bool),
            buffer_length=config.control.buffer_length,
        )

    @property
    def command_period(self) -> int:
        """Commands go out at the slots n with n % P == 0 (MODEL.md §7): P of the disturbance mode, else 1."""
        return self.disturbance.control_period_slots if self.disturbed else 1

    @property
    def measurement_noise(self) -> bool:
        d = self.disturbance
        return self.disturbed and (d.measurement_noise_position_m > 0 or d.measurement_noise_velocity_mps > 0)


class SlotDraws(NamedTuple):
    """A slot's randomness for B scenarios: the fading ``m|h|^2`` of every link (B, K) and, in the
    disturbance mode, the wind gust (B, 2) and the process and measurement noise (B, K, 2) each;
    None where the config has none."""

    fading: np.ndarray
    gust: np.ndarray | None = None
    process_position: np.ndarray | None = None
    process_velocity: np.ndarray | None = None
    measurement_position: np.ndarray | None = None
    measurement_velocity: np.ndarray | None = None


def draw_slot(rng: np.random.Generator, params: SimParams, num: int = 1) -> SlotDraws:
    """One slot's randomness for ``num`` scenarios from ``rng``, in this order: the wind gust
    N(0, gust std) (num, 2), the fading Gamma(m, 1) (num, K), the process noise on positions, then
    on velocities (num, K, 2) each, the measurement noise on positions, then on velocities; a term
    the config does not have is not drawn. With ``num = 1`` these are the draws, in the order, that
    one scenario's environment has always made from its generator."""
    k, d = params.num_agvs, params.disturbance
    gust = rng.normal(0.0, d.wind_gust_std_mps, (num, 2)) if params.disturbed and d.wind_gust_std_mps > 0 else None
    fading = channel.sample_normalized_fading(rng, params.link.m, (num, k))
    if not params.disturbed:
        return SlotDraws(fading)
    pos = rng.normal(0.0, d.process_noise_position_m, (num, k, 2)) if d.process_noise_position_m > 0 else None
    vel = rng.normal(0.0, d.process_noise_velocity_mps, (num, k, 2)) if d.process_noise_velocity_mps > 0 else None
    meas: tuple[np.ndarray | None, np.ndarray | None] = (None, None)
    if params.measurement_noise:
        meas = (rng.normal(0.0, d.measurement_noise_position_m, (num, k, 2)),
                rng.normal(0.0, d.measurement_noise_velocity_mps, (num, k, 2)))
    return SlotDraws(fading, gust, pos, vel, *meas)


class Decisions(NamedTuple):
    """A slot's decisions for B scenarios: increments to send (B, K, 2) m/s^2 (saturated by the
    step), feasible powers (B, K) W, the drone's next positions (B, 2) m; or one scenario's, the same
    without the B axis. An action decoded for ``lawn/Comm-v1``'s role has ``increment`` None (the
    MPC decides it: :class:`lawn_env.envs.base.CommRole`). Under the buffered actuator ``plan``
    (B, K, N_p - 1, 2) is the rest of each AGV's planned sequence, which its packet carries after
    the increment (None: zeros, a plan that holds)."""

    increment: np.ndarray | None
    power_w: np.ndarray
    drone_next: np.ndarray
    plan: np.ndarray | None = None


def buffer_queue(buffer: np.ndarray, age: np.ndarray) -> np.ndarray:
    """The increments the AGVs of a buffered actuator play on their next slots without a packet, in
    order: of buffers (..., K, L, 2) and their ages (..., K), (..., K, L, 2) with entry j the buffer's
    element ``age + j``, zero past its end (a new array)."""
    buffer = np.asarray(buffer, dtype=float)
    length = buffer.shape[-2]
    index = np.asarray(age, dtype=np.int64)[..., None] + np.arange(length)
    out = np.take_along_axis(buffer, np.minimum(index, max(length - 1, 0))[..., None], axis=-2) if length else buffer
    return np.where((index < length)[..., None], out, 0.0)


def later_increments(sequence: np.ndarray, length: int) -> np.ndarray:
    """What a buffered actuator's packet carries after the command of the planned increments
    ``sequence`` (..., N, 2), the first being the command: its next ``length`` (L = N_p - 1), zeros past
    the sequence's end (an AGV that has played them all holds), a new array (..., L, 2)."""
    sequence = np.asarray(sequence, dtype=float)
    plan = np.zeros((*sequence.shape[:-2], length, 2))
    later = sequence[..., 1 : 1 + length, :]
    plan[..., : later.shape[-2], :] = later
    return plan


@dataclass(eq=False, slots=True, kw_only=True)
class SimState:
    """The episode state of B scenarios, every array with a leading batch axis, built by keyword.
    ``x_obs`` and ``error_obs`` are what the policies observe (the true ``x_aug`` and ``tracking_error``
    without measurement noise); ``reference`` (B, K, T, 6) is a broadcast view of the fixed path
    set's table when there is one; ``totals`` holds the episode's running sums packed as the slot
    kernel advances them, read by name through :attr:`sums`."""

    x_aug: np.ndarray  # (B, K, 6) [x, y, v_x, v_y, u_x[n-1], u_y[n-1]]
    tracking_error: np.ndarray  # (B, K, 6) x~ - x~_ref at slot n
    x_obs: np.ndarray
    error_obs: np.ndarray
    applied: np.ndarray  # (B, K, 2) the applied accelerations (actuator lag)
    drone_position: np.ndarray  # (B, 2) q[n-1], where the drone moves from
    slot: np.ndarray  # (B,) int64
    last_power_w: np.ndarray  # (B, K)
    last_delivered: np.ndarray  # (B, K) bool
    last_outage_probability: np.ndarray  # (B, K)
    reference: np.ndarray  # (B, K, T, 6)
    paths: list[list[references.Curve] | None]  # per scenario, its K paths (None before a first reset)
    totals: np.ndarray  # (B, 5 + 3K), columns lawn_env.metrics.TOTALS
    buffer: np.ndarray  # (B, K, L, 2) the AGVs' buffered increments (L = 0 under the hold actuator)
    buffer_age: np.ndarray  # (B, K) int64: how many of them have been played since their packet (L: spent)

    @property
    def num_envs(self) -> int:
        return int(self.x_aug.shape[0])

    @property
    def sums(self) -> Totals:
        """The running sums of every scenario by name (views of ``totals``)."""
        return Totals(self.totals)


def empty_state(params: SimParams, num: int) -> SimState:
    """B scenarios before their first reset (zeros; :func:`reset` starts them)."""
    k, steps = params.num_agvs, params.steps
    fixed = params.fixed_reference
    reference = np.broadcast_to(fixed, (num, *fixed.shape)) if fixed is not None else np.zeros((num, k, steps, 6))
    x = np.zeros((num, k, 6))
    return SimState(
        x_aug=x, tracking_error=np.zeros((num, k, 6)), x_obs=x, error_obs=np.zeros((num, k, 6)),
        applied=np.zeros((num, k, 2)), drone_position=np.zeros((num, 2)), slot=np.zeros(num, dtype=np.int64),
        last_power_w=np.zeros((num, k)), last_delivered=np.ones((num, k), dtype=bool),
        last_outage_probability=np.zeros((num, k)), reference=reference,
        paths=[params.fixed_paths] * num,
        totals=Totals.zeros(num, k),
        buffer=np.zeros((num, k, params.buffer_length, 2)),
        buffer_age=np.full((num, k), params.buffer_length, dtype=np.int64),
    )


def reset(params: SimParams, state: SimState, rngs: Sequence[np.random.Generator],
          which: np.ndarray | None = None) -> None:
    """New episodes for the scenarios ``which`` (a mask; all when None), scenario i drawing from
    ``rngs[i]``: its random paths (for a random path set), its initial offsets N(0, offset std)
    (K, 2), then, under measurement noise, the noise of its first observation. Writes those rows of
    ``state`` in place (the reference tables are large); the other rows are untouched."""
    num, k, steps = state.num_envs, params.num_agvs, params.steps
    idx = np.arange(num) if which is None else np.flatnonzero(which)
    cfg = params.config
    for name in ("tracking_error", "applied", "drone_position", "slot", "last_power_w", "last_delivered",
                 "last_outage_probability", "buffer", "buffer_age"):  # new arrays: records and infos keep the old ones
        setattr(state, name, getattr(state, name).copy())
    if params.fixed_reference is None:  # every restarting scenario's paths drawn together, one table call
        paths = references.sample_paths([rngs[i] for i in idx.tolist()], k, cfg.reference.families, params.area,
                                        duration_s=(steps - 1) * params.slot_s, envelope=params.envelope)
        tables = references.reference_table([p for row in paths for p in row], steps, params.slot_s)
        state.reference[idx] = tables.reshape(idx.size, k, steps, 6)
        for j, i in enumerate(idx.tolist()):
            state.paths[i] = paths[j]
    offsets = np.empty((idx.size, k, 2))
    for j, i in enumerate(idx.tolist()):  # after its paths, from the scenario's own generator
        offsets[j] = rngs[i].normal(0.0, cfg.reference.initial_offset_std_m, size=(k, 2))
    start = state.reference[idx, :, 0]
    x_aug = state.x_aug.copy()
    x_aug[idx] = initial_state(start, offsets, params.area_lo, params.area_hi)
    state.x_aug = x_aug
    state.tracking_error[idx] = x_aug[idx] - start
    state.applied[idx] = x_aug[idx, :, dynamics.ACCELERATION]
    if params.measurement_noise:
        state.x_obs, state.error_obs = state.x_obs.copy(), state.error_obs.copy()
        d = params.disturbance
        for i in idx.tolist():  # after the offsets, from the scenario's generator
            pos = rngs[i].normal(0.0, d.measurement_noise_position_m, (k, 2))
            vel = rngs[i].normal(0.0, d.measurement_noise_velocity_mps, (k, 2))
            state.x_obs[i], state.error_obs[i] = measure(x_aug[i], state.tracking_error[i], pos, vel)
    else:
        state.x_obs, state.error_obs = state.x_aug, state.tracking_error
    state.drone_position[idx] = params.drone_start
    state.slot[idx] = 0
    state.last_power_w[idx] = params.power_budget_w / k
    state.last_delivered[idx] = True
    state.buffer[idx] = 0.0  # an episode starts with every buffer spent: a first lost command holds
    state.buffer_age[idx] = params.buffer_length
    state.last_outage_probability[idx] = link_outage(x_aug[idx], state.drone_position[idx], state.last_power_w[idx],
                                                     params.link)[1]
    state.totals = state.totals.copy()
    state.totals[idx] = 0.0


class SlotRecord(NamedTuple):
    """What one slot produced for B scenarios."""

    terms: np.ndarray  # (B, K, 2) per AGV: e' Q1 e at slot n+1 (e: augmented tracking error), du' Q2 du applied
    delivered: np.ndarray  # (B, K) bool
    outage_probability: np.ndarray  # (B, K) closed form at (p, q[n]) for the true link
    applied_increment: np.ndarray  # (B, K, 2) after saturation and delivery, m/s^2
    power_w: np.ndarray  # (B, K)
    drone_position: np.ndarray  # q[n], (B, 2), after the wind
    costs: np.ndarray  # (B, 3) the slot's tracking, effort and stage cost, summed over AGVs left to right

    @property
    def tracking_cost(self) -> np.ndarray:
        """Per AGV e' Q1 e (B, K)."""
        return self.terms[..., 0]

    @property
    def effort_cost(self) -> np.ndarray:
        """Per AGV du' Q2 du (B, K)."""
        return self.terms[..., 1]

    @property
    def stage_cost(self) -> np.ndarray:
        """The slot's stage cost, tracking + effort, as a column (B, 1)."""
        return self.costs[:, 2:3]

