"""The opt-in RL interface: action schemes, a bounded reward, termination and clipped features.

The benchmark environments (their default, the v0 interface) are the paper's benchmark and stay
as they are: raw actions, reward minus the realized stage cost, no termination, unclipped features. A learner
started there sits in a failure basin (the zero action hovers at the start with equal power; lost commands keep an AGV
accelerating; single slots cost up to 1e7), so every environment also takes
``interface=RLInterface(...)`` (or ``interface="rl"`` for :data:`RL_INTERFACE`), which changes
*how the agent talks to the scenario*, never the scenario:

* **Action schemes** (one codec per scheme, :func:`action_codec` picks it, used by the
  environments, the policies, the learned-policy wrappers and behaviour cloning):

  - ``"direct"``: the v0 actions (:mod:`lawn_env.spaces`);
  - ``"anchored"``: actions measured from a safe anchor, so the zero action is a good policy.
    Drone: a target ``centroid of the AGVs + a * drone_offset_m`` per axis, flown toward at up
    to V_max. Power: the budget is always spent, ``p_k ∝ prior_k exp(a_k power_log_range)``
    with a prior that never starves a link, chosen by ``power_anchor``:

    - ``"distance"``: ``prior_k = d_k^2`` (``d_k`` the 3-D distance from the drone's next
      position), the split that equalizes every link's outage (``x ∝ d^2 / p``);
    - ``"stake"`` (the RL interface's default): the split that minimizes the expected loss
      ``sum_k w_k P_out,k`` of the reduced per-slot problem linearized in psi (``lawn_env.mpc``,
      MODEL.md §4), where ``w_k = V_k(0) - V_k(1)`` is what AGV k's command is worth this slot
      (:meth:`~lawn_env.mpc.OutageAwareMPC.command_stakes`, one extra MPC solve). With the
      high-SNR outage ``P_out ∝ (d^2 / p)^a`` (a the outage law's order, m for Nakagami-m:
      :meth:`~lawn_env.channel.LinkParams.stake_power_weights`) the Lagrange condition gives
      ``prior_k = (w_k d_k^(2a))^(1/(a+1))``; stakes are floored at ``STAKE_FLOOR`` of their mean.
      An AGV far off its track gets the power it needs to be brought back, which the distance
      prior does not give it (docs/rl.md compares the two zero actions: ``python benchmarks/anchors.py``).

    Increments (Joint): a residual ``a * residual_scale * Delta-a_max`` on the first increment
    of the outage-aware MPC at each link's planned success probability (the QP P3 that drives
    the AGVs of ``lawn/Comm-v1``, :class:`lawn_env.mpc.OutageAwareMPC`), clipped to the control
    set; or, with ``increment_anchor="lqr"``, on the LQR baseline's first increment (no QP: the
    from-scratch recipe's anchor, with the distance prior an interface without the expert's MPC).
    Under ``control.actuator="buffer"`` the packet carries the rest of the anchor's planned
    sequence as it planned it (the LQR anchor's rest is zeros, a hold); the anchor of the delivery
    law weighs psi-bar by what each command is worth with a hold on loss (it does not see the
    buffers; the Comm envs' AGVs do).
    (A cheaper anchor, the unconstrained MPC's linear gain saturated afterwards, costs many times
    the MPC even with perfect links: the reference paths ask for more than the AGVs' acceleration
    bounds at their corners, and only a controller that plans with the bounds takes them well.)

* **Reward** ``"scaled"``: ``-min(cost, cost_clip) / cost_scale`` per slot, in
  ``[-cost_clip / cost_scale, 0]``; ``"log"``: ``-log(1 + min(cost, cost_clip) / cost_scale)``, in
  ``[-log(1 + cost_clip / cost_scale), 0]`` (a slot's cost counted by its order of magnitude: the
  default task's first slots cost hundreds, its later ones a few units, and a scaled reward clipped
  at 100 is flat over a third of the prior's cost there). The raw stage cost and its terms stay in ``info``.
* **Termination** past ``termination_distance_m`` of position error of any AGV, with the reward
  of the remaining slots at its floor added as a penalty, so that ending early is never better
  than continuing (every remaining slot would have earned at least that floor).
* **Observation clipping** to ``[-obs_clip, obs_clip]`` (the features are normalized to order
  one; drift can otherwise blow them up). Without it (the v0 interface) features still saturate
  at ``±OBS_LIMIT`` (1e6: an AGV a million half-areas away), so observations stay finite and
  inside the declared space in episodes of any length.

Evaluation never uses the interface: learned policies are wrapped to act on the benchmark
environments (:class:`agents.learned.SB3Policy`), and every comparison reports the realized
control cost of full episodes of the unmodified scenario.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, Literal

import gymnasium as gym
import numpy as np
from pydantic import ConfigDict, model_validator
from pydantic.dataclasses import dataclass

from .channel import LinkParams
from .config import PositiveFloat, ScenarioConfig
from .drone import toward
from .dynamics import ACCELERATION, POSITION, PredictionModel, saturate_increment
from .errors import raises_config_errors
from .mpc import DEFAULT_BACKEND, OutageAwareMPC, SlotData
from .products import matmul
from .spaces import ActionCodec, DirectActions
from .state import Decisions, later_increments
from .tail import DeliveryLaw

__all__ = ["RLInterface", "V0_INTERFACE", "RL_INTERFACE", "OBS_LIMIT", "STAKE_FLOOR", "resolve_interface",
           "action_codec", "AnchoredActions", "InterfaceLike"]


@raises_config_errors("interface.", "interface field")
@dataclass(frozen=True, config=ConfigDict(extra="forbid", allow_inf_nan=False))
class RLInterface:
    """How an agent talks to the scenario (module docstring). The defaults are the v0 interface."""

    action_scheme: Literal["direct", "anchored"] = "direct"
    """``direct``: the v0 actions; ``anchored``: measured from a safe anchor."""
    reward: Literal["cost", "scaled", "log"] = "cost"
    """``cost``: minus the stage cost (v0); ``scaled``: minus the clipped, scaled stage cost; ``log``: minus
    the log of one plus the clipped, scaled stage cost."""
    cost_scale: PositiveFloat = 10.0
    """Stage-cost units per unit of reward (of the order of an expert's cost per slot at the defaults)."""
    cost_clip: PositiveFloat = 100.0
    """Stage cost counted at most per slot (reward floor ``-cost_clip / cost_scale``)."""
    termination_distance_m: PositiveFloat | None = None
    """End the episode when an AGV is farther than this from its reference (None: never)."""
    obs_clip: PositiveFloat | None = None
    """Clip every observation feature to ``[-obs_clip, obs_clip]`` (None: no clipping)."""
    drone_offset_m: PositiveFloat = 50.0
    """Anchored drone target: the AGVs' centroid plus ``a * drone_offset_m`` per axis, m."""
    power_anchor: Literal["distance", "stake"] = "distance"
    """Anchored power prior: ``distance`` (equal outage) or ``stake`` (by what each command is worth)."""
    power_log_range: PositiveFloat = 2.0
    """Anchored power: weights ``prior exp(a * power_log_range)``; links differ at most by e^(2 range) from the
    prior."""
    residual_scale: PositiveFloat = 1.0
    """Anchored increments: residual ``a * residual_scale * Delta-a_max`` on the tracking controller."""
    layout: Literal["flat", "entities"] = "flat"
    """How observations and actions are laid out: ``flat`` (one vector each, the v0 layout) or
    ``entities`` (a row per AGV padded to ``MAX_AGVS`` with a mask, and a row of globals, for set and
    graph networks: :mod:`lawn_env.entities`)."""
    increment_anchor: Literal["mpc", "lqr"] = "mpc"
    """Anchored increments (Joint): the tracking controller under the residual. ``mpc``: the
    outage-aware MPC's first increment at each link's planned success probability; ``lqr``: the
    LQR baseline's (the DARE gain of (A~, B~, Q1, Q2) with the reference's own increment as
    feed-forward, saturated to the control set), which solves no QP: with
    ``power_anchor="distance"`` decoding an action uses no MPC at all."""

    @model_validator(mode="after")
    def _check(self) -> RLInterface:
        if self.termination_distance_m is not None and self.reward == "cost":
            raise ValueError(
                f"termination_distance_m={self.termination_distance_m} needs reward='scaled' or 'log' (got "
                f"reward={self.reward!r}): the penalty that makes ending early never pay is the reward floor "
                "of the remaining slots, and the raw cost has no floor")
        return self

    @property
    def reward_floor(self) -> float:
        """The lowest reward of one slot (``-inf`` for the raw cost)."""
        if self.reward == "cost":
            return -math.inf
        return -self.cost_clip / self.cost_scale if self.reward == "scaled" else -math.log1p(self.cost_clip /
                                                                                             self.cost_scale)

    def rewards_from_costs(self, costs: np.ndarray) -> np.ndarray:
        """The slots' rewards for realized stage costs (any shape)."""
        costs = np.asarray(costs, dtype=float)
        if self.reward == "cost":
            return -costs
        scaled: np.ndarray = np.minimum(costs, self.cost_clip) / self.cost_scale
        return -scaled if self.reward == "scaled" else -np.log1p(scaled)

    def terminates(self, position_error_m: np.ndarray) -> np.ndarray:
        """Per scenario: termination is on and some AGV's position error exceeds the bound;
        position errors (B, K, 2) -> (B,) bool."""
        position_error_m = np.asarray(position_error_m, dtype=float)
        if self.termination_distance_m is None:
            return np.zeros(position_error_m.shape[0], dtype=bool)
        d2 = (position_error_m * position_error_m).sum(axis=-1)
        terminal: np.ndarray = d2.max(axis=-1) > self.termination_distance_m**2
        return terminal

    def terminal_penalties(self, remaining_slots: np.ndarray) -> np.ndarray:
        """Added to the reward of a terminating step: the floor for every slot not played (any shape)."""
        remaining = np.asarray(remaining_slots)
        return np.where(remaining > 0, np.maximum(remaining, 1) * self.reward_floor, 0.0)

    @property
    def obs_bound(self) -> float:
        """Every observation feature lies in ``[-obs_bound, obs_bound]``."""
        return OBS_LIMIT if self.obs_clip is None else min(self.obs_clip, OBS_LIMIT)

    def observation_space(self, size: int) -> gym.spaces.Box:
        return gym.spaces.Box(-self.obs_bound, self.obs_bound, shape=(size,), dtype=np.float32)

    def observe(self, obs: np.ndarray) -> np.ndarray:
        """The observation as the agent sees it (clipped in place to ``obs_bound``; minimum and
        maximum rather than ``np.clip``, whose Python wrapper doubles the cost on this hot path)."""
        bound = self.obs_bound
        np.minimum(obs, bound, out=obs)
        np.maximum(obs, -bound, out=obs)
        return obs

    def to_dict(self) -> dict[str, Any]:
        return {f: getattr(self, f) for f in self.__dataclass_fields__}


#: Stakes below this fraction of their mean are raised to it (``power_anchor="stake"``): a link whose
#: command is worth nothing now still gets ``STAKE_FLOOR^(1/(a+1))`` of an average link's power weight.
STAKE_FLOOR = 1e-3

#: Saturation of observation features without ``obs_clip`` (normalized units).
OBS_LIMIT = 1e6

#: The paper's benchmark interface (what ``lawn/Joint-v1`` and ``lawn/Comm-v1`` use by default).
V0_INTERFACE = RLInterface()
#: The RL-ready interface (``interface="rl"``; the ids ``lawn/JointRL-v1`` and ``lawn/CommRL-v1``).
RL_INTERFACE = RLInterface(action_scheme="anchored", reward="scaled", termination_distance_m=25.0, obs_clip=10.0,
                           power_anchor="stake")
_NAMED = {"v0": V0_INTERFACE, "rl": RL_INTERFACE}
#: What every ``interface=`` argument takes: an RLInterface, a dict of its fields, "v0"/"rl" or None (v0).
InterfaceLike = RLInterface | Mapping[str, Any] | str | None


def resolve_interface(interface: InterfaceLike) -> RLInterface:
    """An :class:`RLInterface` from itself, a dict of its fields, ``"v0"``/``"rl"`` or None (v0)."""
    if interface is None:
        return V0_INTERFACE
    if isinstance(interface, RLInterface):
        return interface
    if isinstance(interface, str):
        try:
            return _NAMED[interface]
        except KeyError:
            raise ValueError(f"interface={interface!r}; valid names: {', '.join(_NAMED)}, "
                             "or a dict of RLInterface fields") from None
    if isinstance(interface, Mapping):
        data = dict(interface)
        base = resolve_interface(data.pop("base", "v0"))
        return RLInterface(**{**base.to_dict(), **data})
    raise TypeError(f"interface must be an RLInterface, a dict, 'v0', 'rl' or None; got {type(interface).__name__}")


def action_codec(config: ScenarioConfig, role: str = "joint", interface: InterfaceLike = None,
                 mpc_backend: str = DEFAULT_BACKEND) -> ActionCodec:
    """The action codec of ``role`` (``joint`` or ``comm``) under ``interface``'s action scheme:
    :class:`~lawn_env.spaces.DirectActions` or :class:`AnchoredActions` (``mpc_backend``: the QP
    backend of the anchor's MPC)."""
    iface = resolve_interface(interface)
    if iface.action_scheme == "anchored":
        return AnchoredActions(config, role, iface, mpc_backend)
    return DirectActions(config, role)


class AnchoredActions(ActionCodec):
    """Actions measured from a safe anchor (module docstring): the drone flies toward the AGVs'
    centroid plus ``a * drone_offset_m``, the power split is ``prior exp(a * power_log_range)``
    spending the budget, and Joint's increments are a residual on the anchor controller's."""

    scheme = "anchored"

    def __init__(self, config: ScenarioConfig, role: str, interface: RLInterface, mpc_backend: str = DEFAULT_BACKEND):
        super().__init__(config, role)
        self.interface = interface
        self._inc_max = config.control.accel_increment_max_mps2
        self._pmax = config.power_budget_w
        self._vmax = config.drone.max_speed_mps
        self._dt = config.slot_s
        self._reach = config.drone_reach_m
        self._link = LinkParams.from_config(config, planning=True)
        self._stake = interface.power_anchor == "stake"
        # the anchor MPC plans as the Comm AGVs do (control.law): the loss-aware tail's command under
        # "delivery", the QP at psi = 1 under "delivery-certainty-equivalent", at the planned psi under "paper"
        self._law = config.control.law
        self._delivery: DeliveryLaw | None = None
        self._lqr_model: PredictionModel | None = None
        lqr = role == "joint" and interface.increment_anchor == "lqr"
        mpc_anchor = role == "joint" and not lqr  # the residual's controller plans by the law
        if mpc_anchor and self._law == "delivery":
            self._delivery = DeliveryLaw(config, backend=mpc_backend)
        if (mpc_anchor and self._delivery is None) or self._stake:  # the residual's controller, the stakes
            self.mpc = OutageAwareMPC.from_config(config, backend=mpc_backend)
        if lqr:
            self._lqr_model = PredictionModel.from_config(config)
            self._accel_max = config.control.accel_max_mps2
        self.needs_reference = self.mpc is not None or self._lqr_model is not None or self._delivery is not None

    def reset(self, which: np.ndarray | None = None) -> None:
        """Start an episode (the anchor MPC's warm starts are per episode, like the envs' MPC);
        ``which`` (a mask over a batch's scenarios) restarts only those scenarios."""
        if self.mpc is not None:
            self.mpc.reset(which)
        if self._delivery is not None:
            self._delivery.reset(which)

    def _decode_rows(self, actions: np.ndarray, x_aug: np.ndarray, reference: np.ndarray | None,
                     drone_position: np.ndarray, slot: int | np.ndarray | None) -> Decisions:
        k, comm = self.num_agvs, actions[:, self.increment_size :]
        target = x_aug[..., POSITION].mean(axis=-2) + comm[:, k:] * self.interface.drone_offset_m
        drone_next = toward(drone_position, target, self._vmax, self._dt, self.area)
        return self._anchored(actions[:, : 2 * k], comm[:, :k], x_aug, reference, slot, drone_next)

    def _prepare(self, x_aug: np.ndarray, reference: np.ndarray | None, slot: int | np.ndarray | None
                 ) -> SlotData | None:
        """The slot's MPC data, when the anchor needs the MPC (stakes, or the residual's controller)."""
        if self.mpc is None:
            return None
        if reference is None:
            raise ValueError(f"the anchored {self.role} actions of this interface (power_anchor="
                             f"{self.interface.power_anchor!r}) plan with the MPC: pass the reference window")
        return self.mpc.prepare(x_aug, reference, slot)

    def _anchored(self, a_increment: np.ndarray, a_power: np.ndarray, x_aug: np.ndarray,
                  reference: np.ndarray | None, slot: int | np.ndarray | None, drone_next: np.ndarray) -> Decisions:
        """The anchored decision once the drone's next position is known (single or batched): the
        power split around the prior and, for Joint, the residual on the anchor MPC's increments,
        within the increment bound."""
        data = self._prepare(x_aug, reference, slot)
        d2 = self._distance_sq(x_aug, drone_next)
        w = self._prior(d2, data) * np.exp(a_power * self.interface.power_log_range)
        power = w * (self._pmax / w.sum(axis=-1, keepdims=True))
        if not self.increment_size:
            return Decisions(None, power, drone_next)
        sequence = self._anchor_sequence(data, power, d2, x_aug, reference, slot)
        increment = sequence[..., 0, :].copy()
        increment += a_increment.reshape(increment.shape) * (self.interface.residual_scale * self._inc_max)
        np.clip(increment, -self._inc_max, self._inc_max, out=increment)
        return Decisions(increment, power, drone_next, self._later(sequence))

    def _later(self, sequence: np.ndarray) -> np.ndarray | None:
        """The plan a buffered actuator's packet carries after the command (None under hold): the
        anchor's later increments (:func:`lawn_env.state.later_increments`)."""
        return later_increments(sequence, self.buffer_length) if self.buffer_length else None

    def _distance_sq(self, x_aug: np.ndarray, drone_next: np.ndarray) -> np.ndarray:
        """d_k^2 from the drone's next position to the AGVs, (..., K)."""
        return self._link.distance_sq(drone_next[..., None, :], x_aug[..., POSITION])

    def power_prior(self, x_aug: np.ndarray, drone_next: np.ndarray, data: SlotData | None = None) -> np.ndarray:
        """The anchored power split's weights, (..., K) (any leading batch axes; the zero action's
        powers are ``P_max prior / sum(prior)``): ``d_k^2`` from the drone's next position, or with
        ``power_anchor="stake"`` ``(w_k d_k^(2a))^(1/(a+1))`` (a the outage law's order) for the stakes ``w_k`` of the
        slot's prepared MPC ``data`` (module docstring), scaled so that the largest weight is 1."""
        return self._prior(self._distance_sq(x_aug, drone_next), data)

    def _prior(self, d2: np.ndarray, data: SlotData | None) -> np.ndarray:
        if not self._stake:
            return d2
        if data is None:
            raise ValueError("power_anchor='stake' weighs the links by the slot's stakes: pass data, the slot's "
                             "prepared MPC data (layout.mpc.prepare(x_aug, reference, slot))")
        assert self.mpc is not None  # built whenever the stake prior is on
        stake = self.mpc.command_stakes(data)
        floor = STAKE_FLOOR * stake.mean(axis=-1, keepdims=True)
        stake = np.where(floor > 0, np.maximum(stake, floor), 1.0)  # no stake anywhere: by distance alone
        return self._link.stake_power_weights(stake, d2)

    def _anchor_sequence(self, data: SlotData | None, power_w: np.ndarray, d2: np.ndarray, x_aug: np.ndarray,
                         reference: np.ndarray | None, slot: int | np.ndarray | None = None) -> np.ndarray:
        """The tracking controller under the residual: its planned increments (..., K, N, 2) m/s^2
        (the first is the command; N = 1 for the LQR anchor). ``increment_anchor="mpc"``: the
        outage-aware MPC's sequence at each link's
        planned success probability (with the stake prior it starts from this slot's stake solve's
        working sets: the same QPs at psi = 1, closer to these than the previous slot's).
        Under ``control.law="delivery"`` it is the loss-aware tail's command
        (:class:`lawn_env.tail.DeliveryLaw`), under ``"delivery-certainty-equivalent"`` the MPC's at psi = 1,
        as the Comm environment's AGVs apply them.
        ``"lqr"``: ``Delta-u_ref - K (x~ - x~_ref)`` saturated so that ``|u| <= a_max``, the first
        increment of the LQR baseline's rollout."""
        if self._lqr_model is not None:
            if reference is None:
                raise ValueError("the anchored joint actions of this interface (increment_anchor='lqr') track the "
                                 "reference: pass the reference window")
            feedforward = reference[..., 1, ACCELERATION] - reference[..., 0, ACCELERATION]
            free = feedforward - matmul(x_aug - reference[..., 0, :], self._lqr_model.lqr_gain.T)
            increment: np.ndarray = saturate_increment(x_aug[..., ACCELERATION], free, self._accel_max)
            return increment[..., None, :]
        start = "stakes" if self._stake else None
        psi = self._link.success_sq(power_w, d2)
        if self._delivery is not None:
            if reference is None:
                raise ValueError("the anchored joint actions of this interface (increment_anchor='mpc' under "
                                 "control.law='delivery') plan with the MPC: pass the reference window")
            law: np.ndarray = self._delivery.solve(x_aug, reference, psi, 0 if slot is None else slot).increments
            return law
        if self._law == "delivery-certainty-equivalent":
            psi = np.ones(d2.shape)
        assert self.mpc is not None and data is not None  # the MPC anchor: built, and _prepare gave its data
        planned: np.ndarray = self.mpc.solve_prepared(data, psi, start_from=start).increments
        return planned

    # ------------------------------------------------------------------ encode
    def encode(self, decision: Decisions, x_aug: np.ndarray, reference: np.ndarray | None,
               drone_position: np.ndarray, slot: int | None = None) -> np.ndarray:
        """The action (float32) that decodes to ``decision`` (nearest one, clipped, otherwise)."""
        power = np.asarray(decision.power_w, dtype=float)
        drone_next = np.asarray(decision.drone_next, dtype=float)
        centroid = x_aug[:, POSITION].mean(axis=0)
        target = drone_next
        move = drone_next - drone_position
        dist = math.hypot(*move.tolist())
        reach = self._reach
        if dist >= reach * (1 - 1e-9):  # a full-speed move: any target further along the ray gives it
            u = move / dist
            target = drone_position + max(dist, float(matmul(centroid - drone_position, u))) * u
        a_drone = np.clip((target - centroid) / self.interface.drone_offset_m, -1.0, 1.0)
        data = self._prepare(x_aug, reference, slot)
        d2 = self._distance_sq(x_aug, drone_next)
        log_w = np.log(np.maximum(power, 1e-300) / self._prior(d2, data))
        # any common shift gives the same split: centre the range, unless the log-weights span more
        # than the action's range (an expert that leaves links unpowered): then the strongest link
        # sits at the top, so the links that carry the budget keep their split and the weakest saturate
        log_w -= max(0.5 * (log_w.max() + log_w.min()), log_w.max() - self.interface.power_log_range)
        a_power = np.clip(log_w / self.interface.power_log_range, -1.0, 1.0)
        parts = [a_power, a_drone]
        if self.increment_size:
            anchor = self._anchor_sequence(data, power, d2, x_aug, reference)[..., 0, :]
            scale = self.interface.residual_scale * self._inc_max
            parts.insert(0, np.clip((np.asarray(decision.increment, dtype=float) - anchor) / scale, -1, 1).reshape(-1))
        return np.concatenate(parts).astype(np.float32)
