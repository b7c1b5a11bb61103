"""The residual action scheme: a learner's action moves an anchor policy's decision.

An anchored interface (:mod:`lawn_env.interface`) measures its actions from a fixed prior: its zero
action flies the drone over the AGVs' centroid and splits the power by distance or stake. The
residual scheme measures them from a *policy* instead, usually the best expert: at every slot the
anchor (``dv-mpc``) decides from the full state, its decision is encoded in the interface's action
scheme (the same encode that labels behaviour cloning), and the learner's action ``a`` in
``[-1, 1]^m`` moves it,

    action = clip(encode(anchor's decision) + scale * a, -1, 1),

so the zero action is the anchor (up to the float32 of the env's action and the interface's
range), and ``scale`` bounds how far a learner can move it in one slot. ``moves`` names the parts
of the decision the learner moves (:data:`PARTS`: Joint's ``increment``, ``power``, ``drone``;
all of them by default): the learner's action then has only those entries, and the others stay the
anchor's. With ``moves=("power", "drone")`` a learner changes where the drone flies and how the
budget is split, the decisions a one-slot planner makes greedily, while the AGVs' increments stay
the expert's MPC solution. One class holds the
equation: :class:`ResidualActions`; :class:`AnchorResidual` puts it in front of a Gymnasium env
for training, and a trained agent (:class:`agents.learned.SB3Policy`) applies it when it acts, from
the ``residual`` its run records (``{"anchor": NAME, "scale": s, "moves": [...]}``: :func:`agents.make_policy` and
:func:`agents.policies.attach_residual` build the anchor).

The anchor's cost is paid every slot: a ``dv-mpc`` decision is about 1.7 ms at K = 4.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypedDict

import gymnasium as gym
import numpy as np

from lawn_env import ObservationLayout, ScenarioConfig, env_role, role_env_id
from lawn_env.envs.base import LawnEnv
from lawn_env.interface import InterfaceLike, action_codec, resolve_interface
from lawn_env.spaces import DirectActions, check_action

from .base import COMM, JOINT, Policy

__all__ = ["ResidualActions", "AnchorResidual", "ResidualSettings", "check_residual", "PARTS"]

#: The parts of an anchored action a residual can move, in the action's order (Joint's increments
#: first; Comm has no ``increment``).
PARTS = ("increment", "power", "drone")


class _Residual(TypedDict):
    anchor: str
    scale: float


class ResidualSettings(_Residual, total=False):
    """A residual scheme's settings, checked: the anchor policy, the scale of the learner's move and
    the parts it moves (absent: all of :data:`PARTS`)."""

    moves: list[str]


def check_residual(residual: Any) -> ResidualSettings:
    """A residual's settings, ``{"anchor": NAME, "scale": s, "moves": [PART, ...]}`` with
    ``0 < s <= 2`` and ``moves`` a non-empty subset of :data:`PARTS` (optional: all), checked (an
    error naming the field otherwise). ``moves`` is kept only when it leaves a part out, in
    :data:`PARTS`' order."""
    if not isinstance(residual, Mapping) or set(residual) - {"anchor", "scale", "moves"} or "anchor" not in residual:
        raise ValueError(f"residual={residual!r}: a mapping with 'anchor' (a policy name) and optionally 'scale' "
                         f"and 'moves'")
    anchor, scale = residual["anchor"], residual.get("scale", 0.25)
    if not isinstance(anchor, str) or not anchor:
        raise ValueError(f"residual anchor={anchor!r}: a policy name (agents.make_policy), e.g. 'dv-mpc'")
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not 0.0 < scale <= 2.0:
        raise ValueError(f"residual scale={scale!r}: a number in (0, 2] (the action's range is [-1, 1])")
    checked: ResidualSettings = {"anchor": anchor, "scale": float(scale)}
    moves = residual.get("moves", PARTS)
    if (isinstance(moves, str) or not isinstance(moves, (list, tuple)) or not moves
            or any(part not in PARTS for part in moves) or len(set(moves)) != len(moves)):
        raise ValueError(f"residual moves={moves!r}: a non-empty list of distinct parts from {list(PARTS)}")
    if set(moves) != set(PARTS):
        checked["moves"] = [part for part in PARTS if part in moves]
    return checked


