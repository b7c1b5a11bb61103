"""What the central environments share: config resolution, spaces, reset, info, render."""

from __future__ import annotations

import dataclasses
from typing import Any

import gymnasium as gym
import numpy as np

from ..core import Simulation, Snapshot
from ..interface import V0_INTERFACE, ActionLayout, InterfaceLike, RLInterface, resolve_interface
from ..presets import ConfigLike, resolve_config
from ..spaces import ObservationLayout

__all__ = ["SimulationView", "LawnEnvBase", "INFO_KEYS", "COMM_INFO_KEYS", "slot_info"]


#: The info keys every step and reset of the central environments (and the parallel env's "drone")
#: carry, with fixed shapes and numpy dtypes; ``lawn/Comm-v0`` adds its MPC's keys
#: (``COMM_INFO_KEYS``); the last step alone adds ``episode_metrics`` (a dict of MODEL.md §6).
INFO_KEYS = ("slot", "stage_cost", "reward_tracking", "reward_effort", "delivered",
             "outage_probability", "power_w", "drone_position", "applied_increment")
COMM_INFO_KEYS = ("mpc_iterations", "mpc_fallbacks", "success_probability_planned")


def slot_info(slot: int, cost_tracking: float, cost_effort: float, delivered: np.ndarray,
              outage_probability: np.ndarray, power_w: np.ndarray, drone_position: np.ndarray,
              applied_increment: np.ndarray) -> dict[str, Any]:
    """One slot's info dict (``INFO_KEYS``, flat: TorchRL's readers turn every value into a tensor):
    ``slot`` int64, ``stage_cost`` and its split ``reward_tracking`` + ``reward_effort`` (negated)
    float64, ``delivered`` (K,) bool,
    ``outage_probability`` and ``power_w`` (K,) float64, ``drone_position`` (2,), ``applied_increment``
    (K, 2) float64."""
    tracking, effort = -float(cost_tracking), -float(cost_effort)
    return {
        "slot": np.int64(slot),
        "stage_cost": np.float64(float(cost_tracking) + float(cost_effort)),
        "reward_tracking": np.float64(tracking),
        "reward_effort": np.float64(effort),
        "delivered": np.asarray(delivered, dtype=bool),
        "outage_probability": np.asarray(outage_probability, dtype=np.float64),
        "power_w": np.asarray(power_w, dtype=np.float64),
        "drone_position": np.asarray(drone_position, dtype=np.float64),
        "applied_increment": np.asarray(applied_increment, dtype=np.float64),
    }


class SimulationView:
    """What every view of a :class:`~lawn_env.core.Simulation` shares (the Gymnasium envs and the
    PettingZoo env): config resolution, the core, the observation layout, snapshot, render, close."""

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 4}

    def _setup_view(self, config, render_mode, overrides, interface=None, role: str = "joint") -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode={render_mode!r}; valid: {self.metadata['render_modes']} or None")
        self.config = resolve_config(config, **overrides)
        self.render_mode = render_mode
        self.sim = Simulation(self.config)
        self.layout = ObservationLayout(self.config)
        self.interface: RLInterface = resolve_interface(interface)
        self.actions = ActionLayout(self.config, role, self.interface)
        self._plain = self.interface == V0_INTERFACE
        self._renderer = None

    def _decide(self, action: np.ndarray):
        """The slot's physical decisions (:class:`~lawn_env.interface.Decision`) for a checked action."""
        sim = self.sim
        return self.actions.decode(action, sim.x_obs, sim.reference_window(), sim.drone_position, sim.slot)

    def _rewards_and_termination(self, costs) -> tuple[list[float], bool]:
        """Rewards for the given stage costs and whether the episode terminates (RL interface),
        the terminal penalty included in every reward of a terminating step."""
        iface, sim = self.interface, self.sim
        rewards = [iface.reward_from_cost(c) for c in costs]
        terminated = iface.terminates(sim.tracking_error[:, 0:2])
        if terminated:
            penalty = iface.terminal_penalty(sim.num_slots - sim.slot)
            rewards = [r + penalty for r in rewards]
        return rewards, terminated

    def snapshot(self) -> Snapshot:
        """Full system state for external planners (see :class:`lawn_env.core.Snapshot`)."""
        if self.sim.x_aug is None:
            raise RuntimeError("call reset() before snapshot()")
        return self.sim.snapshot()

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array' or 'human'")
            return None
        if self.sim.x_aug is None:
            raise RuntimeError("call reset() before render()")
        if self._renderer is None:
            from ..render import Renderer

            self._renderer = Renderer(self.config, human=self.render_mode == "human")
        return self._renderer.draw(self.sim)

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


class LawnEnvBase(SimulationView, gym.Env):
    """Common machinery of ``lawn/Joint-v0`` and ``lawn/Comm-v0`` (not registered itself)."""

    role = "joint"

    def __init__(self, config: ConfigLike = None, render_mode: str | None = None,
                 interface: InterfaceLike = None, **overrides: Any):
        self._setup_view(config, render_mode, overrides, interface, self.role)
        self.num_agvs = self.config.num_agvs
        self.observation_space = self.interface.observation_space(self.layout.size)
        self.action_space = self.actions.space
        self._done = True

    # ------------------------------------------------------------------ gym API
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

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        # ``options`` is accepted for API compatibility (PettingZoo's test passes some); none is used.
        self.sim.reset(self.np_random)
        self.actions.reset()
        self._done = False
        self._on_reset()
        if self.render_mode == "human":
            self.render()
        sim = self.sim
        k = sim.num_agvs
        info = slot_info(sim.slot, 0.0, 0.0, sim.last_delivered, sim.last_outage_probability, sim.last_power_w,
                         sim.drone_position, np.zeros((k, 2)))
        info.update(self._extra_reset_info())
        return self.interface.observe(self.layout.encode(sim)), info

    def _extra_reset_info(self) -> dict:
        """The env-specific info keys at reset, with the shapes and dtypes ``step`` gives them."""
        return {}

    def _on_reset(self) -> None:
        """Hook for subclasses (e.g. solver workspaces)."""

    def _check_running(self) -> None:
        if self._done:
            raise RuntimeError("the episode has ended (or reset() was never called); call reset() before step()")

    def _finish_step(self, record, extra: dict | None = None):
        cost_tracking = sum(record.tracking_cost.tolist())  # tolist + sum: cheaper than ndarray.sum for small K
        cost_effort = sum(record.effort_cost.tolist())
        cost = cost_tracking + cost_effort
        info = slot_info(self.sim.slot, cost_tracking, cost_effort, record.delivered, record.outage_probability,
                         record.power_w, record.drone_position, record.applied_increment)
        if extra:
            info.update(extra)
        sim = self.sim
        if self._plain:  # the benchmark's hot path
            reward, terminated = -cost, False
        else:
            (reward,), terminated = self._rewards_and_termination([cost])
        truncated = sim.slot >= sim.num_slots and not terminated
        if truncated or terminated:
            self._done = True
            info["episode_metrics"] = self.sim.episode_metrics()
        if self.render_mode == "human":
            self.render()
        return self.interface.observe(self.layout.encode(self.sim)), reward, terminated, truncated, info

    # ------------------------------------------------------------------ extras
    def episode_metrics(self) -> dict:
        return self.sim.episode_metrics()
