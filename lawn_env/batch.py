"""The simulation over a batch of B scenarios at once (leading batch axis), for vector envs.

:class:`BatchSimulation` holds the state of B independent scenarios of one config as arrays
with a leading batch axis and advances them all with one call, through the same slot
functions as :class:`lawn_env.core.Simulation` (:func:`~lawn_env.core.saturate_increment`,
:func:`~lawn_env.core.transmit`, :func:`~lawn_env.core.stage_terms`, :func:`initial_state`).
Scenario ``i`` draws its references and initial offsets from its own generator, exactly as a
single :class:`~lawn_env.core.Simulation` reset with that generator does (the restarting
scenarios' paths are drawn together by :func:`lawn_env.references.sample_paths`); the fading of all
scenarios comes from one batched generator, so a step costs a handful of numpy calls whatever
B is. The disturbance mode runs through the same functions as the single simulation
(:func:`~lawn_env.core.apply_wind`, :func:`~lawn_env.core.disturb`,
:func:`~lawn_env.core.measure`); its per-slot draws come from the caller (the vector env's batched
generator), the measurement noise at reset from each scenario's generator, as in
:meth:`Simulation.reset`.
"""

from __future__ import annotations

import numpy as np

from . import references
from .config import ScenarioConfig
from .core import (Simulation, apply_wind, disturb, initial_state, link_outage, measure, saturate_increment,
                   stage_terms, transmit)

__all__ = ["BatchSimulation"]


