"""The residual action scheme: a learner's action moves an anchor policy's decision.

An anchored interface (:mod:`lawn_env.interface`) measures its actions from a fixed prior: its zero
action flies the drone over the AGVs' centroid and splits the power by distance or stake. The
residual scheme measures them from a *policy* instead, usually the best expert: at every slot the
anchor (``dv-mpc``) decides from the full state, its decision is encoded in the interface's action
scheme (the same encode that labels behaviour cloning), and the learner's action ``a`` in
``[-1, 1]^m`` moves it,

    action = clip(encode(anchor's decision) + scale * a, -1, 1),

so the zero action is the anchor (up to the float32 of the env's action and the interface's
range), and ``scale`` bounds how far a learner can move it in one slot. One class holds the
equation: :class:`ResidualActions`; :class:`AnchorResidual` puts it in front of a Gymnasium env
for training, and a trained agent (:class:`agents.learned.SB3Policy`) applies it when it acts, from
the ``residual`` its run records (``{"anchor": NAME, "scale": s}``: :func:`agents.make_policy` and
:func:`agents.policies.attach_residual` build the anchor).

The anchor's cost is paid every slot: a ``dv-mpc`` decision is about 1.7 ms at K = 4.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from lawn_env import ObservationLayout, ScenarioConfig, env_role, role_env_id
from lawn_env.envs.base import LawnEnv
from lawn_env.interface import InterfaceLike, action_codec, resolve_interface
from lawn_env.spaces import check_action

from .base import COMM, JOINT, Policy

__all__ = ["ResidualActions", "AnchorResidual", "check_residual"]


def check_residual(residual: Any) -> dict[str, Any]:
    """A residual's settings, ``{"anchor": NAME, "scale": s}`` with ``0 < s <= 2``, checked (an error
    naming the field otherwise)."""
    if not isinstance(residual, Mapping) or set(residual) - {"anchor", "scale"} or "anchor" not in residual:
        raise ValueError(f"residual={residual!r}: a mapping with 'anchor' (a policy name) and optionally 'scale'")
    anchor, scale = residual["anchor"], residual.get("scale", 0.25)
    if not isinstance(anchor, str) or not anchor:
        raise ValueError(f"residual anchor={anchor!r}: a policy name (agents.make_policy), e.g. 'dv-mpc'")
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not 0.0 < scale <= 2.0:
        raise ValueError(f"residual scale={scale!r}: a number in (0, 2] (the action's range is [-1, 1])")
    return {"anchor": anchor, "scale": float(scale)}


class ResidualActions:
    """The residual scheme of ``interface`` (an anchored interface of the flat layout) around the
    policy ``anchor`` (built for ``env_id`` and ``config``, :func:`agents.make_policy`):
    :meth:`action` maps a learner's action and the benchmark observation of the slot to the
    interface's action."""

    def __init__(self, anchor: Policy, config: ScenarioConfig, env_id: str, interface: InterfaceLike,
                 scale: float = 0.25):
        if not isinstance(anchor, Policy):
            raise TypeError(f"anchor={anchor!r}: a built policy (agents.make_policy(name, config, env_id=...))")
        settings = check_residual({"anchor": anchor.name, "scale": scale})
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
        self.scheme, self.v0 = action_codec(config, role, self.interface), action_codec(config, role, None)
        self.layout = ObservationLayout(config)
        self.scale = settings["scale"]
        self.size = self.scheme.size

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
        moved: np.ndarray = np.clip(self.anchor_action(obs) + self.scale * np.asarray(residual, dtype=np.float64),
                                    -1.0, 1.0)
        return moved


class AnchorResidual(gym.ActionWrapper[Any, np.ndarray, np.ndarray]):
    """``env`` (``lawn/Joint-v1`` or ``lawn/Comm-v1`` with an anchored flat interface, possibly
    wrapped) acting by the residual scheme around ``anchor`` (a policy built for the env's scenario,
    ``make_policy("dv-mpc", env.unwrapped.config, env_id=...)``): the action space is the env's, and
    the zero action plays the anchor."""

    def __init__(self, env: gym.Env[Any, Any], anchor: Policy, scale: float = 0.25):
        super().__init__(env)
        base = env.unwrapped
        if not isinstance(base, LawnEnv):
            raise TypeError(f"AnchorResidual wraps a lawn env (lawn/Joint-v1, lawn/Comm-v1); got {type(base).__name__}")
        self.base: LawnEnv = base
        self.residual = ResidualActions(anchor, base.config, role_env_id(base.role), base.interface,
                                        scale)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        self.residual.reset(seed)
        return obs, info

    def action(self, action: np.ndarray) -> np.ndarray:
        checked = check_action(action, self.residual.size)  # a clear error for a bad shape, NaN or out of [-1, 1]
        return self.residual.action(checked, self.base.benchmark_observation()).astype(np.float32)
