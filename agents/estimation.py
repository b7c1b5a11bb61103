"""What a planner knows of the AGVs beyond one observation: the applied acceleration under an actuator
lag, and a Kalman filter of positions and velocities under measurement noise (MODEL.md §7).

Both follow an episode slot by slot from its start (a policy's ``plan`` sees every slot in order), and
both are exact or optimal for the disturbance model the config declares:

* **The applied acceleration.** Under a lag the AGV moves with ``a = alpha a[n-1] + (1 - alpha) u``
  (:func:`lawn_env.dynamics.lagged_acceleration`), and ``u`` is the commanded acceleration, which the
  observation carries (x~'s ``u[n-1]``, free of measurement noise): filtering the observed ``u``
  reproduces the simulator's ``a`` to rounding. Without a lag ``a = u``.
* **Positions and velocities.** Measurement noise (std per axis) on what the planner observes, process
  noise on what the AGVs do, a known input (the applied acceleration): the linear-Gaussian case, where
  the Kalman filter is the optimal estimate. One covariance serves every AGV and axis-pair (the same
  noise levels), so the filter costs a few 4 x 4 products per slot.
"""

from __future__ import annotations

import numpy as np

from lawn_env import dynamics
from lawn_env.config import ScenarioConfig
from lawn_env.dynamics import ACCELERATION
from lawn_env.products import matmul, solve

__all__ = ["AGVTracker"]


class AGVTracker:
    """The planner's running estimate of every AGV's state: :meth:`state` takes each slot's observed
    x~ (K, 6), in order from the episode's start, and returns x~ with filtered positions and
    velocities, and, with ``lag``, the applied acceleration appended (K, 8). ``filter`` and ``lag``
    off return x~ unchanged."""

    def __init__(self, config: ScenarioConfig, lag: bool, filter: bool):
        d = config.disturbance
        self.num_agvs = config.num_agvs
        self.lag_alpha = dynamics.lag_alpha(config.slot_s, d.actuator_lag_s) if lag and d.actuator_lag_s > 0 else None
        noise = (d.measurement_noise_position_m, d.measurement_noise_velocity_mps)
        self.filtering = filter and max(noise) > 0
        self._a_aug, self._b_aug = dynamics.augmented_matrices(config.slot_s)
        self._f = self._a_aug[0:4, 0:4]  # [p, v] <- [p, v]: the covariance's transition
        pos, vel = (d.process_noise_position_m, d.process_noise_velocity_mps)
        self._q = np.diag([pos**2, pos**2, vel**2, vel**2])
        self._r = np.diag([noise[0] ** 2, noise[0] ** 2, noise[1] ** 2, noise[1] ** 2])
        self.reset()

    def reset(self) -> None:
        self.applied = np.zeros((self.num_agvs, 2))
        self.estimate: np.ndarray | None = None  # filtered [p, v] (K, 4)
        self.covariance = self._r.copy()

    def state(self, x_aug: np.ndarray) -> np.ndarray:
        x_aug = np.array(x_aug, dtype=float)
        commanded = x_aug[:, ACCELERATION]  # u[n-1]: what the AGV was told in the slot before
        moved = commanded if self.lag_alpha is None else dynamics.lagged_acceleration(self.applied, commanded,
                                                                                        self.lag_alpha)
        if self.filtering:
            x_aug[:, 0:4] = self._filter(x_aug[:, 0:4], moved)
        self.applied = moved
        if self.lag_alpha is None:
            return x_aug
        return np.concatenate([x_aug, self.applied], axis=1)

    def _filter(self, measured: np.ndarray, moved: np.ndarray) -> np.ndarray:
        """One Kalman step: predict the last estimate through the slot with the acceleration the AGVs
        applied, then correct with this slot's measurement (the first slot: the measurement)."""
        if self.estimate is None:
            self.estimate = measured.copy()
            return self.estimate
        f = self._f
        moving = np.concatenate([self.estimate, moved], axis=1)  # [p, v] and the acceleration they moved with
        predicted = dynamics.step_augmented(moving, np.zeros_like(moved), self._a_aug, self._b_aug)[:, 0:4]
        prior = matmul(matmul(f, self.covariance), f.T) + self._q
        gain = solve(prior + self._r + 1e-12 * np.eye(4), prior).T  # P (P + R)^-1, P and R symmetric
        self.covariance = matmul(np.eye(4) - gain, prior)
        self.estimate = predicted + matmul(measured - predicted, gain.T)
        return self.estimate
