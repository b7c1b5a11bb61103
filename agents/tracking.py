"""Fixed-gain tracking laws of the predictive PID and LQR baselines (MODEL.md §5).

Both are rolled out over the MPC horizon on the nominal model (every command delivered) to give
the "predicted inputs over the horizon" that the power and drone blocks then optimize against;
the first increment is the one sent. Every increment is saturated into the control set:
``|Delta-u| <= Delta-a_max`` and ``|u| <= a_max`` per axis. With a control period (MODEL.md §7),
``commands`` (:func:`lawn_env.dynamics.command_mask`) marks the horizon slots where a command
goes out; in between the law is not applied and the AGV holds its acceleration (increment 0).
"""

from __future__ import annotations

import numpy as np
from pydantic import ConfigDict
from pydantic.dataclasses import dataclass as pydantic_dataclass

from lawn_env.dynamics import ACCELERATION, POSITION, VELOCITY, PredictionModel, step_augmented
from lawn_env.errors import raises_config_errors
from lawn_env.products import matmul

__all__ = ["PIDGains", "saturate", "pid_rollout", "lqr_gain", "lqr_rollout"]


@raises_config_errors("gains.", "gain")
@pydantic_dataclass(frozen=True, config=ConfigDict(extra="forbid", allow_inf_nan=False))
class PIDGains:
    """Gains of the predictive PID (per axis, SI units). Defaults from the grid search of
    ``benchmarks/tune_pid.py`` (closed-loop control cost with perfect links): the best gains with a
    non-zero integral term, so that the baseline is the PID the paper names (``python benchmarks/tune_pid.py``
    prints the grid, whose overall best has ki = 0)."""

    kp: float = 0.3
    ki: float = 0.02
    kd: float = 0.6
    integral_limit: float = 10.0


def saturate(u_desired: np.ndarray, u_prev: np.ndarray, accel_max: float, accel_increment_max: float) -> np.ndarray:
    """The increment that moves u[n-1] toward ``u_desired`` inside the control set."""
    u = np.clip(u_desired, -accel_max, accel_max)
    increment: np.ndarray = np.clip(u - u_prev, -accel_increment_max, accel_increment_max)
    return increment


def pid_rollout(x_aug: np.ndarray, reference: np.ndarray, integral: np.ndarray, model: PredictionModel,
                gains: PIDGains, accel_max: float, accel_increment_max: float,
                commands: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """PID per axis on the position error with velocity and acceleration feed-forward:
    ``u[i] = a_ref[i+1] + k_p e_p + k_i I + k_d e_v`` (``e_v`` is the velocity error, the
    derivative of the position error; ``a_ref[i+1]`` is the reference acceleration the cost
    compares u[i] with, since the augmented state at i+1 carries u[i]). ``gains`` carries
    ``kp``, ``ki``, ``kd`` and the integral's clamp ``integral_limit`` (:class:`PIDGains`).
    Returns the increments (K, N_p, 2) and the integral after the first step.
    """
    kp, ki, kd, integral_limit = gains.kp, gains.ki, gains.kd, gains.integral_limit
    dt = model.slot_s
    x = x_aug.copy()
    integ = integral.copy()
    out = np.empty((x.shape[0], model.horizon, 2))
    first_integral: np.ndarray | None = None
    for i in range(model.horizon):
        ref = reference[:, i]
        e_pos = ref[:, POSITION] - x[:, POSITION]
        integ = np.clip(integ + e_pos * dt, -integral_limit, integral_limit)
        if first_integral is None:
            first_integral = integ.copy()
        u = reference[:, i + 1, ACCELERATION] + kp * e_pos + ki * integ + kd * (ref[:, VELOCITY] - x[:, VELOCITY])
        du = saturate(u, x[:, ACCELERATION], accel_max, accel_increment_max)
        if commands is not None and not commands[i]:
            du = np.zeros_like(du)
        out[:, i] = du
        x = step_augmented(x, du, model.a_aug, model.b_aug)
    assert first_integral is not None  # the horizon has at least one step
    return out, first_integral


def lqr_gain(model: PredictionModel) -> np.ndarray:
    """The infinite-horizon LQR gain of the model (:attr:`lawn_env.dynamics.PredictionModel.lqr_gain`), 2 x 6."""
    return model.lqr_gain


def lqr_rollout(x_aug: np.ndarray, reference: np.ndarray, model: PredictionModel, gain: np.ndarray,
                accel_max: float, accel_increment_max: float, commands: np.ndarray | None = None) -> np.ndarray:
    """``Delta-u[i] = Delta-u_ref[i] - K (x~[i] - x~_ref[i])``, saturated, over the horizon:
    increments (K, N_p, 2). ``Delta-u_ref[i] = a_ref[i+1] - a_ref[i]`` is the reference's own
    increment (feed-forward), so that a reference the AGV sits on is followed exactly."""
    x = x_aug.copy()
    out = np.empty((x.shape[0], model.horizon, 2))
    for i in range(model.horizon):
        feedforward = reference[:, i + 1, ACCELERATION] - reference[:, i, ACCELERATION]
        du_free = feedforward - matmul(x - reference[:, i], gain.T)
        du = saturate(x[:, ACCELERATION] + du_free, x[:, ACCELERATION], accel_max, accel_increment_max)
        if commands is not None and not commands[i]:
            du = np.zeros_like(du)
        out[:, i] = du
        x = step_augmented(x, du, model.a_aug, model.b_aug)
    return out