class ResidualActions:
    """The residual scheme of ``interface`` (an anchored interface of the flat layout) around the
    policy ``anchor`` (built for ``env_id`` and ``config``, :func:`agents.make_policy`):
    :meth:`action` maps a learner's action and the benchmark observation of the slot to the
    interface's action."""

    def __init__(self, anchor: Policy, config: ScenarioConfig, env_id: str, interface: InterfaceLike,
                 scale: float = 0.25, moves: tuple[str, ...] | list[str] = PARTS):
        if not isinstance(anchor, Policy):
            raise TypeError(f"anchor={anchor!r}: a built policy (agents.make_policy(name, config, env_id=...))")
        settings = check_residual({"anchor": anchor.name, "scale": scale, "moves": moves})
        self.interface = resolve_interface(interface)
        if self.interface.action_scheme != "anchored" or self.interface.layout != "flat":
            raise ValueError(f"the residual scheme moves an anchored interface's flat actions; got action_scheme="
                             f"{self.interface.action_scheme!r}, layout={self.interface.layout!r}")
        if env_id not in (JOINT, COMM):
            raise ValueError(f"env_id={env_id!r}; the residual scheme drives {JOINT} or {COMM}")
        self.anchor = anchor
        if self.anchor.env_id != env_id:
            raise ValueError(f"anchor {self.anchor.name!r} drives {self.anchor.env_id}, not {env_id}")
        role = env_role(env_id)
        self.scheme, self.v0 = action_codec(config, role, self.interface), DirectActions(config, role)
        self.layout = ObservationLayout(config)
        self.scale = settings["scale"]
        #: the entries of the interface's action the learner moves (``moves``' parts)
        parts = [p for p in PARTS if p != "increment" or self.scheme.increment_size]
        missing = [p for p in settings.get("moves", parts) if p not in parts]
        if missing:
            raise ValueError(f"residual moves={list(moves)!r}: {env_id} has no {missing} (its parts: {parts})")
        self.moved = _entries(self.scheme.increment_size, config.num_agvs, settings.get("moves", PARTS))
        self.size = int(self.moved.size)

    def reset(self, seed: int | None = None) -> None:
        """Start an episode: the anchor's and the scheme's per-episode state."""
        self.anchor.reset(seed)
        self.scheme.reset()

    def anchor_action(self, obs: np.ndarray) -> np.ndarray:
        """The anchor's decision at benchmark observation ``obs``, in the interface's scheme."""
        state = self.layout.decode(obs)
        args = (state["x_aug"], state["reference"], state["drone_position"], state["slot"])
        return np.asarray(self.scheme.encode(self.v0.decode(self.anchor.act(obs), *args), *args), dtype=np.float64)

    def action(self, residual: np.ndarray, obs: np.ndarray) -> np.ndarray:
        """The interface's action: the anchor's, moved by ``scale`` times the learner's ``residual``."""
        moved = self.anchor_action(obs)
        moved[self.moved] += self.scale * np.asarray(residual, dtype=np.float64)
        clipped: np.ndarray = np.clip(moved, -1.0, 1.0)
        return clipped


def _entries(increment_size: int, num_agvs: int, moves: tuple[str, ...] | list[str]) -> np.ndarray:
    """The indices of ``moves``' parts in an anchored action (increments, then the K powers, then the
    drone's two offsets)."""
    spans = {"increment": range(increment_size), "power": range(increment_size, increment_size + num_agvs),
             "drone": range(increment_size + num_agvs, increment_size + num_agvs + 2)}
    return np.array([i for part in PARTS if part in moves for i in spans[part]], dtype=np.intp)


class AnchorResidual(gym.ActionWrapper[Any, np.ndarray, np.ndarray]):
    """``env`` (``lawn/Joint-v1`` or ``lawn/Comm-v1`` with an anchored flat interface, possibly
    wrapped) acting by the residual scheme around ``anchor`` (a policy built for the env's scenario,
    ``make_policy("dv-mpc", env.unwrapped.config, env_id=...)``): the action space is the env's (with
    ``moves`` a subset of :data:`PARTS`: those parts' entries only), and the zero action plays the anchor."""

    def __init__(self, env: gym.Env[Any, Any], anchor: Policy, scale: float = 0.25,
                 moves: tuple[str, ...] | list[str] = PARTS):
        super().__init__(env)
        base = env.unwrapped
        if not isinstance(base, LawnEnv):
            raise TypeError(f"AnchorResidual wraps a lawn env (lawn/Joint-v1, lawn/Comm-v1); got {type(base).__name__}")
        self.base: LawnEnv = base
        self.residual = ResidualActions(anchor, base.config, role_env_id(base.role), base.interface,
                                        scale, moves)
        if self.residual.size != self.residual.scheme.size:  # the learner's action: the moved parts only
            self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(self.residual.size,), dtype=np.float32)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        self.residual.reset(seed)
        return obs, info

    def action(self, action: np.ndarray) -> np.ndarray:
        checked = check_action(action, self.residual.size)  # a clear error for a bad shape, NaN or out of [-1, 1]
        return self.residual.action(checked, self.base.benchmark_observation()).astype(np.float32)