class BatchSimulation:
    """B scenarios of ``config``: ``x_aug`` (B, K, 6), ``drone_position`` (B, 2), ``slot`` (B,),
    ``reference`` (B, K, T, 6) (a broadcast view when the path set is fixed), and the last
    slot's ``last_power_w``, ``last_delivered``, ``last_outage_probability`` (B, K)."""

    def __init__(self, config: ScenarioConfig, num_envs: int):
        if not isinstance(num_envs, (int, np.integer)) or isinstance(num_envs, bool) or num_envs < 1:
            raise ValueError(f"num_envs={num_envs!r}: must be an integer >= 1")
        self.config = config
        self.num_envs = int(num_envs)
        self.single = Simulation(config)  # parameters, matrices and the fixed path set, shared
        s = self.single
        self.num_agvs, self.num_slots, self.horizon = s.num_agvs, s.num_slots, s.horizon
        self.steps = self.num_slots + self.horizon + 1
        self.reference = None
        self.shared_reference = None  # (K, T, 6) when every scenario has the same (fixed) path set
        self.reference_packed = None  # (B, K, T, 8) [reference, 0, 0] rows for the stage cost (random paths)
        self.shared_packed = None  # (T, K, 8) the same for a fixed path set, shared by every scenario
        self.x_aug = self.tracking_error = None
        self.x_obs = self.error_obs = None  # what the policies observe (the true state without measurement noise)
        self.disturbed = config.disturbance.active
        self._applied = None  # the applied accelerations under actuator lag, (B, K, 2)
        self.drone_position = None
        self.slot = np.zeros(self.num_envs, dtype=np.int64)
        self._rows = np.arange(self.num_envs)

    # ------------------------------------------------------------------ episodes
    def reset(self, rngs: list[np.random.Generator], which: np.ndarray | None = None) -> None:
        """Start new episodes for the scenarios ``which`` (all when None), scenario i drawing from
        ``rngs[i]`` as :meth:`Simulation.reset` would."""
        s, b, k = self.single, self.num_envs, self.num_agvs
        idx = self._rows if which is None else np.flatnonzero(which)
        if self.x_aug is None:
            if idx.size != b:
                raise RuntimeError("the first reset must start every scenario")
            self.x_aug = np.zeros((b, k, 6))
            self.drone_position = np.zeros((b, 2))
            self.last_power_w = np.zeros((b, k))
            self.last_delivered = np.ones((b, k), dtype=bool)
            self.last_outage_probability = np.zeros((b, k))
            if s._paper_table is not None:  # one path set for every scenario: shared, never copied per scenario
                self.shared_reference = s._paper_table
                self.reference = np.broadcast_to(s._paper_table, (b,) + s._paper_table.shape)
                packed = np.concatenate([s._paper_table, np.zeros((k, self.steps, 2))], axis=2)
                self.shared_packed = np.ascontiguousarray(packed.transpose(1, 0, 2))  # slot-major: one gather per step
            else:
                self.reference = np.zeros((b, k, self.steps, 6))
                self.reference_packed = np.zeros((b, k, self.steps, 8))
            self.tracking_error = np.zeros((b, k, 6))
        cfg = self.config
        if s._paper_table is None:  # every restarting scenario's paths drawn together, one table call
            paths = references.sample_paths([rngs[i] for i in idx.tolist()], k, cfg.reference.families, s.area,
                                            duration_s=(self.steps - 1) * s.slot_s, envelope=s._envelope)
            tables = references.reference_table([p for row in paths for p in row], self.steps, s.slot_s)
            self.reference[idx] = tables.reshape(idx.size, k, self.steps, 6)
            self.reference_packed[idx, :, :, 0:6] = self.reference[idx]
        offsets = np.empty((idx.size, k, 2))
        for j, i in enumerate(idx.tolist()):  # after its paths, as Simulation.reset draws them
            offsets[j] = rngs[i].normal(0.0, cfg.reference.initial_offset_std_m, size=(k, 2))
        start = self.reference[idx, :, 0]
        self.x_aug[idx] = initial_state(start, offsets, s._area_lo, s._area_hi)
        self.tracking_error[idx] = self.x_aug[idx] - start
        if self.disturbed:
            if self._applied is None:
                self._applied = np.zeros((b, k, 2))
            self._applied[idx] = self.x_aug[idx, :, 4:6]
            d = cfg.disturbance
            if d.measurement_noise_position_m > 0 or d.measurement_noise_velocity_mps > 0:
                if self.x_obs is None or self.x_obs is self.x_aug:
                    self.x_obs, self.error_obs = self.x_aug.copy(), self.tracking_error.copy()
                for i in idx.tolist():  # after the offsets, from the scenario's generator (Simulation._observe)
                    pos = rngs[i].normal(0.0, d.measurement_noise_position_m, (k, 2))
                    vel = rngs[i].normal(0.0, d.measurement_noise_velocity_mps, (k, 2))
                    self.x_obs[i], self.error_obs[i] = measure(self.x_aug[i], self.tracking_error[i], pos, vel)
            else:
                self.x_obs, self.error_obs = self.x_aug, self.tracking_error
        else:
            self.x_obs, self.error_obs = self.x_aug, self.tracking_error
        self.drone_position[idx] = np.asarray(cfg.drone.start_m, dtype=float)
        self.slot[idx] = 0
        self.last_power_w[idx] = s.power_budget_w / k
        self.last_delivered[idx] = True
        self.last_outage_probability[idx] = link_outage(self.x_aug[idx], self.drone_position[idx], self.last_power_w[idx],
                                                        s.link)[1]

    # ------------------------------------------------------------------ one slot
    def step(self, increment: np.ndarray, power_w: np.ndarray, drone_next: np.ndarray,
             normalized_fading: np.ndarray, noise: dict | None = None) -> dict:
        """Advance every scenario one slot: increments (B, K, 2), powers (B, K), next drone
        positions (B, 2), fading m|h|^2 (B, K) and, in the disturbance mode, the slot's other draws
        ``noise`` (:meth:`noise_shapes`). Returns the slot's arrays: ``tracking_cost`` and
        ``effort_cost`` (B, K), ``delivered``, ``outage_probability``, ``applied_increment`` and
        ``drone_position`` (after the wind)."""
        s = self.single
        d = self.config.disturbance
        if self.disturbed:  # Simulation.step's disturbance mode, with the same functions
            wind = np.asarray(d.wind_mps, dtype=float)
            if "gust" in noise:
                wind = wind + noise["gust"]
            drone_next = apply_wind(drone_next, wind, s.slot_s, s._area_lo, s._area_hi)
        du = saturate_increment(self.x_aug[..., 4:6], increment, s.accel_max)
        if self.disturbed and d.control_period_slots > 1:
            du[self.slot % d.control_period_slots != 0] = 0.0  # no command this slot: nothing is sent
        packed, delivered, outage_p = transmit(self.x_aug, du, power_w, drone_next, normalized_fading, s.link,
                                               s._packed_t)
        if self.disturbed:
            lag = s._lag_alpha if d.actuator_lag_s > 0 else None
            self._applied = disturb(packed, self.x_aug[..., 4:6] + packed[..., 6:8], self._applied, lag,
                                    s._accel_effect_t, noise.get("process_position"), noise.get("process_velocity"))
        self.slot += 1
        if self.shared_packed is not None:  # one path set: gather from its (T, K, 8) table, not the batch's
            reference = self.shared_packed[self.slot]
        else:
            reference = self.reference_packed[self._rows, :, self.slot]
        err, terms = stage_terms(packed, reference, s._packed_w)
        self.x_aug = packed[..., 0:6]
        self.tracking_error = err[..., 0:6]
        if "measurement_position" in (noise or {}):
            self.x_obs, self.error_obs = measure(self.x_aug, self.tracking_error, noise["measurement_position"],
                                                 noise["measurement_velocity"])
        else:
            self.x_obs, self.error_obs = self.x_aug, self.tracking_error
        self.drone_position = drone_next
        self.last_power_w = power_w
        self.last_delivered = delivered
        self.last_outage_probability = outage_p
        return {"tracking_cost": terms[..., 0], "effort_cost": terms[..., 1], "delivered": delivered,
                "outage_probability": outage_p, "applied_increment": packed[..., 6:8]}

    def noise_shapes(self) -> dict:
        """The disturbance mode's draws of one slot besides the fading, name -> (shape, std), in the
        order :meth:`Simulation.step` draws them (the gust, the process noise, then the
        measurement noise); empty without the disturbance mode."""
        if not self.disturbed:
            return {}
        d, b, k = self.config.disturbance, self.num_envs, self.num_agvs
        out = {}
        if d.wind_gust_std_mps > 0:
            out["gust"] = ((b, 2), d.wind_gust_std_mps)
        if d.process_noise_position_m > 0:
            out["process_position"] = ((b, k, 2), d.process_noise_position_m)
        if d.process_noise_velocity_mps > 0:
            out["process_velocity"] = ((b, k, 2), d.process_noise_velocity_mps)
        if d.measurement_noise_position_m > 0 or d.measurement_noise_velocity_mps > 0:
            out["measurement_position"] = ((b, k, 2), d.measurement_noise_position_m)
            out["measurement_velocity"] = ((b, k, 2), d.measurement_noise_velocity_mps)
        return out

    def reference_windows(self) -> np.ndarray:
        """Reference augmented states at slots n..n+N_p of every scenario: (B, K, N_p+1, 6)."""
        idx = self.slot[:, None] + np.arange(self.horizon + 1)[None, :]
        return self.reference[self._rows[:, None], :, idx].transpose(0, 2, 1, 3)
