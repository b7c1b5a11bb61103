"""The zero action of an action interface, as a policy: the anchor a learner starts from.

A learned agent of the RL interface acts *around* an anchor (:mod:`lawn_env.interface`): its zero
action already flies the drone over the AGVs' centroid, splits the power by a prior and (on
Joint) applies the outage-aware MPC's increments. What learning adds is measured against that
zero action on the same seeds, so the benchmark tables carry it as a row of its own:
``make_policy("anchor:stake")``, ``lawn evaluate --policy anchor:stake``.

=====================  ======================================================================
``anchor:hover``       the v0 interface's zero action: the drone hovers at its start, equal power
``anchor:distance``    the anchored scheme with the distance prior (d_k^2): equal outage on every link
``anchor:stake``       the anchored scheme with the stake prior: the RL interface's default
``anchor:NAME-lqr``    either prior with the LQR baseline's increments under the Joint residual
                       (``increment_anchor="lqr"``; on Comm-v1 the same as ``anchor:NAME``)
=====================  ======================================================================

The zero action of the anchored scheme depends on the scheme, the power prior and the increment
anchor only (the drone offset, the power range and the residual scale multiply the action), so
these names cover every interface an agent can be trained with (:func:`anchor_name`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from lawn_env import env_role
from lawn_env.interface import InterfaceLike, action_codec, resolve_interface

from .base import COMM, JOINT, Policy

__all__ = ["InterfacePolicy", "AnchorPolicy", "ANCHORS", "anchor_name"]

#: The anchors by name: the interface whose zero action each one plays (None: the v0 interface).
ANCHORS: dict[str, dict[str, str] | None] = {
    "hover": None,
    "distance": {"base": "rl", "power_anchor": "distance"},
    "stake": {"base": "rl", "power_anchor": "stake"},
    "distance-lqr": {"base": "rl", "power_anchor": "distance", "increment_anchor": "lqr"},
    "stake-lqr": {"base": "rl", "power_anchor": "stake", "increment_anchor": "lqr"},
}


class InterfacePolicy(Policy):
    """A policy that chooses its actions in an interface's action scheme and hands the v0
    environment the equivalent v0 action (:meth:`to_v0`), so that it is compared with the experts
    on the unmodified scenario."""

    def __init__(self, config: Any, env_id: str, interface: InterfaceLike = None, seed: int | None = None):
        super().__init__(config, env_id, seed)
        self.interface = resolve_interface(interface)
        role = env_role(env_id)
        self.scheme = action_codec(self.config, role, self.interface)
        self.v0 = action_codec(self.config, role, None)

    def _on_reset(self, rng: np.random.Generator) -> None:
        self.scheme.reset()

    def to_v0(self, action: np.ndarray, obs: np.ndarray) -> np.ndarray:
        """The v0 action that carries out ``action`` of the interface's scheme at observation ``obs``."""
        if self.interface.action_scheme == "direct":
            return np.asarray(action, dtype=np.float32)
        state = self.layout.decode(obs)
        args = (state["x_aug"], state["reference"], state["drone_position"], state["slot"])
        return self.v0.encode(self.scheme.decode(action, *args), *args)


class AnchorPolicy(InterfacePolicy):
    """The zero action of the named anchor (:data:`ANCHORS`) on ``lawn/Joint-v1`` or ``lawn/Comm-v1``."""

    env_ids = (JOINT, COMM)

    def __init__(self, anchor: str, config: Any = None, env_id: str | None = None, seed: int | None = None):
        if anchor not in ANCHORS:
            raise ValueError(f"unknown anchor {anchor!r}; valid: {', '.join(ANCHORS)} (anchor:NAME)")
        self.name = f"anchor:{anchor}"  # before the base class checks the env, so its errors name the anchor
        super().__init__(config, env_id or JOINT, ANCHORS[anchor], seed)
        self._zero = np.zeros(self.scheme.size)

    def act(self, obs: np.ndarray) -> np.ndarray:
        return self.to_v0(self._zero, self.check_observation(obs))


def anchor_name(interface: InterfaceLike) -> str:
    """The ``anchor:NAME`` policy that plays the zero action of ``interface`` (an agent's recorded
    training interface): ``anchor:hover`` for the direct scheme, else the power prior's anchor
    (``-lqr`` with the LQR increment anchor)."""
    iface = resolve_interface(interface)
    if iface.action_scheme == "direct":
        return "anchor:hover"
    return f"anchor:{iface.power_anchor}" + ("-lqr" if iface.increment_anchor == "lqr" else "")


def load_anchor(name: str, config: Any = None, env_id: str | None = None, seed: int | None = None,
                **kwargs: Any) -> AnchorPolicy:
    """``make_policy("anchor:NAME")``: anchors take no settings."""
    if kwargs:
        raise ValueError(f"anchor:{name} takes no settings; got {sorted(kwargs)}")
    return AnchorPolicy(name, config, env_id, seed)
