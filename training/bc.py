"""Behaviour cloning of an expert with DAgger relabelling (``lawn train --algo bc``).

Cloning fits the policy network of an SB3 algorithm (``target``) by mean-squared error to the
expert's actions (live, or from a Minari dataset: :mod:`training.datasets`) on normalized
observations; each DAgger round lets the clone drive, labels the states it visits with the
expert's actions and fits again. The expert decides on the run's clock (:class:`Labeller`).
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Mapping
from typing import Any, NamedTuple, TypedDict

import gymnasium as gym
import numpy as np

from agents import Step, make_policy, rollout
from agents.base import Policy
from agents.learned import ObsNormalizer, SB3Policy
from agents.runs import algorithm_class
from agents.timing import DecisionClock
from evaluation.seeds import TRAIN_SEED_BASE
from lawn_env import ScenarioConfig
from lawn_env.interface import InterfaceLike, RLInterface, resolve_interface
from lawn_env.rollouts import Actor

from .datasets import dataset_transitions, label_transitions
from .spec import Hyperparameters
from .validation import RunSummary, append_learning_curve, limit_torch_threads, versions, write_learning_curve

__all__ = ["Labeller", "Round", "Demonstrations", "collect", "fit", "BCSettings", "bc_settings", "train_bc",
           "BC_TARGETS"]

#: The algorithms whose policy network behaviour cloning fits (the ``target`` hyperparameter).
BC_TARGETS = ("ppo", "sac")


@dataclasses.dataclass(frozen=True)
class Labeller:
    """The expert that labels a run's transitions (a policy name, :func:`agents.make_policy`), deciding
    on the run's ``clock`` (how much of the run its decisions take: ``run.json``'s ``expert_decision_s``)."""

    name: str
    clock: DecisionClock = dataclasses.field(default_factory=DecisionClock)

    def policy(self, config: ScenarioConfig, env_id: str) -> Policy:
        """The expert for ``config`` on ``env_id``, timed on the clock."""
        return self.clock.timed(make_policy(self.name, config, env_id=env_id))


class Round(TypedDict):
    """One fit of an imitation run (``bc_losses.json``): round 0 on the expert's states, then each DAgger
    round; the samples it fitted on and its loss after each epoch."""

    round: int
    samples: int
    losses: list[float]


class Demonstrations(NamedTuple):
    """Labelled transitions: the observations (steps, n), the expert's actions (steps, m) and the
    control costs of the episodes that ended."""

    observations: np.ndarray
    actions: np.ndarray
    costs: list[float]


def collect(env_id: str, config: ScenarioConfig, expert: str | Labeller, steps: int, seed: int,
            interface: InterfaceLike, actor: Actor | None = None) -> Demonstrations:
    """``steps`` transitions of seeded episodes (seed, seed + 1, ...) of the benchmark env: the states ``actor``
    (default: the expert, a policy name or a :class:`Labeller`) visits labelled with the expert's action,
    and the costs of the episodes that ended."""
    env = gym.make(env_id, config=config)
    labeller = expert if isinstance(expert, Labeller) else Labeller(expert)
    driver = _Labelling(labeller.policy(config, env_id), actor)
    episodes: list[tuple[list[Any], list[Any]]] = []
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
    return Demonstrations(obs, labels, costs)


class _Labelling:
    """Drives the env with ``actor`` (default: the expert) while the expert decides every slot."""

    def __init__(self, expert: Any, actor: Actor | None = None):
        self.expert, self.actor = expert, actor
        self.expert_action = None

    def reset(self, seed: int | None = None) -> None:
        self.expert.reset(seed)
        if self.actor is not None:
            self.actor.reset(seed)

    def act(self, obs: np.ndarray) -> np.ndarray:
        self.expert_action = action = self.expert.act(obs)  # the expert decides every slot, also when it does not act
        return action if self.actor is None else self.actor.act(obs)


def _deterministic_action(model: Any, obs_tensor: Any) -> Any:
    from stable_baselines3 import SAC

    if isinstance(model, SAC):
        return model.policy.actor(obs_tensor, deterministic=True)
    return model.policy.get_distribution(obs_tensor).mode()


def fit(model: Any, obs: np.ndarray, actions: np.ndarray, epochs: int, batch_size: int, learning_rate: float,
        seed: int) -> list[float]:
    """Mean-squared-error regression of the model's deterministic action on the expert's; the loss over
    the whole data set before the first epoch and after each."""
    import torch

    torch.manual_seed(seed)
    policy = model.policy
    params = list(model.policy.actor.parameters()) if hasattr(policy, "actor") else list(policy.parameters())
    optimizer = torch.optim.Adam(params, lr=learning_rate)
    x, y = torch.as_tensor(obs), torch.as_tensor(actions)
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


#: A BC run's hyperparameters and their defaults (``bc.yml`` and ``--hp``).
_BC_KEYS = {"expert": "rg-mpc", "target": "ppo", "interface": "v0", "epochs": 30, "batch_size": 256,
            "learning_rate": 1e-3, "dagger_iterations": 0, "dagger_timesteps": 1200, "policy_kwargs": {}}


@dataclasses.dataclass(frozen=True)
class BCSettings:
    """A BC run's hyperparameters, resolved (:func:`bc_settings`)."""

    expert: str
    target: str
    interface: RLInterface
    epochs: int
    batch_size: int
    learning_rate: float
    dagger_iterations: int
    dagger_timesteps: int
    policy_kwargs: Hyperparameters


