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

import json
import time
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from agents.learned import SB3Policy
from lawn_env import ScenarioConfig
from lawn_env.entities import EntityLayout
from lawn_env.interface import InterfaceLike, resolve_interface

from .bc import collect

__all__ = ["fleet_pairs", "fit_fleet", "dagger_round", "fleet_settings", "train_fleet_run"]


def fleet_pairs(env_id: str, config: ScenarioConfig, steps: int, seed: int, interface: InterfaceLike,
                expert: str = "rg-mpc", actor: Any = None) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """``steps`` labelled transitions of the v0 env of ``config`` (:func:`training.bc.collect`, the
    states visited by ``actor``, default the expert) in the entity layout: the observations (a
    dict of (steps, ...) arrays), the expert's entity actions (steps, A) and which entries carry a
    label (steps, A) bool: the AGVs present and the drone."""
    iface = resolve_interface(interface)
    obs, labels, _ = collect(env_id, config, expert, steps, seed, iface, actor=actor)
    layout = EntityLayout(config, "joint" if env_id == "lawn/Joint-v1" else "comm", iface.obs_bound)
    present = np.zeros((len(labels), layout.action_space.shape[0]), dtype=bool)
    present[:, layout.gather] = True
    return layout.observe(obs), layout.to_entity_actions(labels), present


def fit_fleet(model: Any, obs: dict[str, np.ndarray], actions: np.ndarray, present: np.ndarray, epochs: int,
              batch_size: int, learning_rate: float, seed: int) -> list[float]:
    """Mean-squared-error regression of the model's deterministic action on the labelled entries;
    returns the loss over the whole data set before the first epoch and after each. The step size
    falls by 0.9 ``learning_rate`` / ``epochs`` after each epoch (a tenth of it would come after the
    last). Every batch holds one fleet size (the network then attends over that many rows, not the data's largest
    fleet); the batches of an epoch come in random order."""
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
                 interface: InterfaceLike, expert: str = "rg-mpc"
                 ) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """The states ``model`` visits on the v0 env of every config (``steps`` each, seeds from
    ``seed``), labelled by the expert (``model`` None: the expert's own states), concatenated."""
    parts = []
    for i, config in enumerate(configs):
        actor = None if model is None else SB3Policy(model, config, env_id, interface)
        parts.append(fleet_pairs(env_id, config, steps, seed + 1000 * i, interface, expert, actor))
    obs = {key: np.concatenate([p[0][key] for p in parts]) for key in parts[0][0]}
    return obs, np.concatenate([p[1] for p in parts]), np.concatenate([p[2] for p in parts])


_SETTINGS = ("interface", "expert", "fleet_sizes", "epochs", "batch_size", "learning_rate", "dagger_iterations",
             "dagger_timesteps", "width", "heads", "layers")


def fleet_settings(params: Mapping[str, Any]) -> dict[str, Any]:
    """A fleet run's hyperparameters (``fleet.yml`` and ``--hp``), resolved: the interface in the
    entity layout, the sizes sorted; an unknown one raises an error naming it."""
    p = {k: v for k, v in dict(params).items() if k != "n_envs"}  # the expert's rollouts run in one env
    unknown = sorted(set(p) - set(_SETTINGS))
    if unknown:
        raise ValueError(f"unknown fleet hyperparameters {unknown}; valid: {', '.join(_SETTINGS)}")
    iface = resolve_interface(p.get("interface", "rl")).to_dict() | {"layout": "entities"}
    sizes = sorted({int(k) for k in p.get("fleet_sizes", (3, 4, 8))})
    return {"interface": iface, "expert": p.get("expert", "rg-mpc"), "fleet_sizes": sizes,
            "epochs": int(p.get("epochs", 20)), "batch_size": int(p.get("batch_size", 256)),
            "learning_rate": float(p.get("learning_rate", 1e-3)),
            "dagger_iterations": int(p.get("dagger_iterations", 2)),
            "dagger_timesteps": int(p.get("dagger_timesteps", 2400)),
            "network": {"width": int(p.get("width", 64)), "heads": int(p.get("heads", 4)),
                        "layers": int(p.get("layers", 2))}}


