"""``lawn/Comm-v1``: the agent allocates the communication resources; MPC drives the AGVs."""

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
    not as in ``lawn/Joint-v1``. Good power and trajectory decisions raise psi where the MPC
    needs it.

    ## Action Space

    ``Box(-1, 1, (K + 2,), float32)``:

    | index      | meaning                 | scaling                                                 |
    |------------|-------------------------|---------------------------------------------------------|
    | 0 .. K-1   | power weight of link k  | ``w = (a+1)/2``, ``p = P_max w / max(1, sum w)``         |
    | K .. K+1   | drone velocity (x, y)   | ``a * V_max`` m/s, clipped to norm V_max, kept in area   |

    ## Observation Space

    As ``lawn/Joint-v1`` (:class:`lawn_env.spaces.ObservationLayout`).

    ## Rewards

    As ``lawn/Joint-v1``: minus the realized stage cost (``info["stage_cost"]``), terms in
    ``info["reward_tracking"]`` and ``info["reward_effort"]``; with ``interface="rl"`` bounded and scaled as there.
    ``info`` also reports the MPC's iterations, fallbacks and the planned psi; the wall-clock
    solve time of the last step is ``env.unwrapped.last_mpc_solve_time_s``.

    ## Starting State

    As ``lawn/Joint-v1``.

    ## Episode End

    Truncation after ``num_slots`` slots; ``info["episode_metrics"]`` on the last step. With
    ``interface="rl"``, termination past 25 m of tracking error as in ``lawn/Joint-v1``.

    ## Arguments

    ``gym.make("lawn/Comm-v1", config=None, render_mode=None, qp_backend="compiled", interface=None,
    **overrides)``; ``qp_backend`` is ``"compiled"`` (the exact compiled solver of
    :mod:`lawn_env.qp`) or a reference, ``"daqp"``, ``"osqp"`` or ``"qpsolvers:<name>"`` (:mod:`lawn_env.mpc`);
    ``interface`` as for ``lawn/Joint-v1`` (``lawn/CommRL-v1`` is this env with
    ``interface="rl"``: power ``p_k ∝ prior_k exp(2 a_k)`` spending the budget, with the stake
    prior, by what each command is worth (:mod:`lawn_env.interface`), drone toward the AGVs' centroid ``+ a * 50 m``).

    ## Version History

    * v1: under measurement noise (the disturbance mode's ``measurement_noise_*``, as in the
      ``disturbed`` preset) the MPC that drives the AGVs plans from the measured state, the
      snapshot's, as every planner does (v0 planned from the true state), and with
      ``interface="rl"`` it is the anchor's MPC (one per env): episodes with measurement noise
      differ from v0's, every other episode is bit for bit as v0's. The native vector env as
      ``lawn/Joint-v1``'s history says (one generator, episodes differ for N > 1). The MPC's QPs are
      solved by the compiled exact solver (``qp_backend="compiled"``, the default; the same
      decisions up to the solvers' rounding). Infos, spec, observation bound, rendering and the
      entity layout as ``lawn/Joint-v1``'s history says. Later, within v1: ``control.law="delivery"``
      (opt-in; the default law is the paper's, so every default episode is unchanged) became the
      loss-aware tail's command (:class:`lawn_env.tail.DeliveryLaw`), the former delivery law kept as
      ``"delivery-certainty-equivalent"``; ``info["episode_metrics"]`` gained ``max_tracking_error_m``
      and ``diverged``; the opt-in buffered actuator (``control.actuator="buffer"``: the AGVs' packets
      carry their MPC's planned sequence, a lost one's AGV plays its buffer; the default hold's episodes
      bit for bit as before).
    * v0: initial version; the ``interface`` keyword (opt-in) and ``info["stage_cost"]`` added
      later. Still registered: ``lawn/Comm-v0`` builds this class with ``planning_state="true"``
      (the MPC plans from the true state) and without a native vector env.
    """

    role = "comm"

    def __init__(self, config: ConfigLike = None, render_mode: str | None = None, interface: InterfaceLike = None,
                 qp_backend: str = DEFAULT_BACKEND, planning_state: str = "measured", **overrides: Any):
        self.planning_state = planning_state
        super().__init__(config, render_mode, interface, qp_backend, **overrides)