def checked_settings(params: Mapping[str, Any], defaults: Mapping[str, Any], noun: str) -> Hyperparameters:
    """``params`` over ``defaults``, numbers as the default's type (``n_envs`` ignored: the expert's
    rollouts run in one env); an unknown key raises an error naming it."""
    p = {**defaults, **{k: v for k, v in params.items() if k != "n_envs"}}
    unknown = sorted(set(p) - set(defaults))
    if unknown:
        raise ValueError(f"unknown {noun} hyperparameters {unknown}; valid: {', '.join(defaults)}")
    return {k: type(defaults[k])(v) if type(defaults[k]) in (int, float) else v for k, v in p.items()}


def bc_settings(params: Mapping[str, Any]) -> BCSettings:
    """The hyperparameters of a BC run, checked (an unknown key or ``target`` is named)."""
    p = checked_settings(params, _BC_KEYS, "bc")
    if p["target"] not in BC_TARGETS:
        raise ValueError(f"bc target {p['target']!r}; valid: {', '.join(BC_TARGETS)}")
    if p["target"] == "sac":
        p["policy_kwargs"] = {k: v for k, v in p["policy_kwargs"].items() if k != "log_std_init"}
    return BCSettings(**p | {"interface": resolve_interface(p["interface"])})


def _clone_with_dagger(env_id: str, config: ScenarioConfig, st: BCSettings, expert: Labeller, obs: np.ndarray,
                       actions: np.ndarray, seed: int, episode_seed: int
                       ) -> tuple[Any, Any, np.ndarray, list[Round]]:
    """Fit the clone, then the DAgger rounds; the normalizing env (the expert's observation statistics),
    the model, every observation and every round's losses."""
    from stable_baselines3.common.running_mean_std import RunningMeanStd
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    venv: Any = VecNormalize(DummyVecEnv([lambda: gym.make(env_id, config=config, interface=st.interface)]),
                             norm_reward=False)
    venv.obs_rms = RunningMeanStd(shape=obs.shape[1:])
    venv.obs_rms.update(obs.astype(np.float64))
    venv.training = False
    cls: Any = algorithm_class(st.target)  # a concrete SB3 class: mypy sees the base's signature
    model = cls("MlpPolicy", venv, seed=seed, policy_kwargs=st.policy_kwargs, verbose=0, device="cpu")

    def normalized(o: np.ndarray) -> np.ndarray:
        normalized_obs: np.ndarray = venv.normalize_obs(o).astype(np.float32)
        return normalized_obs

    history = [Round(round=0, samples=len(obs), losses=fit(model, normalized(obs), actions, st.epochs,
                                                           st.batch_size, st.learning_rate, seed))]
    for it in range(1, st.dagger_iterations + 1):
        actor = SB3Policy(model, config, env_id, st.interface, ObsNormalizer.from_vecnormalize(venv))
        new_obs, new_act, _ = collect(env_id, config, expert, st.dagger_timesteps, episode_seed + 100 * it,
                                      st.interface, actor=actor)
        obs, actions = np.concatenate([obs, new_obs]), np.concatenate([actions, new_act])
        history.append(Round(round=it, samples=len(obs), losses=fit(model, normalized(obs), actions, st.epochs,
                                                                    st.batch_size, st.learning_rate, seed + it)))
    return venv, model, obs, history