def _dagger(model: Any, env_id: str, configs: list, st: dict, timesteps: int, episode_seed: int) -> list[dict]:
    """The expert's round and the DAgger rounds, each followed by a fit; the loss history."""
    per_size = max(1, timesteps // len(configs))
    obs, actions, present = dagger_round(None, env_id, configs, per_size, episode_seed, st["interface"], st["expert"])
    fit_args = (st["epochs"], st["batch_size"], st["learning_rate"])
    history = [{"round": 0, "samples": len(actions), "losses": fit_fleet(model, obs, actions, present, *fit_args,
                                                                          seed=episode_seed)}]
    for it in range(1, st["dagger_iterations"] + 1):
        more = dagger_round(model, env_id, configs, max(1, st["dagger_timesteps"] // len(configs)),
                            episode_seed + 100 * it, st["interface"], st["expert"])
        obs = {key: np.concatenate([obs[key], more[0][key]]) for key in obs}
        actions, present = np.concatenate([actions, more[1]]), np.concatenate([present, more[2]])
        history.append({"round": it, "samples": len(actions),
                        "losses": fit_fleet(model, obs, actions, present, *fit_args, seed=episode_seed + it)})
    return history


def train_fleet_run(env_id: str, config: ScenarioConfig, timesteps: int, seed: int, out_dir: Path,
                    params: Mapping[str, Any], version: int, eval_episodes: int = 5) -> dict:
    """``lawn train --algo fleet``: DAgger of a :class:`agents.fleet.FleetPolicy` from the expert on
    every size of ``fleet_sizes`` (``config`` with that K), saved as a PPO model in the run's usual
    layout (``sb3:DIR`` loads it), validated on ``config``'s own K."""
    from stable_baselines3 import PPO

    from agents.fleet import FleetPolicy
    from lawn_env import MixedFleetEnv

    from .callbacks import ControlCostValidation
    from .protocol import (TRAIN_SEED_BASE, VALIDATION_SEED_BASE, append_learning_curve, limit_torch_threads,
                           versions, write_learning_curve)

    limit_torch_threads()
    if env_id not in ("lawn/Joint-v1", "lawn/Comm-v1"):
        raise ValueError(f"fleet networks train on lawn/Joint-v1 or lawn/Comm-v1, not {env_id!r}")
    st = fleet_settings(params)
    env = MixedFleetEnv(env_id, st["fleet_sizes"], st["interface"], config)  # checks the sizes
    start = time.perf_counter()
    model = PPO(FleetPolicy, env, seed=seed, device="cpu", verbose=0,
                policy_kwargs={**st["network"], "log_std_init": -1.0})
    configs = [config.override(num_agvs=k) for k in st["fleet_sizes"]]
    history = _dagger(model, env_id, configs, st, timesteps, TRAIN_SEED_BASE + 1000 * seed)
    wall = time.perf_counter() - start
    out_dir = Path(out_dir)  # written once the network is trained and validated: a failed run leaves nothing
    validation = ControlCostValidation(env_id, config, st["interface"], episodes=eval_episodes, every=1,
                                       out_dir=out_dir, seed_base=VALIDATION_SEED_BASE)
    validation.model = model
    row = validation.validate()
    env.close()
    out_dir.mkdir(parents=True, exist_ok=True)
    model.save(str(out_dir / "model.zip"))
    spec = {"algo": "fleet", "target": "fleet", "trainer": "fleet", "env": env_id, "seed": seed, "timesteps": timesteps,
            "interface": st["interface"], "fleet_sizes": st["fleet_sizes"],
            "num_timesteps": int(history[-1]["samples"]), "hyperparams_version": version,
            "wall_time_s": wall, "eval_episodes": eval_episodes, "versions": versions()}
    for name, data in (("config.json", config.to_dict()), ("hyperparams.json", st), ("bc_losses.json", history)):
        (out_dir / name).write_text(json.dumps(data, indent=2))
    (out_dir / "learning_curve.csv").unlink(missing_ok=True)
    append_learning_curve(out_dir, history[-1]["samples"], row)
    summary = write_learning_curve(out_dir, spec)
    (out_dir / "run.json").write_text(json.dumps(spec, indent=2))  # last: a run with run.json is a finished one
    summary.update(bc_loss_first=history[0]["losses"][0], bc_loss_last=history[-1]["losses"][-1])
    return summary
