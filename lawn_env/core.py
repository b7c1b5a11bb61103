"""The simulation core shared by every environment (one model, several views of it).

:class:`Simulation` holds the state (augmented AGV states, drone position, slot index,
references) and advances it one slot given the decisions of that slot: the acceleration
increments to send, the power split and the drone's next position. It samples the links,
applies delivered commands, computes the realized stage cost and accumulates the episode
metrics of MODEL.md §6. It knows nothing about action or observation encodings; the
environments do (see :mod:`lawn_env.spaces`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from . import channel, drone, references
from .config import ScenarioConfig
from .dynamics import PredictionModel, packed_step_matrices

__all__ = ["Simulation", "Snapshot", "SlotRecord", "initial_state", "saturate_increment", "link_outage", "link_success",
           "apply_wind", "disturb", "measure", "transmit", "stage_terms"]


# ---------------------------------------------------------------------- the slot's equations
# Shape-generic over leading axes: (K, ...) for one scenario, (B, K, ...) for a batch of them
# (lawn_env.batch). Every view of the simulation calls these.
def initial_state(reference_start: np.ndarray, offsets: np.ndarray, area_lo: np.ndarray,
                  area_hi: np.ndarray) -> np.ndarray:
    """Augmented AGV states at slot 0: the reference start position plus ``offsets`` (kept in
    the area), the reference velocity, zero previous acceleration. (..., K, 6) from the
    reference's first slot (..., K, 6) and offsets (..., K, 2)."""
    x_aug = np.zeros(reference_start.shape)
    x_aug[..., 0:2] = np.clip(reference_start[..., 0:2] + offsets, area_lo, area_hi)
    x_aug[..., 2:4] = reference_start[..., 2:4]
    return x_aug


def saturate_increment(u_prev: np.ndarray, du: np.ndarray, accel_max: float) -> np.ndarray:
    """Increments clipped so that |u[n-1] + du| <= a_max per axis (the control set, by
    saturation): a new array."""
    u = u_prev + du
    np.maximum(u, -accel_max, out=u)
    np.minimum(u, accel_max, out=u)
    u -= u_prev
    return u


def link_outage(x_aug: np.ndarray, drone_xy: np.ndarray, power_w: np.ndarray,
                link: channel.LinkParams) -> tuple[np.ndarray, np.ndarray]:
    """The outage argument x (Prop. 1) and the outage probability of the links from the drone at
    ``drone_xy`` (..., 2) to the AGVs (x_aug (..., K, 6)) with powers (..., K)."""
    x = link.outage_argument_sq(power_w, link.distance_sq(drone_xy[..., None, :], x_aug[..., 0:2]))
    return x, link.outage_at(x)


def link_success(x_aug: np.ndarray, drone_xy: np.ndarray, power_w: np.ndarray, link: channel.LinkParams) -> np.ndarray:
    """The success probability psi of the links from the drone at ``drone_xy`` (..., 2) to the AGVs
    (x_aug (..., K, 6)) with powers (..., K): the planners' psi when ``link`` is their link model
    (``LinkParams.from_config(config, planning=True)``)."""
    return link.success_sq(power_w, link.distance_sq(drone_xy[..., None, :], x_aug[..., 0:2]))


def apply_wind(drone_next: np.ndarray, wind_mps: np.ndarray, slot_s: float, area_lo: np.ndarray,
               area_hi: np.ndarray) -> np.ndarray:
    """The drone's next position (..., 2) drifted by the slot's wind (mean plus gust, (..., 2) m/s)
    and kept in the area (disturbance mode)."""
    return np.clip(drone_next + wind_mps * slot_s, area_lo, area_hi)