def _expert_data(spec: Any, st: BCSettings, episode_seed: int, clock: DecisionClock) -> tuple[Any, ...]:
    """The expert's transitions (live, deciding on ``clock``, or a dataset's: DAgger then asks the
    policy that recorded them), costs, the dataset record and the expert's name."""
    if spec.dataset is None:
        obs, actions, costs = collect(spec.env_id, spec.config, Labeller(st.expert, clock), spec.timesteps,
                                      episode_seed, st.interface)
        return obs, actions, costs, None, st.expert
    obs, actions, costs, seeds, recorded = dataset_transitions(spec.dataset, spec.env_id, spec.config, spec.timesteps,
                                                               st.interface)
    if st.dagger_iterations and recorded != st.expert:  # relabelling by another policy would mix two experts
        raise ValueError(f"--dataset {spec.dataset!r} holds episodes of {recorded}, DAgger's expert is {st.expert}: "
                         f"pass --hp expert={recorded} or --hp dagger_iterations=0")
    return obs, actions, costs, {"id": spec.dataset, "episode_seeds": seeds}, recorded or "unrecorded"


def train_bc(spec: Any, params: Mapping[str, Any], version: int) -> RunSummary:
    """Clone, DAgger and save the run of ``spec`` (a :class:`training.spec.TrainSpec`)."""
    limit_torch_threads()
    st = bc_settings(params)
    start = time.perf_counter()
    episode_seed = TRAIN_SEED_BASE + 1000 * spec.seed  # expert episodes never use test or validation seeds
    clock = DecisionClock()
    obs, actions, expert_costs, dataset, expert = _expert_data(spec, st, episode_seed, clock)
    venv, model, obs, history = _clone_with_dagger(spec.env_id, spec.config, st, Labeller(expert, clock), obs,
                                                   actions, spec.seed, episode_seed)
    record = {"algo": st.target, "target": st.target, "trainer": "bc", "env": spec.env_id, "seed": spec.seed,
              "timesteps": spec.timesteps, "interface": st.interface.to_dict(), "num_timesteps": len(obs),
              "hyperparams_version": version, "wall_time_s": time.perf_counter() - start,
              "expert_decision_s": clock.seconds, "eval_episodes": spec.eval_episodes,
              "expert_mean_control_cost": float(np.mean(expert_costs)) if expert_costs else None,
              "dataset": dataset, "versions": versions()}
    hyperparams = vars(st) | {"expert": expert, "interface": st.interface.to_dict()}
    summary = save_imitation(spec, model, record, hyperparams, history)
    venv.close()
    return summary


def save_imitation(spec: Any, model: Any, record: dict[str, Any], hyperparams: Hyperparameters,
                   history: list[Round]) -> RunSummary:
    """Validate an imitation-trained model once on ``spec.eval_episodes`` validation seeds and write
    its run; ``run.json`` last (a run with it is a finished one), nothing at all on a failure before."""
    from .callbacks import ControlCostValidation, save_model

    validation = ControlCostValidation(spec.env_id, spec.config, record["interface"], spec.eval_episodes, 1,
                                       spec.out_dir)
    validation.model = model
    row = validation.validate()
    out_dir = spec.out_dir
    out_dir.mkdir(parents=True, exist_ok=True)
    save_model(model, out_dir)
    for name, data in (("config.json", spec.config.to_dict()), ("hyperparams.json", hyperparams),
                       ("bc_losses.json", history)):
        (out_dir / name).write_text(json.dumps(data, indent=2))
    (out_dir / "learning_curve.csv").unlink(missing_ok=True)
    append_learning_curve(out_dir, record["num_timesteps"], row)
    summary = write_learning_curve(out_dir, record)
    (out_dir / "run.json").write_text(json.dumps(record, indent=2))
    return dataclasses.replace(summary, bc_loss_first=history[0]["losses"][0], bc_loss_last=history[-1]["losses"][-1])
