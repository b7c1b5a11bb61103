"""Behaviour cloning of an expert, with optional DAgger relabelling (``lawn train --algo bc``).

1. Roll out the expert (``rg-mpc`` by default) for ``timesteps`` transitions of seeded episodes
   and record (observation, action) pairs.
2. Fit the policy network of an SB3 algorithm (``target``: PPO or SAC) by mean-squared error
   between its deterministic action and the expert's, on observations normalized with the
   expert data's running mean and variance (saved as ``vecnormalize.pkl``).
3. DAgger: run the cloned policy for ``dagger_timesteps`` more transitions, label the states it
   visits with the expert's actions, add them to the data set and fit again; ``dagger_iterations``
   times.

The result is an SB3 model in the run directory's usual layout, so ``lawn evaluate --policy
bc:DIR`` and ``lawn train --algo ppo --init-from DIR`` use it directly.
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path
from typing import Any, Iterable, Mapping

import gymnasium as gym
import numpy as np

from agents import Step, make_policy, rollout
from agents.learned import ObsNormalizer, SB3Policy
from agents.rollouts import Actor
from agents.runs import algorithm_class
from lawn_env import ObservationLayout, ScenarioConfig
from lawn_env.presets import resolve_config
from lawn_env.interface import InterfaceLike, RLInterface, action_codec, resolve_interface
from lawn_env.spaces import check_action

__all__ = ["collect", "label_transitions", "fit", "train_bc_run", "BC_TARGETS"]

#: The algorithms whose policy network behaviour cloning fits (the ``target`` hyperparameter).
BC_TARGETS = ("ppo", "sac")


def collect(env_id: str, config: ScenarioConfig, expert_name: str, steps: int, seed: int, interface: InterfaceLike,
            actor: Actor | None = None) -> tuple[np.ndarray, np.ndarray, list[float]]:
    """``steps`` transitions of seeded episodes (seed, seed + 1, ...) of the v0 env; states visited by
    ``actor`` (a v0 policy, default the expert) and labelled with the expert's action there
    (:func:`label_transitions`). Returns the observations as the learner sees them (the
    interface's clipping), the labels and the costs of the episodes that ended."""
    env = gym.make(env_id, config=config)
    expert = make_policy(expert_name, config, env_id=env_id)
    driver = _Labelling(expert, actor)
    episodes: list[tuple[list, list]] = []
    costs = []
    count = 0

    def on_step(step: Step) -> bool:
        nonlocal count
        episodes[-1][0].append(step.obs.copy())
        episodes[-1][1].append(driver.expert_action)
        count += 1
        return count >= steps

    episode = 0
    while count < steps:
        episodes.append(([], []))
        run = rollout(env, driver, seed + episode, on_step=on_step)
        if run.ended:
            costs.append(run.metrics["control_cost"])
        episode += 1
    env.close()
    obs, labels = label_transitions(config, env_id, interface, [(np.array(o), np.array(a)) for o, a in episodes])
    return obs, labels, costs


def label_transitions(config: ScenarioConfig, env_id: str, interface: InterfaceLike,
                      episodes: Iterable[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """Behaviour-cloning pairs from v0 transitions: per episode (in order), the v0 observations
    (T, n) and the v0 actions (T, m) chosen there, whoever chose them (a live expert, a Minari
    dataset). Returns the observations as the learner sees them (the interface's clipping) and the
    actions re-expressed in the interface's scheme (decode as v0, encode in the scheme)."""
    iface = resolve_interface(interface)
    role = "joint" if env_id == "lawn/Joint-v0" else "comm"
    v0, scheme = action_codec(config, role, None), action_codec(config, role, iface)
    layout = ObservationLayout(config)
    obs_out, act_out = [], []
    for observations, actions in episodes:
        scheme.reset()  # the stake prior's MPC starts every episode afresh, as the envs' MPC does
        for o, a in zip(observations, actions):
            state = layout.decode(o)
            args = (state["x_aug"], state["reference"], state["drone_position"], state["slot"])
            act_out.append(scheme.encode(v0.decode(check_action(a, v0.size), *args), *args))
            obs_out.append(iface.observe(np.array(o, dtype=np.float32)))
    n, m = layout.size, scheme.size
    return (np.array(obs_out, dtype=np.float32).reshape(-1, n), np.array(act_out, dtype=np.float32).reshape(-1, m))


class _Labelling:
    """Drives the env with ``actor`` (default: the expert) while the expert decides every slot, so
    that each visited state gets the expert's action (``expert_action``)."""

    def __init__(self, expert, actor=None):
        self.expert, self.actor = expert, actor
        self.expert_action = None

    def reset(self, seed: int | None = None) -> None:
        self.expert.reset(seed)
        if self.actor is not None:
            self.actor.reset(seed)

    def act(self, obs: np.ndarray) -> np.ndarray:
        self.expert_action = self.expert.act(obs)  # the expert decides every slot, also when it does not act
        return self.expert_action if self.actor is None else self.actor.act(obs)


def _deterministic_action(model, obs_tensor):
    from stable_baselines3 import SAC

    if isinstance(model, SAC):
        return model.policy.actor(obs_tensor, deterministic=True)
    return model.policy.get_distribution(obs_tensor).mode()


def fit(model: Any, obs: np.ndarray, actions: np.ndarray, epochs: int, batch_size: int, learning_rate: float,
        seed: int) -> list[float]:
    """Mean-squared-error regression of the model's deterministic action on the expert's; returns
    the loss of every epoch (over the whole data set, before the epoch's updates for epoch 0)."""
    import torch

    torch.manual_seed(seed)
    policy = model.policy
    params = list(model.policy.actor.parameters()) if hasattr(policy, "actor") else list(policy.parameters())
    optimizer = torch.optim.Adam(params, lr=learning_rate)
    x = torch.as_tensor(obs)
    y = torch.as_tensor(actions)
    rng = np.random.default_rng(seed)
    losses = []

    def full_loss() -> float:
        with torch.no_grad():
            return float(((_deterministic_action(model, x) - y) ** 2).mean())

    losses.append(full_loss())
    for _ in range(epochs):
        order = rng.permutation(len(x))
        for start in range(0, len(x), batch_size):
            idx = torch.as_tensor(order[start : start + batch_size])
            loss = ((_deterministic_action(model, x[idx]) - y[idx]) ** 2).mean()
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
        losses.append(full_loss())
    return losses


def dataset_transitions(dataset_id: str, env_id: str, config: ScenarioConfig, steps: int, interface: InterfaceLike
                        ) -> tuple[np.ndarray, np.ndarray, list[float], list, str | None]:
    """The first ``steps`` transitions of a Minari dataset (``lawn dataset create``) as
    behaviour-cloning pairs (:func:`label_transitions`), with the control costs and seeds of the
    episodes they come from and the policy that recorded them (the dataset's ``algorithm_name``).
    The dataset must hold episodes of ``env_id`` with ``config``."""
    from .datasets import dataset_task, episodes_of, load_dataset

    dataset = load_dataset(dataset_id)
    recorded_env, recorded_config = dataset_task(dataset)
    if recorded_env != env_id:
        raise ValueError(f"--dataset {dataset_id!r} holds episodes of {recorded_env}; this run trains on {env_id}")
    if resolve_config(recorded_config) != config:
        raise ValueError(f"--dataset {dataset_id!r} was recorded with config {recorded_config!r}, not this run's "
                         "scenario: pass the same --preset/--set")
    chosen, seeds, costs, left = [], [], [], steps
    for (seed, obs, actions), episode in zip(episodes_of(dataset), dataset.iterate_episodes()):
        if left <= 0:
            break
        chosen.append((obs[:left], actions[:left]))
        seeds.append(seed)
        costs.append(float(np.sum(episode.infos["stage_cost"][1:])))
        left -= len(actions)
    obs, labels = label_transitions(config, env_id, interface, chosen)
    return obs, labels, costs, seeds, dataset.storage.metadata.get("algorithm_name")


@dataclasses.dataclass(frozen=True)
class _Settings:
    """A BC run's hyperparameters, resolved (:func:`_settings`)."""

    expert: str
    target: str
    interface: RLInterface
    epochs: int
    batch_size: int
    learning_rate: float
    dagger_iterations: int
    dagger_timesteps: int
    policy_kwargs: dict

    def to_dict(self) -> dict:
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        out["interface"] = self.interface.to_dict()
        return out


def _settings(params: Mapping[str, Any]) -> _Settings:
    """The hyperparameters of a BC run, with a clear error for an unknown one."""
    p = dict(params)
    p.pop("n_envs", None)  # expert rollouts run in one environment
    target = p.pop("target", "ppo")
    if target not in BC_TARGETS:
        raise ValueError(f"bc target {target!r}; valid: {', '.join(BC_TARGETS)}")
    policy_kwargs = p.pop("policy_kwargs", {})
    if target == "sac":
        policy_kwargs = {k: v for k, v in policy_kwargs.items() if k != "log_std_init"}
    st = _Settings(target=target, expert=p.pop("expert", "rg-mpc"), epochs=int(p.pop("epochs", 30)),
                   batch_size=int(p.pop("batch_size", 256)), learning_rate=float(p.pop("learning_rate", 1e-3)),
                   dagger_iterations=int(p.pop("dagger_iterations", 0)),
                   dagger_timesteps=int(p.pop("dagger_timesteps", 1200)),
                   interface=resolve_interface(p.pop("interface", "v0")), policy_kwargs=policy_kwargs)
    if p:
        raise ValueError(f"unknown bc hyperparameters {sorted(p)}; valid: expert, target, interface, epochs, "
                         "batch_size, learning_rate, dagger_iterations, dagger_timesteps, policy_kwargs")
    return st


def _write_records(out_dir: Path, config: ScenarioConfig, st: _Settings, spec: dict, history: list) -> None:
    """config.json, hyperparams.json, run.json and bc_losses.json of a BC run."""
    (out_dir / "config.json").write_text(json.dumps(config.to_dict(), indent=2))
    (out_dir / "hyperparams.json").write_text(json.dumps(st.to_dict(), indent=2))
    (out_dir / "run.json").write_text(json.dumps(spec, indent=2))
    (out_dir / "bc_losses.json").write_text(json.dumps(history, indent=2))


def _clone_with_dagger(env_id: str, config: ScenarioConfig, st: _Settings, expert: str, obs: np.ndarray,
                       actions: np.ndarray, seed: int, episode_seed: int):
    """Fit the clone to the expert's transitions, then the DAgger rounds (the clone drives, the
    expert labels); the normalizing env (its statistics fixed from the expert's observations), the
    model, every observation and the losses of every round."""
    from stable_baselines3.common.running_mean_std import RunningMeanStd
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    venv = VecNormalize(DummyVecEnv([lambda: gym.make(env_id, config=config, interface=st.interface)]),
                        norm_reward=False)
    venv.obs_rms = RunningMeanStd(shape=obs.shape[1:])
    venv.obs_rms.update(obs.astype(np.float64))
    venv.training = False
    model = algorithm_class(st.target)("MlpPolicy", venv, seed=seed, policy_kwargs=st.policy_kwargs, verbose=0,
                                       device="cpu")

    def normalized(o):
        return venv.normalize_obs(o).astype(np.float32)

    history = [{"round": 0, "samples": len(obs), "losses": fit(model, normalized(obs), actions, st.epochs,
                                                                st.batch_size, st.learning_rate, seed)}]
    for it in range(1, st.dagger_iterations + 1):
        actor = SB3Policy(model, config, env_id, st.interface, ObsNormalizer.from_vecnormalize(venv))
        new_obs, new_act, _ = collect(env_id, config, expert, st.dagger_timesteps, episode_seed + 100 * it,
                                      st.interface, actor=actor)
        obs, actions = np.concatenate([obs, new_obs]), np.concatenate([actions, new_act])
        history.append({"round": it, "samples": len(obs), "losses": fit(model, normalized(obs), actions, st.epochs,
                                                                         st.batch_size, st.learning_rate, seed + it)})
    return venv, model, obs, history


def train_bc_run(env_id: str, config: ScenarioConfig, timesteps: int, seed: int, out_dir: Path,
                 params: Mapping[str, Any], version: int, progress: bool = True, dataset: str | None = None,
                 eval_episodes: int = 5) -> dict:
    """Clone, DAgger, save; one validation of the clone on ``eval_episodes`` validation seeds."""
    from .callbacks import ControlCostValidation
    from .protocol import (
        TRAIN_SEED_BASE,
        VALIDATION_SEED_BASE,
        append_learning_curve,
        limit_torch_threads,
        versions,
        write_learning_curve,
    )

    limit_torch_threads()
    if env_id not in ("lawn/Joint-v0", "lawn/Comm-v0"):
        raise ValueError(f"behaviour cloning runs on lawn/Joint-v0 or lawn/Comm-v0, not {env_id!r}")
    st = _settings(params)
    target, expert, interface = st.target, st.expert, st.interface
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    episode_seed = TRAIN_SEED_BASE + 1000 * seed  # expert episodes never use test or validation seeds
    if dataset is None:
        obs, actions, expert_costs = collect(env_id, config, expert, timesteps, episode_seed, interface)
    else:  # the dataset's episodes are the expert data; DAgger rounds ask the same policy live
        obs, actions, expert_costs, dataset_seeds, recorded = dataset_transitions(dataset, env_id, config, timesteps,
                                                                                  interface)
        if st.dagger_iterations and recorded != expert:  # relabelling by another policy would mix two experts
            raise ValueError(f"--dataset {dataset!r} holds episodes of {recorded}, DAgger's expert is {expert}: "
                             f"pass --hp expert={recorded} or --hp dagger_iterations=0")
        expert = recorded or "unrecorded"  # the policy whose actions are cloned
    venv, model, obs, history = _clone_with_dagger(env_id, config, st, expert, obs, actions, seed, episode_seed)
    elapsed = time.perf_counter() - start
    model.save(str(out_dir / "model.zip"))
    venv.save(str(out_dir / "vecnormalize.pkl"))
    spec = {"algo": target, "target": target, "trainer": "bc", "env": env_id, "seed": seed, "timesteps": timesteps,
            "interface": interface.to_dict(),
            "num_timesteps": int(len(obs)), "hyperparams_version": version, "wall_time_s": elapsed,
            "eval_episodes": eval_episodes,
            "expert_mean_control_cost": float(np.mean(expert_costs)) if expert_costs else None,
            "dataset": None if dataset is None else {"id": dataset, "episode_seeds": dataset_seeds},
            "versions": versions()}
    _write_records(out_dir, config, dataclasses.replace(st, expert=expert), spec, history)
    validation = ControlCostValidation(env_id, config, interface.to_dict(), episodes=eval_episodes, every=1,
                                       out_dir=out_dir, seed_base=VALIDATION_SEED_BASE)
    validation.model = model
    (out_dir / "learning_curve.csv").unlink(missing_ok=True)
    append_learning_curve(out_dir, len(obs), validation.validate())
    summary = write_learning_curve(out_dir, spec)
    summary.update(bc_loss_first=history[0]["losses"][0], bc_loss_last=history[-1]["losses"][-1])
    venv.close()
    return summary
