"""DAgger of a fleet network (``agents.fleet.FleetPolicy``) from an expert, on mixed fleet sizes: the
expert's (then the network's own) rollouts on the benchmark env of every fleet size K, labelled with the
expert's actions in the interface's scheme and laid out per entity (:func:`fleet_pairs`), fitted by
mean-squared error over the AGVs present and the drone (:func:`fit_fleet`). Every K shares the entity
layout's shapes, so one data set and one network serve them all.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np

from agents.learned import SB3Policy
from evaluation.seeds import TRAIN_SEED_BASE
from lawn_env import MixedFleetEnv, ScenarioConfig, env_role, presets
from lawn_env.entities import EntityLayout
from lawn_env.interface import InterfaceLike, resolve_interface

from .bc import Labeller, Round, checked_settings, collect, save_imitation
from .spec import Hyperparameters
from .validation import RunSummary, limit_torch_threads, versions

__all__ = ["EntityPairs", "fleet_pairs", "fit_fleet", "dagger_round", "fleet_settings", "task_config",
           "training_configs",
           "train_fleet"]


class EntityPairs(NamedTuple):
    """Labelled transitions in the entity layout: the observations (a dict of arrays), the expert's
    entity actions (steps, A) and which entries carry a label (steps, A)."""

    observations: dict[str, np.ndarray]
    actions: np.ndarray
    present: np.ndarray


def fleet_pairs(env_id: str, config: ScenarioConfig, steps: int, seed: int, interface: InterfaceLike,
                expert: str | Labeller = "rg-mpc", actor: Any = None) -> EntityPairs:
    """``steps`` labelled transitions of the benchmark env of ``config`` (:func:`training.bc.collect`) in the
    entity layout: the observations (a dict of arrays), the expert's entity actions (steps, A) and
    which entries carry a label (steps, A): the AGVs present and the drone."""
    iface = resolve_interface(interface)
    obs, labels, _ = collect(env_id, config, expert, steps, seed, iface, actor=actor)
    layout = EntityLayout(config, env_role(env_id), iface.obs_bound, iface.action_scheme)
    present = np.zeros((len(labels), layout.action_space.shape[0]), dtype=bool)
    present[:, layout.gather] = True
    return EntityPairs(layout.observe(obs), layout.to_entity_actions(labels), present)


def fit_fleet(model: Any, obs: dict[str, np.ndarray], actions: np.ndarray, present: np.ndarray, epochs: int,
              batch_size: int, learning_rate: float, seed: int) -> list[float]:
    """Mean-squared-error regression of the model's deterministic action on the labelled entries; the
    loss over the data before the first epoch and after each. The step size falls linearly to a tenth;
    every batch holds one fleet size (the network attends over that many rows), in random order."""
    import torch

    torch.manual_seed(seed)
    policy = model.policy
    optimizer = torch.optim.Adam(policy.parameters(), lr=learning_rate)
    decay = torch.optim.lr_scheduler.LinearLR(optimizer, 1.0, 0.1, total_iters=max(1, epochs))
    x = {key: torch.as_tensor(value) for key, value in obs.items()}
    y, w = torch.as_tensor(actions), torch.as_tensor(present, dtype=torch.float32)
    rng = np.random.default_rng(seed)
    sizes = np.asarray(obs["mask"]).sum(axis=1)
    groups = [np.flatnonzero(sizes == k) for k in np.unique(sizes)]

    def squared(idx: Any) -> Any:
        mean = policy.get_distribution({key: value[idx] for key, value in x.items()}).mode()
        return (((mean - y[idx]) ** 2) * w[idx]).sum()

    def full_loss() -> float:
        with torch.no_grad():
            chunks = [torch.as_tensor(g[i : i + 4096]) for g in groups for i in range(0, len(g), 4096)]
            return float(sum(squared(idx) for idx in chunks) / w.sum())

    losses = [full_loss()]
    for _ in range(epochs):
        batches = [g[i : i + batch_size] for g in (rng.permutation(g) for g in groups)
                   for i in range(0, len(g), batch_size)]
        for b in rng.permutation(len(batches)):
            idx = torch.as_tensor(batches[b])
            loss = squared(idx) / w[idx].sum()
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
        decay.step()
        losses.append(full_loss())
    return losses


def dagger_round(model: Any, env_id: str, configs: Sequence[ScenarioConfig], steps: int, seed: int,
                 interface: InterfaceLike, expert: str | Labeller = "rg-mpc") -> EntityPairs:
    """The states ``model`` visits on the benchmark env of every config (``steps`` each, seeds from
    ``seed``), labelled by the expert (a policy name or a :class:`~training.bc.Labeller`; ``model``
    None: the expert's own states), concatenated."""
    parts = []
    for i, config in enumerate(configs):
        actor = None if model is None else SB3Policy(model, config, env_id, interface)
        parts.append(fleet_pairs(env_id, config, steps, seed + 1000 * i, interface, expert, actor))
    obs = {key: np.concatenate([p.observations[key] for p in parts]) for key in parts[0].observations}
    return EntityPairs(obs, np.concatenate([p.actions for p in parts]), np.concatenate([p.present for p in parts]))


#: A fleet run's hyperparameters and their defaults (``fleet.yml`` and ``--hp``).
#: ``tasks`` (preset names, :mod:`lawn_env.presets`), when given, replaces ``fleet_sizes``: the network
#: trains on those scenarios, each at its own K, with ``task_settings`` (dotted config keys, as
#: ``--set``) applied to every one.
_FLEET_KEYS = {"interface": "rl", "expert": "rg-mpc", "fleet_sizes": (3, 4, 8), "tasks": (), "task_settings": {},
               "epochs": 20, "batch_size": 256, "learning_rate": 1e-3, "dagger_iterations": 2, "dagger_timesteps": 2400,
               "width": 64, "heads": 4, "layers": 2}


def fleet_settings(params: Mapping[str, Any]) -> Hyperparameters:
    """A fleet run's hyperparameters, checked: the interface in the entity layout, the sizes sorted."""
    p = checked_settings(params, _FLEET_KEYS, "fleet")
    network = {key: p.pop(key) for key in ("width", "heads", "layers")}
    tasks = [p["tasks"]] if isinstance(p["tasks"], str) else list(p["tasks"])
    for task in tasks:
        if task not in presets.names():
            raise ValueError(f"fleet hyperparameter tasks: unknown preset {task!r}; valid: "
                             f"{', '.join(presets.names())}")
    if not isinstance(p["task_settings"], Mapping):
        raise ValueError(f"fleet hyperparameter task_settings={p['task_settings']!r}: a mapping of config keys")
    sizes = sorted({task_config(t, p["task_settings"]).num_agvs for t in tasks} if tasks
                   else {int(k) for k in p["fleet_sizes"]})
    return p | {"interface": resolve_interface(p["interface"]).to_dict() | {"layout": "entities"}, "tasks": tasks,
                "task_settings": dict(p["task_settings"]), "fleet_sizes": sizes, "network": network}


def task_config(task: str, settings: Mapping[str, Any]) -> ScenarioConfig:
    """The scenario of preset ``task`` with ``settings`` (dotted config keys) applied."""
    return presets.get(task).override(dict(settings))


def training_configs(config: ScenarioConfig, st: Mapping[str, Any]) -> list[ScenarioConfig]:
    """The scenarios a fleet run trains on: its ``tasks`` with ``task_settings``, else ``config`` at
    every size of ``fleet_sizes`` (with ``task_settings``)."""
    if st["tasks"]:
        return [task_config(t, st["task_settings"]) for t in st["tasks"]]
    return [config.override(dict(st["task_settings"]), num_agvs=k) for k in st["fleet_sizes"]]


def _dagger(model: Any, env_id: str, configs: list[Any], st: Hyperparameters, timesteps: int,
            episode_seed: int, expert: Labeller) -> list[Round]:
    """The expert's round and the DAgger rounds, each followed by a fit; the loss history."""
    per_size = max(1, timesteps // len(configs))
    obs, actions, present = dagger_round(None, env_id, configs, per_size, episode_seed, st["interface"], expert)
    fit_args = (st["epochs"], st["batch_size"], st["learning_rate"])
    history = [Round(round=0, samples=len(actions), losses=fit_fleet(model, obs, actions, present, *fit_args,
                                                                     seed=episode_seed))]
    for it in range(1, st["dagger_iterations"] + 1):
        more = dagger_round(model, env_id, configs, max(1, st["dagger_timesteps"] // len(configs)),
                            episode_seed + 100 * it, st["interface"], expert)
        obs = {key: np.concatenate([obs[key], more[0][key]]) for key in obs}
        actions, present = np.concatenate([actions, more[1]]), np.concatenate([present, more[2]])
        history.append(Round(round=it, samples=len(actions),
                             losses=fit_fleet(model, obs, actions, present, *fit_args, seed=episode_seed + it)))
    return history


def train_fleet(spec: Any, params: Mapping[str, Any], version: int) -> RunSummary:
    """``lawn train --algo fleet``: DAgger of a :class:`agents.fleet.FleetPolicy` on every size of
    ``fleet_sizes``, saved as a PPO model (``sb3:DIR`` loads it), validated on the spec's own K."""
    from stable_baselines3 import PPO

    from agents.fleet import FleetPolicy

    limit_torch_threads()
    if spec.env_id not in ("lawn/Joint-v1", "lawn/Comm-v1"):
        raise ValueError(f"fleet networks train on lawn/Joint-v1 or lawn/Comm-v1, not {spec.env_id!r}")
    st = fleet_settings(params)
    env = MixedFleetEnv(spec.env_id, st["fleet_sizes"], st["interface"], spec.config)  # checks the sizes
    start = time.perf_counter()
    model = PPO(FleetPolicy, env, seed=spec.seed, device="cpu", verbose=0,
                policy_kwargs={**st["network"], "log_std_init": -1.0})
    configs = training_configs(spec.config, st)
    expert = Labeller(st["expert"])
    history = _dagger(model, spec.env_id, configs, st, spec.timesteps, TRAIN_SEED_BASE + 1000 * spec.seed, expert)
    record = {"algo": "fleet", "target": "fleet", "trainer": "fleet", "env": spec.env_id, "seed": spec.seed,
              "timesteps": spec.timesteps, "interface": st["interface"], "fleet_sizes": st["fleet_sizes"],
              "tasks": st["tasks"], "task_settings": st["task_settings"],
              "num_timesteps": int(history[-1]["samples"]), "hyperparams_version": version,
              "wall_time_s": time.perf_counter() - start, "expert_decision_s": expert.clock.seconds,
              "eval_episodes": spec.eval_episodes, "versions": versions()}
    summary = save_imitation(spec, model, record, st, history)
    env.close()
    return summary
