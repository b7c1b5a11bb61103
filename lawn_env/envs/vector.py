"""Native vector environments: ``gym.make_vec("lawn/Joint-v0", num_envs=N,
vectorization_mode="vector_entry_point")`` and the same for ``lawn/Comm-v0``.

One :class:`~lawn_env.batch.BatchSimulation` advances all N scenarios per call, through the
slot functions every lawn env shares, instead of N Python-level env copies. Conventions are
Gymnasium's vector ones (as ``CartPoleVectorEnv``):

* batched spaces (``single_observation_space``, ``single_action_space`` are the single env's);
* next-step autoreset (the default): the step after an episode ends resets that scenario and
  returns its first observation with reward 0 and both flags False (its action is ignored);
  ``autoreset_mode="SameStep"`` resets it within the step that ends it instead, returning the
  new first observation and the final one in ``info["final_obs"]`` (mask ``_final_obs``);
* ``reset(seed=s)`` seeds scenario i from ``s + i`` (as ``SyncVectorEnv`` seeds its copies), so
  its references and initial state equal ``gym.make(...).reset(seed=s + i)``'s; a list of N
  seeds sets them one by one. The fading of all scenarios comes from one batched generator,
  seeded from ``s``;
* ``info`` holds arrays with a leading N axis for every key of the single env's info
  (``lawn_env.envs.base.INFO_KEYS``), and ``episode_control_cost`` with its mask
  ``_episode_control_cost`` on the step an episode ends.

``lawn/Comm-v0``'s N x K outage-aware MPC QPs of a step are solved together
(:class:`CommVectorEnv`); its info adds ``mpc_iterations`` (N, K),
``mpc_fallbacks`` (N,) and ``success_probability_planned`` (N, K) as the single env's does.

``render_mode="rgb_array"`` draws env ``render_env`` (default 0) as the single env draws itself.
``interface=`` takes the single envs' RL interface (:mod:`lawn_env.interface`; ``"rl"`` is
``lawn/JointRL-v0`` and ``lawn/CommRL-v0``): anchored actions decoded for the whole batch (the
Joint anchor's MPC solved by the batched QP solver), the scaled reward, termination with its
penalty, clipped observations. The disturbance mode runs as in the single env (wind on the drone,
a reduced control rate, actuator lag, process and measurement noise); its per-slot draws come
from the batched generator like the fading.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from ..batch import BatchSimulation
from ..channel import LinkParams
from ..core import link_success
from ..interface import ActionLayout, resolve_interface
from ..mpc import DEFAULT_BACKEND, OutageAwareMPC
from ..presets import ConfigLike, resolve_config
from ..spaces import ObservationLayout, check_action

__all__ = ["CommVectorEnv", "JointVectorEnv"]


class JointVectorEnv(VectorEnv):
    """N copies of ``lawn/Joint-v0`` (any interface) in one batched simulation."""

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": ["rgb_array"], "render_fps": 4}
    role = "joint"

    def __init__(self, num_envs: int, config: ConfigLike = None,
                 render_mode: str | None = None, interface: Any = None,
                 autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP, render_env: int = 0,
                 **overrides: Any):
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode={render_mode!r}; valid: 'rgb_array' (one env, render_env) or None")
        self.interface = resolve_interface(interface)
        modes = {m.value: m for m in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP)}
        mode = modes.get(autoreset_mode.value if isinstance(autoreset_mode, AutoresetMode) else autoreset_mode)
        if mode is None:
            raise ValueError(f"autoreset_mode={autoreset_mode!r}; valid: {', '.join(modes)}")
        self.metadata = dict(self.metadata, autoreset_mode=mode)
        self.config = resolve_config(config, **overrides)
        self.sim = BatchSimulation(self.config, num_envs)
        self.num_envs = self.sim.num_envs
        if not (isinstance(render_env, (int, np.integer)) and 0 <= render_env < self.num_envs):
            raise ValueError(f"render_env={render_env!r}: the index of the env to render, in [0, {self.num_envs - 1}]")
        self.render_mode = render_mode
        self.render_env = int(render_env)
        self._view = _EnvView(self.sim, self.render_env) if render_mode else None
        self._renderer = None
        self.layout = ObservationLayout(self.config)
        k = self.config.num_agvs
        self.num_agvs = k
        self.single_observation_space = self.interface.observation_space(self.layout.size)
        self.actions = ActionLayout(self.config, self.role, self.interface)
        self.single_action_space = self.actions.space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._rngs: list[np.random.Generator] = []
        self._done = np.zeros(self.num_envs, dtype=bool)
        self._cost = np.zeros(self.num_envs)
        self._started = False

    # ------------------------------------------------------------------ fading (tests inject draws here)
    def _draw_fading(self) -> np.ndarray:
        """m|h|^2 of every link of every scenario for this slot, (N, K), from the batched generator."""
        return self.np_random.standard_gamma(self.sim.single.link.m, (self.num_envs, self.num_agvs))

    def _draw_noise(self) -> dict:
        """The disturbance mode's other draws of this slot (gust, process and measurement noise;
        :meth:`BatchSimulation.noise_shapes`), from the batched generator; empty without it."""
        return {name: self.np_random.normal(0.0, std, shape) for name, (shape, std) in self.sim.noise_shapes().items()}

    # ------------------------------------------------------------------ API
    def reset(self, *, seed: int | list[int] | None = None,
              options: dict | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        if isinstance(seed, (list, tuple)):
            if len(seed) != self.num_envs:
                raise ValueError(f"seed: a list of {len(seed)} seeds for {self.num_envs} envs")
            seeds = [int(s) for s in seed]
            super().reset(seed=seeds[0])
        else:
            super().reset(seed=seed)
            base = seed if seed is not None else int(self.np_random.integers(2**62))
            seeds = [base + i for i in range(self.num_envs)]
        self._rngs = [np.random.default_rng(s) for s in seeds]  # = gymnasium's seeding.np_random(s)
        self.sim.reset(self._rngs)
        self._on_reset()
        if self._view is not None:
            self._view.restart()
        self._done[:] = False
        self._cost[:] = 0.0
        self._started = True
        return self._observe(), dict(self._info(), **self._extra_reset_info())

    def _on_reset(self) -> None:
        """A new batch of episodes starts (the anchored actions' MPC forgets its warm starts)."""
        self.actions.reset()

    def _observe(self) -> np.ndarray:
        return self.layout.encode_batch(self.sim, bound=self.interface.obs_bound)

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        if not self._started:
            raise RuntimeError("call reset() before step()")
        a = check_action(actions, self.single_action_space.shape[0], "action", self.num_envs)
        sim = self.sim
        increment, power, drone_next, extra = self._decide(a)
        same_step = self.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
        restart = np.zeros(self.num_envs, dtype=bool) if same_step else self._done.copy()
        record = sim.step(increment, power, drone_next, self._draw_fading(), self._draw_noise())
        cost_tracking = record["tracking_cost"].sum(axis=1)
        cost_effort = record["effort_cost"].sum(axis=1)
        applied = record["applied_increment"].copy()
        if self._view is not None:
            self._view.record()
        if restart.any():  # next-step autoreset: these scenarios start over; their action was ignored
            self._restart(restart)
            cost_tracking[restart] = cost_effort[restart] = 0.0
            applied[restart] = 0.0
        cost = cost_tracking + cost_effort
        self._cost += cost
        iface = self.interface
        reward = iface.rewards_from_costs(cost)
        terminated = iface.terminates_batch(sim.tracking_error[..., 0:2]) & ~restart
        if terminated.any():  # the reward floor of every slot not played (RL interface)
            reward[terminated] += iface.terminal_penalties(sim.num_slots - sim.slot[terminated])
        reward[restart] = 0.0
        truncated = (sim.slot >= sim.num_slots) & ~terminated
        info = self._info(cost_tracking, cost_effort, applied)  # restarted rows describe their new episode
        if extra:
            if restart.any():  # restarted rows describe their new episode here too
                fresh = self._extra_reset_info()
                extra = {key: np.where(restart.reshape((-1,) + (1,) * (v.ndim - 1)), fresh[key], v)
                         for key, v in extra.items()}
            info.update(extra)
        ended = truncated | terminated
        info["episode_control_cost"] = np.where(ended, self._cost, 0.0)
        info["_episode_control_cost"] = ended
        self._cost[ended] = 0.0
        self._done = ended.copy()  # info holds ended itself
        obs = self._observe()
        if same_step and ended.any():  # same-step autoreset: the final observation goes to info
            info["final_obs"] = obs
            info["_final_obs"] = ended
            self._restart(ended)  # info keeps describing the step that ended them
            obs = self._observe()
            self._done = np.zeros(self.num_envs, dtype=bool)
        return obs, reward, terminated, truncated, info

    # ------------------------------------------------------------------ the role's decisions
    def _decide(self, a: np.ndarray):
        """Increments (N, K, 2), powers (N, K), next drone positions (N, 2) and the role's extra
        info for a batch of checked actions."""
        d = self._decisions(a)
        return d.increment, d.power_w, d.drone_next, {}

    def _decisions(self, a: np.ndarray):
        """The actions decoded under the env's action scheme (:meth:`ActionLayout.decode`)."""
        sim = self.sim
        windows = sim.reference_windows() if self.actions.needs_reference else None  # the anchor plans or tracks
        return self.actions.decode(a, sim.x_obs, windows, sim.drone_position, sim.slot)

    def _extra_reset_info(self) -> dict:
        return {}

    def _restart(self, which: np.ndarray) -> None:
        """New episodes for the envs ``which`` (autoreset), each from its own generator."""
        self.sim.reset(self._rngs, which)
        self.actions.reset(which)
        if self._view is not None and which[self.render_env]:
            self._view.restart()

    def render(self) -> np.ndarray | None:
        """An RGB frame (H, W, 3) of env ``render_env``: area, references, trails, links colored by
        outage probability, as the single env draws it."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array'")
            return None
        if not self._started:
            raise RuntimeError("call reset() before render()")
        if self._renderer is None:
            from ..render import Renderer

            self._renderer = Renderer(self.config)
        return self._renderer.draw(self._view)

    def close_extras(self, **kwargs: Any) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def _info(self, cost_tracking=None, cost_effort=None, applied=None) -> dict:
        """The single env's info keys (``INFO_KEYS``) with a leading env axis; zero costs and
        increments at reset."""
        sim, b = self.sim, self.num_envs
        tracking = np.zeros(b) if cost_tracking is None else cost_tracking
        effort = np.zeros(b) if cost_effort is None else cost_effort
        return {
            "slot": sim.slot.copy(),
            "stage_cost": tracking + effort,
            "reward_tracking": -tracking,
            "reward_effort": -effort,
            "delivered": sim.last_delivered.copy(),
            "outage_probability": np.array(sim.last_outage_probability, dtype=np.float64),
            "power_w": np.array(sim.last_power_w, dtype=np.float64),
            "drone_position": np.array(sim.drone_position, dtype=np.float64),
            "applied_increment": np.zeros((b, self.num_agvs, 2)) if applied is None else np.array(applied),
        }


class CommVectorEnv(JointVectorEnv):
    """N copies of ``lawn/Comm-v0`` (any interface) in one batched simulation: the actions set
    powers and the drone, and the N x K outage-aware MPC QPs of a step are solved together
    (the compiled solver of :mod:`lawn_env.qp`, warm-started per scenario; problems it cannot
    settle go to DAQP one by one and are counted in ``info["mpc_fallbacks"]``). ``qp_backend``
    names a reference backend instead (``"daqp"``, ``"osqp"``, ``"qpsolvers:<name>"``: one QP at a
    time through Python)."""

    role = "comm"

    def __init__(self, num_envs: int, config: ConfigLike = None,
                 render_mode: str | None = None, interface: Any = None, qp_backend: str = DEFAULT_BACKEND,
                 autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP, render_env: int = 0,
                 **overrides: Any):
        super().__init__(num_envs, config, render_mode, interface, autoreset_mode, render_env, **overrides)
        self.mpc = OutageAwareMPC.from_config(self.config, backend=qp_backend)
        self._planning_link = LinkParams.from_config(self.config, planning=True)
        self.last_mpc_solve_time_s = float("nan")

    def _on_reset(self) -> None:
        super()._on_reset()
        self.mpc.reset()

    def _restart(self, which: np.ndarray) -> None:
        super()._restart(which)
        self.mpc.reset(which)  # a new episode starts without the old one's warm starts

    def _decide(self, a: np.ndarray):
        sim = self.sim
        _, power, drone_next = self._decisions(a)
        psi = link_success(sim.x_aug, drone_next, power, self._planning_link)
        solution = self.mpc.solve(sim.x_aug, sim.reference_windows(), psi, sim.slot)
        increments, iterations, status = solution.increments[:, :, 0, :], solution.iterations, solution.status
        self.last_mpc_solve_time_s = solution.solve_time_s
        extra = {"mpc_iterations": iterations.astype(np.int64),
                 "mpc_fallbacks": np.count_nonzero(status, axis=1).astype(np.int64),
                 "success_probability_planned": np.asarray(psi, dtype=np.float64)}
        return increments, power, drone_next, extra

    def _extra_reset_info(self) -> dict:
        sim = self.sim
        return {"mpc_iterations": np.zeros((self.num_envs, self.num_agvs), dtype=np.int64),
                "mpc_fallbacks": np.zeros(self.num_envs, dtype=np.int64),
                "success_probability_planned": link_success(sim.x_aug, sim.drone_position, sim.last_power_w,
                                                            self._planning_link)}


class _EnvView:
    """One env of a batch as :mod:`lawn_env.render` reads a ``Simulation``: its state, references
    and the trails of its current episode (recorded only for this env)."""

    def __init__(self, bsim: BatchSimulation, index: int):
        self.bsim, self.i = bsim, index
        s = bsim.single
        self.area, self.num_agvs, self.num_slots = s.area, s.num_agvs, s.num_slots
        self._drone: list[np.ndarray] = []
        self._agv: list[np.ndarray] = []

    def restart(self) -> None:
        self._drone, self._agv = [], []
        self.record()

    def record(self) -> None:
        self._drone.append(self.drone_position.copy())
        self._agv.append(self.x_aug[:, 0:2].copy())

    _ROWS = ("reference", "x_aug", "drone_position", "last_outage_probability")

    def __getattr__(self, name: str):  # the batch's arrays, row i
        if name in _EnvView._ROWS:
            return getattr(self.bsim, name)[self.i]
        raise AttributeError(name)

    @property
    def slot(self) -> int:
        return int(self.bsim.slot[self.i])

    def trajectories(self) -> dict:
        return {"drone_position": np.array(self._drone), "agv_position": np.array(self._agv)}
