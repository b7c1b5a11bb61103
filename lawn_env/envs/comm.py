"""``lawn/Comm-v0``: the agent allocates the communication resources; MPC drives the AGVs."""

from __future__ import annotations

from typing import Any

from ..interface import InterfaceLike
from ..mpc import DEFAULT_BACKEND
from ..presets import ConfigLike
from .base import LawnEnv

__all__ = ["CommEnv"]


class CommEnv(LawnEnv):
    """
    ## Description

    The communication-resource problem of the paper: every slot the agent chooses the split of
    the power budget over the K links and the drone's move. Each AGV is driven by the
    outage-aware MPC of MODEL.md §3: the QP P3 with the success probability psi_k of its link
    at the chosen power and drone position, planned from the measured state (what a planner on
    the drone has; the true state without measurement noise), solved exactly (the compiled dual active-set solver
    of :mod:`lawn_env.qp`, warm-started per AGV). Its first increment is sent and arrives or
    not as in ``lawn/Joint-v0``. Good power and trajectory decisions raise psi where the MPC
    needs it.

    ## Action Space

    ``Box(-1, 1, (K + 2,), float32)``:

    | index      | meaning                 | scaling                                                 |
    |------------|-------------------------|---------------------------------------------------------|
    | 0 .. K-1   | power weight of link k  | ``w = (a+1)/2``, ``p = P_max w / max(1, sum w)``         |
    | K .. K+1   | drone velocity (x, y)   | ``a * V_max`` m/s, clipped to norm V_max, kept in area   |

    ## Observation Space

    As ``lawn/Joint-v0`` (:class:`lawn_env.spaces.ObservationLayout`).

    ## Rewards

    As ``lawn/Joint-v0``: minus the realized stage cost (``info["stage_cost"]``), terms in
    ``info["reward_tracking"]`` and ``info["reward_effort"]``; with ``interface="rl"`` bounded and scaled as there.
    ``info`` also reports the MPC's iterations, fallbacks and the planned psi; the wall-clock
    solve time of the last step is ``env.unwrapped.last_mpc_solve_time_s``.

    ## Starting State

    As ``lawn/Joint-v0``.

    ## Episode End

    Truncation after ``num_slots`` slots; ``info["episode_metrics"]`` on the last step. With
    ``interface="rl"``, termination past 25 m of tracking error as in ``lawn/Joint-v0``.

    ## Arguments

    ``gym.make("lawn/Comm-v0", config=None, render_mode=None, qp_backend="compiled", interface=None,
    **overrides)``; ``qp_backend`` is ``"compiled"`` (the exact compiled solver of
    :mod:`lawn_env.qp`) or a reference, ``"daqp"``, ``"osqp"`` or ``"qpsolvers:<name>"`` (:mod:`lawn_env.mpc`);
    ``interface`` as for ``lawn/Joint-v0`` (``lawn/CommRL-v0`` is this env with
    ``interface="rl"``: power ``p_k ∝ prior_k exp(2 a_k)`` spending the budget, with the stake
    prior, by what each command is worth (:mod:`lawn_env.interface`), drone toward the AGVs' centroid ``+ a * 50 m``).

    ## Version History

    * v0: initial version; the ``interface`` keyword (opt-in) and ``info["stage_cost"]`` added later.
    * v0 (later): reset and step infos share one flat schema (``lawn_env.envs.base.INFO_KEYS``;
      ``reward_tracking``/``reward_effort`` replace the nested ``reward_terms``); a made env's spec
      carries ``max_episode_steps`` (= ``num_slots``; the registry entry has no time limit, the
      env truncates itself); v0 observations saturate at ±1e6 (``OBS_LIMIT``, the space's
      bound); the dynamics and rewards are unchanged.
    * v0 (later): the MPC's QPs are solved by the compiled exact solver (``qp_backend="compiled"``,
      the default): the same decisions up to the solvers' rounding.
    * v0 (later): one compiled simulation core under every view, as ``lawn/Joint-v0``'s
      history says: this env's episodes bit for bit as before, ``episode_metrics`` summed slot by
      slot (within 1e-15 relative), the native vector env's slot randomness from one generator.
    * v0 (later): ``render()`` frames as ``lawn/Joint-v0``'s history says (a colour bar,
      the running control cost, 512 x 448 pixels); episodes are unchanged.
    * v0 (later): under measurement noise (the disturbance mode's ``measurement_noise_*``, as in
      the ``disturbed`` preset) the MPC that drives the AGVs plans from the measured state, the
      snapshot's, as every planner does (it planned from the true state before), and with
      ``interface="rl"`` it is the anchor's MPC (one per env). Episodes with measurement noise
      differ from before; every other episode is bit for bit as before.
    * v0 (later): the interface's ``layout="entities"`` as ``lawn/Joint-v0``'s history says
      (opt-in; episodes are unchanged).
    """

    role = "comm"

    def __init__(self, config: ConfigLike = None, render_mode: str | None = None, interface: InterfaceLike = None,
                 qp_backend: str = DEFAULT_BACKEND, planning_state: str = "measured", **overrides: Any):
        self.planning_state = planning_state
        super().__init__(config, render_mode, interface, qp_backend, **overrides)