def disturb(packed: np.ndarray, commanded: np.ndarray, applied: np.ndarray, lag_alpha: float | None,
            accel_effect_t: np.ndarray, position_noise: np.ndarray | None,
            velocity_noise: np.ndarray | None) -> np.ndarray:
    """The disturbance mode's changes to the transition, in place on the packed rows (..., K, 8):
    the actuator lag (``lag_alpha``, None without lag) moves the AGV with the applied acceleration
    instead of the commanded u[n] (the difference enters through A~'s acceleration column, the
    same model), and process noise (..., K, 2) perturbs position and velocity. Returns the new
    applied accelerations."""
    if lag_alpha is not None:
        applied = lag_alpha * applied + (1.0 - lag_alpha) * commanded
        packed[..., 0:4] += _rows_matmul(applied - commanded, accel_effect_t)
    if position_noise is not None:
        packed[..., 0:2] += position_noise
    if velocity_noise is not None:
        packed[..., 2:4] += velocity_noise
    return applied


def measure(x_aug: np.ndarray, tracking_error: np.ndarray, position_noise: np.ndarray,
            velocity_noise: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """What the policies observe under measurement noise (..., K, 2) on positions and velocities:
    the state and the tracking error, both with the same noise."""
    noise = np.zeros_like(x_aug)
    noise[..., 0:2] = position_noise
    noise[..., 2:4] = velocity_noise
    return x_aug + noise, tracking_error + noise


def transmit(x_aug: np.ndarray, du: np.ndarray, power_w: np.ndarray, drone_next: np.ndarray,
             normalized_fading: np.ndarray, link: channel.LinkParams,
             packed_t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One slot's links and transition: the commands go from the drone at ``drone_next`` (..., 2)
    to the AGVs (x_aug (..., K, 6)) with powers (..., K); those whose fading m|h|^2 reaches the
    outage argument arrive. Returns the packed rows [x~[n+1], du] (..., K, 8) of the delivered
    increments (dynamics.packed_step_matrices), ``delivered`` and the outage probabilities."""
    x, outage_p = link_outage(x_aug, drone_next, power_w, link)
    delivered = channel.delivered_from_fading(normalized_fading, x)
    du = du * delivered[..., None]
    return _rows_matmul(np.concatenate((x_aug, du), axis=-1), packed_t), delivered, outage_p


def stage_terms(packed: np.ndarray, reference_packed: np.ndarray,
                packed_w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The packed error [x~[n+1] - x~_ref[n+1], du] and the stage cost's two terms per AGV
    (e' Q1 e, du' Q2 du): (..., K, 8) and (..., K, 2)."""
    err = packed - reference_packed
    return err, _rows_matmul(err * err, packed_w)


def _rows_matmul(a: np.ndarray, m: np.ndarray) -> np.ndarray:
    """``a @ m`` for rows ``a`` (..., n) with any leading axes, as one 2-D product: numpy's
    stacked matmul over a (B, K, n) batch is several times slower than the same rows flattened."""
    if a.ndim <= 2:
        return a @ m
    return (a.reshape(-1, a.shape[-1]) @ m).reshape(a.shape[:-1] + m.shape[1:])


@dataclass(frozen=True)
class Snapshot:
    """The full system state an external planner needs at the start of a slot.

    ``x_aug`` (K, 6): augmented AGV states [x, y, v_x, v_y, u_x[n-1], u_y[n-1]];
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


class SlotRecord(NamedTuple):
    """What one slot produced (arrays are per AGV); ``Simulation.history`` is a list of these."""

    tracking_cost: np.ndarray  # e' Q1 e at slot n+1 (e: augmented tracking error)
    effort_cost: np.ndarray  # Delta-u' Q2 Delta-u of the delivered increment
    delivered: np.ndarray  # bool
    outage_probability: np.ndarray  # closed form at (p, q[n]) for the true link
    applied_increment: np.ndarray  # (K, 2) after saturation and delivery, m/s^2
    power_w: np.ndarray  # (K,)
    drone_position: np.ndarray  # q[n], (2,)
    agv_position: np.ndarray  # (K, 2) at slot n+1


class Simulation:
    """One scenario's dynamics, channel and bookkeeping.

    ``reset(rng)`` draws the references (for random path sets) and the initial offsets from
    ``rng``; ``step`` draws the fading from the same generator, so one seed fixes an episode.
    """

    def __init__(self, config: ScenarioConfig):
        if not isinstance(config, ScenarioConfig):
            raise TypeError(f"config must be a ScenarioConfig, got {type(config).__name__}")
        self.config = config
        self.num_agvs = config.num_agvs
        self.num_slots = config.num_slots
        self.horizon = config.control.horizon
        self.slot_s = config.slot_s
        self.model = PredictionModel.from_config(config)
        self.link = channel.LinkParams.from_config(config)
        self.planning_link = channel.LinkParams.from_config(config, planning=True)
        self._disturbed = config.disturbance.active
        lag = config.disturbance.actuator_lag_s
        self._lag_alpha = float(np.exp(-config.slot_s / lag)) if lag > 0 else 0.0
        self.power_budget_w = config.power_budget_w
        self.accel_max = config.control.accel_max_mps2
        self.max_speed = config.drone.max_speed_mps
        self.area = tuple(config.area_m)
        self._area_lo = np.array([self.area[0], self.area[2]])
        self._area_hi = np.array([self.area[1], self.area[3]])
        self._q1 = np.asarray(config.control.q1_diag, dtype=float)
        self._q2 = np.asarray(config.control.q2_diag, dtype=float)
        self._packed_t, self._packed_w = packed_step_matrices(self.model.a_aug, self.model.b_aug, self._q1, self._q2)
        self._a_aug_t = np.ascontiguousarray(self.model.a_aug.T)
        # effect of a slot's acceleration on [position, velocity]: A~'s u[n-1] columns (the lag's correction)
        self._accel_effect_t = np.ascontiguousarray(self.model.a_aug[0:4, 4:6].T)
        self._b_aug_t = np.ascontiguousarray(self.model.b_aug.T)
        self._envelope = references.Envelope.from_config(config, self.num_slots + self.horizon + 1)
        self._paper_paths = (references.paper_paths(self.num_agvs, self.area, self._envelope)
                             if config.uses_paper_paths else None)
        self._paper_table = (
            references.reference_table(self._paper_paths, self.num_slots + self.horizon + 1, self.slot_s)
            if self._paper_paths is not None else None
        )
        self.paths = None
        self.reference = None
        self.x_aug = None
        self.drone_position = None
        self.slot = 0

    # ------------------------------------------------------------------ episode
    def reset(self, rng: np.random.Generator) -> None:
        cfg = self.config
        k = self.num_agvs
        steps = self.num_slots + self.horizon + 1
        if self._paper_paths is not None:
            self.paths = self._paper_paths
            self.reference = self._paper_table
        else:
            self.paths = references.random_paths(
                rng, k, cfg.reference.families, self.area, duration_s=(steps - 1) * self.slot_s,
                envelope=self._envelope,
            )
            self.reference = references.reference_table(self.paths, steps, self.slot_s)
        self._reference_packed = np.concatenate([self.reference, np.zeros(self.reference.shape[:2] + (2,))], axis=2)
        self.rng = rng
        offsets = rng.normal(0.0, cfg.reference.initial_offset_std_m, size=(k, 2))
        x_aug = initial_state(self.reference[:, 0], offsets, self._area_lo, self._area_hi)
        self.x_aug = x_aug
        self.tracking_error = x_aug - self.reference[:, 0]
        self._applied = x_aug[:, 4:6].copy()
        self.x_obs, self.error_obs = self.x_aug, self.tracking_error
        if self._disturbed:
            self._observe()
        self.drone_position = np.array(cfg.drone.start_m, dtype=float)
        self.slot = 0
        self.last_power_w = np.full(k, self.power_budget_w / k)
        self.last_delivered = np.ones(k, dtype=bool)
        self.last_outage_probability = self.outage_probability(self.last_power_w, self.drone_position)
        self.history: list[SlotRecord] = []
        self._start_drone = self.drone_position.copy()
        self._start_agv = x_aug[:, 0:2].copy()

    # ------------------------------------------------------------------ channel helpers
    def outage_probability(self, power_w: np.ndarray, drone_position: np.ndarray) -> np.ndarray:
        """Closed-form outage of the true link at the current AGV positions."""
        return link_outage(self.x_aug, np.asarray(drone_position, dtype=float), power_w, self.link)[1]

    def planning_success(self, power_w: np.ndarray, drone_position: np.ndarray) -> np.ndarray:
        """psi of the planners' link model (CSI-aware or not, see ChannelConfig)."""
        return link_success(self.x_aug, np.asarray(drone_position, dtype=float), power_w, self.planning_link)

    def drone_target(self, velocity_mps: np.ndarray) -> np.ndarray:
        """Next drone position for a commanded velocity (speed-limited, kept in the area)."""
        return drone.move_drone(self.drone_position, velocity_mps, self.max_speed, self.slot_s, self.area)

    def reference_window(self) -> np.ndarray:
        """Reference augmented states at slots n..n+N_p: (K, N_p+1, 6) (a view)."""
        return self.reference[:, self.slot : self.slot + self.horizon + 1]

    def saturate_increment(self, du: np.ndarray) -> np.ndarray:
        """Clip increments so that |u[n-1] + du| <= a_max per axis (the control set, by saturation)."""
        return saturate_increment(self.x_aug[:, 4:6], du, self.accel_max)

    def snapshot(self) -> Snapshot:
        return Snapshot(
            x_aug=self.x_obs.copy(),  # measured state: what a planner would have
            reference=self.reference_window().copy(),
            drone_position=self.drone_position.copy(),
            slot=self.slot,
            config=self.config,
            last_power_w=self.last_power_w.copy(),
        )

    # ------------------------------------------------------------------ one slot
    def step(self, increment: np.ndarray, power_w: np.ndarray, drone_next: np.ndarray) -> SlotRecord:
        """Advance one slot.

        ``increment`` (K, 2): the Delta-u to send (saturated here to the acceleration bound);
        ``power_w`` (K,): feasible powers (p >= 0, sum <= P_max); ``drone_next`` (2,): q[n], a
        feasible next drone position (use :meth:`drone_target`); the simulator keeps references to
        ``power_w`` and ``drone_next``, so pass fresh arrays. Commands are sent from q[n]
        to the AGVs at their slot-n positions and arrive with the sampled fading.

        One path for the nominal model and the disturbance mode (MODEL.md §7): when it is on, wind
        moves the drone after its planned move, commands go out only every
        ``control_period_slots``, the applied AGV acceleration lags the commanded one, the AGV
        state takes process noise and what the policies observe takes measurement noise; the
        channel, the transition and the costs are the same equations either way.
        """
        disturbed = self._disturbed
        d = self.config.disturbance
        rng = self.rng
        if disturbed:
            wind = np.asarray(d.wind_mps, dtype=float)
            if d.wind_gust_std_mps > 0:
                wind = wind + rng.normal(0.0, d.wind_gust_std_mps, 2)
            drone_next = apply_wind(np.asarray(drone_next, dtype=float), wind, self.slot_s, self._area_lo,
                                    self._area_hi)
        x_aug = self.x_aug
        du = saturate_increment(x_aug[:, 4:6], increment, self.accel_max)
        if disturbed and self.slot % d.control_period_slots:
            du[:] = 0.0  # no command this slot (reduced control rate): nothing is sent
        fading = channel.sample_normalized_fading(rng, self.link.m, self.num_agvs)
        packed, delivered, outage_p = transmit(x_aug, du, power_w, drone_next, fading, self.link,
                                               self._packed_t)
        du = packed[:, 6:8]
        if disturbed:
            self._disturb(packed, x_aug[:, 4:6] + du)
        self.slot += 1
        err, terms = stage_terms(packed, self._reference_packed[:, self.slot], self._packed_w)
        tracking, effort = terms[:, 0], terms[:, 1]
        x_next = packed[:, 0:6]
        self.x_aug = self.x_obs = x_next
        self.tracking_error = self.error_obs = err[:, 0:6]
        if disturbed:
            self._observe()
        return self._record(SlotRecord(tracking, effort, delivered, outage_p, du, power_w, drone_next, x_next[:, 0:2]))

    def _disturb(self, packed: np.ndarray, commanded: np.ndarray) -> None:
        """:func:`disturb` with this episode's process noise (drawn position first, then velocity)."""
        d, k = self.config.disturbance, self.num_agvs
        pos = self.rng.normal(0.0, d.process_noise_position_m, (k, 2)) if d.process_noise_position_m > 0 else None
        vel = self.rng.normal(0.0, d.process_noise_velocity_mps, (k, 2)) if d.process_noise_velocity_mps > 0 else None
        lag = self._lag_alpha if d.actuator_lag_s > 0 else None
        self._applied = disturb(packed, commanded, self._applied, lag, self._accel_effect_t, pos, vel)

    def _record(self, record: SlotRecord) -> SlotRecord:
        """The slot's bookkeeping (the AGV state is already updated)."""
        self.drone_position = record.drone_position
        self.last_power_w = record.power_w
        self.last_delivered = record.delivered
        self.last_outage_probability = record.outage_probability
        self.history.append(record)
        return record

    def _observe(self) -> None:
        """What the policies see: the state with measurement noise (the true state without it)."""
        d = self.config.disturbance
        if d.measurement_noise_position_m <= 0 and d.measurement_noise_velocity_mps <= 0:
            self.x_obs, self.error_obs = self.x_aug, self.tracking_error
            return
        pos = self.rng.normal(0.0, d.measurement_noise_position_m, (self.num_agvs, 2))
        vel = self.rng.normal(0.0, d.measurement_noise_velocity_mps, (self.num_agvs, 2))
        self.x_obs, self.error_obs = measure(self.x_aug, self.tracking_error, pos, vel)

    @property
    def done(self) -> bool:
        """True once ``num_slots`` slots have run (the episode truncates)."""
        return self.slot >= self.num_slots

    def trajectories(self) -> dict:
        """The episode so far as arrays: drone (n+1, 2), AGVs (n+1, K, 2), reference positions (n+1, K, 2),
        and the per-slot records stacked (n, K) each."""
        hist = self.history
        drone_xy = np.vstack([self._start_drone] + [r.drone_position for r in hist])
        agv_xy = np.stack([self._start_agv] + [r.agv_position for r in hist])
        out = {
            "drone_position": drone_xy,
            "agv_position": agv_xy,
            "reference_position": np.swapaxes(self.reference[:, : len(hist) + 1, 0:2], 0, 1),
        }
        for name in ("tracking_cost", "effort_cost", "delivered", "outage_probability", "power_w"):
            out[name] = np.array([getattr(r, name) for r in hist])
        return out

    # ------------------------------------------------------------------ metrics
    def episode_metrics(self) -> dict:
        """Metrics of MODEL.md §6 over the slots run so far (decision time is the caller's)."""
        n = self.slot
        k = self.num_agvs
        if n == 0:
            raise RuntimeError("no slot has been simulated yet")
        traj = self.trajectories()
        tracking = float(traj["tracking_cost"].sum())
        effort = float(traj["effort_cost"].sum())
        pos_err = traj["agv_position"][1:] - traj["reference_position"][1:]
        sq_err = (pos_err**2).sum(axis=(0, 2))
        outages = n - traj["delivered"].sum(axis=0)
        drone_steps = np.diff(traj["drone_position"], axis=0)
        return {
            "slots": n,
            "control_cost": tracking + effort,
            "tracking_cost": tracking,
            "effort_cost": effort,
            "rmse_m": float(np.sqrt(sq_err.sum() / (n * k))),
            "rmse_per_agv_m": np.sqrt(sq_err / n).tolist(),
            "outage_rate": float(outages.sum() / (n * k)),
            "outage_rate_predicted": float(traj["outage_probability"].mean()),
            "outage_rate_per_agv": (outages / n).tolist(),
            "mean_power_w": traj["power_w"].mean(axis=0).tolist(),
            "drone_path_length_m": float(np.sqrt((drone_steps**2).sum(axis=1)).sum()),
        }
