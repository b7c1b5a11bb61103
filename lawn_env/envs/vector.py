"""Native vector environments: ``gym.make_vec("lawn/Joint-v1", num_envs=N,
vectorization_mode="vector_entry_point")`` and the same for ``lawn/Comm-v1``.

One :class:`~lawn_env.envs.base.Engine` of N scenarios, the step template of the single envs
(their B = 1 views), advances all N per call instead of N Python-level env copies. Conventions are
Gymnasium's vector ones (as ``CartPoleVectorEnv``):

* batched spaces (``single_observation_space``, ``single_action_space`` are the single env's);
* next-step autoreset (the default): the step after an episode ends resets that scenario and
  returns its first observation with reward 0 and both flags False (its action is ignored);
  ``autoreset_mode="SameStep"`` resets it within the step that ends it instead, returning the
  new first observation and the final one in ``info["final_obs"]`` (mask ``_final_obs``);
* ``reset(seed=s)`` seeds scenario i from ``s + i`` (as ``SyncVectorEnv`` seeds its copies), so
  its references and initial state equal ``gym.make(...).reset(seed=s + i)``'s; a list of N
  seeds sets them one by one; ``reset()`` without a seed continues every scenario's generator, as
  the single env's ``reset()`` does. Each slot's randomness for all N scenarios
  (:func:`lawn_env.core.draw_slot`) comes from scenario 0's generator, the env's ``np_random``:
  with N = 1 an episode is bitwise the single env's with the same seed and actions. With independent
  draws each scenario draws its slot's randomness from its own generator, as its
  single env does: scenario i's episode is then bitwise ``gym.make(...)``'s with seed ``s + i`` and the
  same actions, whatever N (what evaluation plays seeds in lockstep with; a few microseconds a scenario
  more per step). ``reset(options={"independent_draws": True})`` sets it for the episodes that reset
  starts and their autoresets (a reset without it goes back to the shared generator);
* ``info`` holds arrays with a leading N axis for every key of the single env's info
  (``lawn_env.envs.base.INFO_KEYS``); on the step an episode ends, ``episode_metrics`` (an object
  array of N, the single env's dict where an episode ended, else None) with its mask
  ``_episode_metrics``, and ``episode_control_cost`` with its mask ``_episode_control_cost``.

``lawn/Comm-v1``'s N x K outage-aware MPC QPs of a step are solved together
(:class:`CommVectorEnv`); its info adds ``mpc_iterations`` (N, K),
``mpc_fallbacks`` (N,) and ``success_probability_planned`` (N, K) as the single env's does.

``render_mode="rgb_array"`` draws env ``render_env`` (default 0) as the single env draws itself.
``interface=`` takes the single envs' RL interface (:mod:`lawn_env.interface`; ``"rl"`` is
``lawn/JointRL-v1`` and ``lawn/CommRL-v1``): anchored actions decoded for the whole batch (the
Joint anchor's MPC solved by the batched QP solver), the scaled reward, termination with its
penalty, clipped observations. The disturbance mode runs as in the single env (wind on the drone,
a reduced control rate, actuator lag, process and measurement noise); its per-slot draws come
with the fading, in :func:`lawn_env.core.draw_slot`'s order.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from ..core import SlotDraws, control_costs, draw_slot
from ..interface import InterfaceLike
from ..mpc import DEFAULT_BACKEND
from ..presets import ConfigLike, resolve_config
from .base import Engine, EngineAccess, Observation

__all__ = ["CommVectorEnv", "JointVectorEnv"]


def _independent_draws(options: dict[str, Any] | None) -> bool:
    """The ``independent_draws`` option of a reset (False when absent). ``reset_mask`` (Gymnasium's partial
    reset, for envs without autoreset) is refused: these envs autoreset; the other options are ignored."""
    if options and "reset_mask" in options:
        raise ValueError("options['reset_mask']: partial resets are not supported; these envs reset an ended "
                         "scenario themselves (autoreset_mode 'NextStep' or 'SameStep')")
    value = (options or {}).get("independent_draws", False)
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"options['independent_draws']={value!r}: must be True or False")
    return bool(value)


class JointVectorEnv(EngineAccess, VectorEnv):
    """N copies of ``lawn/Joint-v1`` (any interface) in one engine."""

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": ["rgb_array"], "render_fps": 4}
    role = "joint"

    def __init__(self, num_envs: int, config: ConfigLike = None,
                 render_mode: str | None = None, interface: InterfaceLike = None,
                 autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP, render_env: int = 0,
                 qp_backend: str = DEFAULT_BACKEND, **overrides: Any):
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode={render_mode!r}; valid: 'rgb_array' (one env, render_env) or None")
        modes = {m.value: m for m in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP)}
        mode = modes.get(autoreset_mode.value if isinstance(autoreset_mode, AutoresetMode) else autoreset_mode)
        if mode is None:
            raise ValueError(f"autoreset_mode={autoreset_mode!r}; valid: {', '.join(modes)}")
        self.metadata = dict(self.metadata, autoreset_mode=mode)
        self.config = resolve_config(config, **overrides)
        self.engine = Engine(self.config, self.role, interface, num_envs, qp_backend, trail_row=None)
        self.sim = self.engine.sim
        if not (isinstance(render_env, (int, np.integer)) and 0 <= render_env < self.sim.num_envs):
            last = self.sim.num_envs - 1
            raise ValueError(f"render_env={render_env!r}: the index of the env to render, in [0, {last}]")
        if render_mode:
            self.engine.keep_trail(int(render_env))
        self.interface, self.layout, self.actions = self.engine.interface, self.engine.layout, self.engine.actions
        self.num_envs = self.sim.num_envs
        self.render_mode = render_mode
        self.render_env = int(render_env)
        self.num_agvs = self.config.num_agvs
        self.single_observation_space = self.engine.observation_space
        self.single_action_space = self.engine.action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.independent_draws = False  # reset(options={"independent_draws": True})
        self._rngs: list[np.random.Generator] = []
        self._done = np.zeros(self.num_envs, dtype=bool)
        self._started = False

    # ------------------------------------------------------------------ randomness (tests inject draws here)
    def _draw(self) -> SlotDraws:
        """This slot's randomness for every scenario, from the env's generator (scenario 0's)."""
        return self.sim.draw(self.np_random)

    def _draw_each(self, active: np.ndarray | None) -> SlotDraws:
        """This slot's randomness for each scenario from its own generator (``independent_draws``): the
        scenarios ``active`` alone (a single env draws nothing on the step that restarts it; the others'
        entries are zeros)."""
        rows = range(self.num_envs) if active is None else np.flatnonzero(active).tolist()
        drawn = {i: draw_slot(self._rngs[i], self.sim.params, 1) for i in rows}
        first = next(iter(drawn.values()))
        fields: list[np.ndarray | None] = []
        for j, value in enumerate(first):
            if value is None:
                fields.append(None)
                continue
            stacked = np.zeros((self.num_envs, *value.shape[1:]))
            for i, draws in drawn.items():
                stacked[i] = draws[j][0]  # type: ignore[index]  # present in every scenario's draws as in the first's
            fields.append(stacked)
        return SlotDraws(*fields)  # type: ignore[arg-type]  # the fading is always drawn

    # ------------------------------------------------------------------ API
    def reset(self, *, seed: int | list[int] | None = None,
              options: dict[str, Any] | None = None) -> tuple[Observation, dict[str, Any]]:
        independent = _independent_draws(options)
        if isinstance(seed, (list, tuple)):
            if len(seed) != self.num_envs:
                raise ValueError(f"seed: a list of {len(seed)} seeds for {self.num_envs} envs")
            seeds = [int(s) for s in seed]
        elif seed is not None:
            seeds = [int(seed) + i for i in range(self.num_envs)]
        else:
            seeds = None
        if seeds is not None:  # scenario 0's generator is the env's own (= gymnasium's seeding.np_random(s))
            super().reset(seed=seeds[0])
            self._rngs = [self.np_random] + [np.random.default_rng(s) for s in seeds[1:]]
        self.independent_draws = independent
        if seeds is None and not self._rngs:  # never seeded: the OS's entropy, through the env's generator
            self._rngs = [self.np_random] + [np.random.default_rng(int(self.np_random.integers(2**62)))
                                             for _ in range(self.num_envs - 1)]
        self.engine.reset(self._rngs)
        self._done[:] = False
        self._started = True
        return self.engine.observe(), self.engine.info()

    def step(self, actions: np.ndarray) -> tuple[Observation, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        if not self._started:
            raise RuntimeError("call reset() before step()")
        engine, sim = self.engine, self.sim
        a = engine.check(actions)
        same_step = self.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
        restart = np.zeros(self.num_envs, dtype=bool) if same_step else self._done.copy()
        zeros = np.zeros(self.num_envs, dtype=bool)
        if restart.any():  # next-step autoreset: new episodes first, from their generators; their action is ignored
            self._restart(restart)
        if restart.all():  # no slot this step: every scenario is at its first observation
            self._done = zeros
            return engine.observe(), np.zeros(self.num_envs), zeros, zeros.copy(), engine.info()
        active = ~restart if restart.any() else None
        draws = self._draw_each(active) if self.independent_draws else self._draw()
        result = engine.step(a, draws, active=active)
        record, reward, terminated, truncated = result.record, result.reward[:, 0], result.terminated, result.truncated
        ended = truncated | terminated
        info = engine.info(record, result.extra)
        if restart.any():  # restarted rows describe their new episode
            fresh = engine.info()
            for key, value in fresh.items():
                info[key] = np.where(restart.reshape((-1,) + (1,) * (value.ndim - 1)), value, info[key])
        if ended.any():
            metrics = np.full(self.num_envs, None, dtype=object)
            rows = np.flatnonzero(ended)
            for i, values in zip(rows.tolist(), sim.episode_metrics(rows), strict=True):
                metrics[i] = values.as_dict()
            info["episode_metrics"], info["_episode_metrics"] = metrics, ended
            info["episode_control_cost"] = np.where(ended, control_costs(sim.state), 0.0)
            info["_episode_control_cost"] = ended
        self._done = ended
        obs = engine.observe()
        if same_step and ended.any():  # same-step autoreset: the final observation goes to info
            info["final_obs"] = obs
            info["_final_obs"] = ended
            self._restart(ended)  # info keeps describing the step that ended them
            obs = engine.observe()
            self._done = zeros
        return obs, reward, terminated, truncated, info

    def _restart(self, which: np.ndarray) -> None:
        """New episodes for the envs ``which`` (autoreset), each from its own generator."""
        self.engine.reset(self._rngs, which)

    def render(self) -> np.ndarray | None:  # type: ignore[override]  # one env's frame (render_env), not a tuple
        """An RGB frame (H, W, 3) of env ``render_env``: area, references, trails, links coloured by
        outage probability, as the single env draws it."""
        if self.render_mode is not None and not self._started:
            raise RuntimeError("call reset() before render()")
        return self.engine.render(self.render_mode, human_ok=False)

    def close_extras(self, **kwargs: Any) -> None:
        self.engine.close()


class CommVectorEnv(JointVectorEnv):
    """N copies of ``lawn/Comm-v1`` (any interface) in one engine: the actions set powers and the
    drone, and the N x K outage-aware MPC QPs of a step are solved together (the compiled solver of
    :mod:`lawn_env.qp`, warm-started per scenario; problems it cannot settle go to DAQP one by one
    and are counted in ``info["mpc_fallbacks"]``). ``qp_backend`` names a reference backend
    instead (``"daqp"``, ``"osqp"``, ``"qpsolvers:<name>"``: one QP at a time through Python)."""

    role = "comm"
