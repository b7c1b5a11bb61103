"""DAgger of a fleet network (``agents.fleet.FleetPolicy``) from an expert, on mixed fleet sizes.

1. For every fleet size K of ``fleet_sizes``, roll out the expert (``rg-mpc`` by default) on the
   v0 env of that K and label each visited state with its action, re-expressed in the interface's
   scheme and laid out per entity (:func:`fleet_pairs`: :func:`training.bc.collect`'s labels).
2. Fit the network's deterministic action to the labels by mean-squared error over the entries
   of the AGVs present and the drone (:func:`fit_fleet`; padded rows carry no label).
3. DAgger: roll out the network itself (through :class:`agents.learned.SB3Policy`, on the v0
   envs), label the states it visits with the expert's actions, add them and fit again.

The observations and labels of every K share one shape (the entity layout), so one data set and
one network serve them all.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from agents.learned import SB3Policy
from lawn_env import ScenarioConfig
from lawn_env.entities import EntityLayout
from lawn_env.interface import InterfaceLike, resolve_interface

from .bc import collect

__all__ = ["fleet_pairs", "fit_fleet", "dagger_round"]


def fleet_pairs(env_id: str, config: ScenarioConfig, steps: int, seed: int, interface: InterfaceLike,
                expert: str = "rg-mpc", actor: Any = None) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """``steps`` labelled transitions of the v0 env of ``config`` (:func:`training.bc.collect`, the
    states visited by ``actor``, default the expert) in the entity layout: the observations (a
    dict of (steps, ...) arrays), the expert's entity actions (steps, A) and which entries carry a
    label (steps, A) bool: the AGVs present and the drone."""
    iface = resolve_interface(interface)
    obs, labels, _ = collect(env_id, config, expert, steps, seed, iface, actor=actor)
    layout = EntityLayout(config, "joint" if env_id == "lawn/Joint-v0" else "comm", iface.obs_bound)
    present = np.zeros((len(labels), layout.action_space.shape[0]), dtype=bool)
    present[:, layout.gather] = True
    return layout.observe(obs), layout.to_entity_actions(labels), present


def fit_fleet(model: Any, obs: dict[str, np.ndarray], actions: np.ndarray, present: np.ndarray, epochs: int,
              batch_size: int, learning_rate: float, seed: int) -> list[float]:
    """Mean-squared-error regression of the model's deterministic action on the labelled entries;
    returns the loss over the whole data set before the first epoch and after each."""
    import torch

    torch.manual_seed(seed)
    policy = model.policy
    optimizer = torch.optim.Adam(policy.parameters(), lr=learning_rate)
    x = {key: torch.as_tensor(value) for key, value in obs.items()}
    y, w = torch.as_tensor(actions), torch.as_tensor(present, dtype=torch.float32)
    rng = np.random.default_rng(seed)

    def loss_of(idx: Any) -> Any:
        mean = policy.get_distribution({key: value[idx] for key, value in x.items()}).mode()
        return (((mean - y[idx]) ** 2) * w[idx]).sum() / w[idx].sum()

    def full_loss() -> float:
        with torch.no_grad():
            return float(loss_of(slice(None)))

    losses = [full_loss()]
    for _ in range(epochs):
        order = rng.permutation(len(y))
        for start in range(0, len(y), batch_size):
            loss = loss_of(torch.as_tensor(order[start : start + batch_size]))
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
        losses.append(full_loss())
    return losses


def dagger_round(model: Any, env_id: str, configs: Sequence[ScenarioConfig], steps: int, seed: int,
                 interface: InterfaceLike, expert: str = "rg-mpc") -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """The states ``model`` visits on the v0 env of every config (``steps`` each, seeds from
    ``seed``), labelled by the expert (``model`` None: the expert's own states), concatenated."""
    parts = []
    for i, config in enumerate(configs):
        actor = None if model is None else SB3Policy(model, config, env_id, interface)
        parts.append(fleet_pairs(env_id, config, steps, seed + 1000 * i, interface, expert, actor))
    obs = {key: np.concatenate([p[0][key] for p in parts]) for key in parts[0][0]}
    return obs, np.concatenate([p[1] for p in parts]), np.concatenate([p[2] for p in parts])
