"""Episodes of any policy as a Minari dataset (``lawn dataset create``, the ``data`` extra), and
the behaviour-cloning pairs of episodes, recorded or live (:func:`label_transitions`,
:func:`dataset_transitions`; :mod:`training.bc` clones from them). A dataset's reference scores are
``epa``'s and ``dv-mpc``'s mean returns on its seeds, so ``minari.get_normalized_score`` is the
normalized score / 100.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any, NamedTuple

import gymnasium as gym
import numpy as np

import lawn_env
from agents import make_policy, rollout
from agents.errors import MissingExtra
from evaluation.episode import EpisodeSpec
from evaluation.provenance import provenance
from evaluation.run import evaluate
from evaluation.stats import SCORE_HIGH, SCORE_LOW
from lawn_env import ENV_IDS, ObservationLayout, ScenarioConfig, env_role, presets
from lawn_env.interface import InterfaceLike, action_codec, resolve_interface
from lawn_env.presets import resolve_config
from lawn_env.spaces import check_action

if TYPE_CHECKING:
    import minari

__all__ = ["Pairs", "Recorded", "label_transitions", "dataset_transitions", "create_dataset", "load_dataset",
           "DATA_EXTRA",
           "DATASET_ENV_IDS"]

DATA_EXTRA = "datasets need the data extra (minari): pip install -e '.[data]' (bash scripts/setup.sh full installs it)"
#: Datasets record the benchmark envs (the RL ids reshape the reward and end episodes early).
DATASET_ENV_IDS = ("lawn/Joint-v1", "lawn/Comm-v1")


class Pairs(NamedTuple):
    """Behaviour-cloning pairs: the observations as the learner sees them and the actions in its scheme."""

    observations: np.ndarray
    actions: np.ndarray


class Recorded(NamedTuple):
    """A dataset's pairs, the control costs and seeds of its episodes and the policy that recorded them."""

    observations: np.ndarray
    actions: np.ndarray
    costs: list[float]
    seeds: list[Any]
    policy: str | None


def label_transitions(config: ScenarioConfig, env_id: str, interface: InterfaceLike,
                      episodes: Iterable[tuple[np.ndarray, np.ndarray]]) -> Pairs:
    """Behaviour-cloning pairs from v0 episodes ((T, n) observations, (T, m) actions): the observations
    as the learner sees them and the actions in the interface's scheme (decoded as v0, encoded in it)."""
    iface = resolve_interface(interface)
    role = env_role(env_id)
    v0, scheme = action_codec(config, role, None), action_codec(config, role, iface)
    layout = ObservationLayout(config)
    obs_out, act_out = [], []
    for observations, actions in episodes:
        scheme.reset()  # the stake prior's MPC starts every episode afresh, as the envs' MPC does
        for o, a in zip(observations, actions, strict=True):
            state = layout.decode(o)
            args = (state["x_aug"], state["reference"], state["drone_position"], state["slot"])
            act_out.append(scheme.encode(v0.decode(check_action(a, v0.size), *args), *args))
            obs_out.append(iface.observe(np.array(o, dtype=np.float32)))
    n, m = layout.size, scheme.size
    return Pairs(np.array(obs_out, dtype=np.float32).reshape(-1, n), np.array(act_out, dtype=np.float32).reshape(-1, m))


def dataset_transitions(dataset_id: str, env_id: str, config: ScenarioConfig, steps: int, interface: InterfaceLike
                        ) -> Recorded:
    """The first ``steps`` transitions of a Minari dataset of ``env_id`` with ``config`` as pairs
    (:func:`label_transitions`), their episodes' control costs and seeds and the policy that recorded them."""
    dataset = load_dataset(dataset_id)
    spec = dataset.spec.env_spec
    recorded_env, recorded_config = spec.id, (spec.kwargs or {}).get("config", "default")
    if recorded_env != env_id:
        raise ValueError(f"--dataset {dataset_id!r} holds episodes of {recorded_env}; this run trains on {env_id}")
    if resolve_config(recorded_config) != config:
        raise ValueError(f"--dataset {dataset_id!r} was recorded with config {recorded_config!r}, not this run's "
                         "scenario: pass the same --preset/--set")
    chosen, seeds, costs, left = [], [], [], steps
    metadata = dataset.storage.get_episode_metadata(dataset.episode_indices)
    for episode, meta in zip(dataset.iterate_episodes(), metadata, strict=False):
        if left <= 0:
            break
        obs, actions = np.asarray(episode.observations, dtype=np.float32)[:-1], np.asarray(episode.actions, np.float32)
        chosen.append((obs[:left], actions[:left]))
        seeds.append(meta.get("seed"))
        costs.append(float(np.sum(episode.infos["stage_cost"][1:])))
        left -= len(actions)
    obs, labels = label_transitions(config, env_id, interface, chosen)
    return Recorded(obs, labels, costs, seeds, dataset.storage.metadata.get("algorithm_name"))


def _minari() -> Any:  # the minari module (an optional extra: not followed)
    try:
        import minari
    except ImportError:
        raise MissingExtra(DATA_EXTRA) from None
    return minari


def create_dataset(policy: str, env_id: str, episodes: int, seed: int, dataset_id: str, task: str = "default",
                   progress: bool = True) -> minari.MinariDataset:
    """Record ``episodes`` seeded episodes of ``policy`` on ``env_id`` (the scenario of preset ``task``)
    as the Minari dataset ``dataset_id``; returns the ``MinariDataset``."""
    minari = _minari()
    from minari import DataCollector, StepDataCallback
    from tqdm.auto import tqdm


    class LawnStepData(StepDataCallback):  # type: ignore[misc]  # minari is an optional extra, not followed
        """The env's per-step info without ``episode_metrics`` (present on the last step only)."""

        def __call__(self, env: Any, **kwargs: Any) -> Any:
            data = super().__call__(env, **kwargs)
            data["info"] = {k: np.asarray(v) for k, v in data["info"].items() if k != "episode_metrics"}
            return data

    if env_id not in DATASET_ENV_IDS:
        raise ValueError(f"--env {env_id!r}: datasets record {' or '.join(DATASET_ENV_IDS)} (the unmodified "
                         f"scenario every policy acts on); registered ids: {', '.join(ENV_IDS)}")
    if episodes < 1 or seed < 0:
        raise ValueError(f"episodes={episodes}, seed={seed}: episodes must be >= 1 and the seed >= 0")
    _check_dataset_id(dataset_id)
    config = presets.get(task)
    agent = make_policy(policy, config, env_id=env_id)  # fails fast on a bad name or a mismatched agent
    if dataset_id in minari.list_local_datasets():
        raise ValueError(f"--dataset-id {dataset_id!r} already exists under MINARI_DATASETS_PATH; choose another id "
                         f"or delete it (minari delete {dataset_id})")
    references = (SCORE_LOW, SCORE_HIGH)  # Minari's reference scores: their mean returns on the same seeds
    specs = [EpisodeSpec(p, env_id, config, seed + i) for p in references for i in range(episodes)]
    rows = evaluate(specs, progress=False)
    low, high = (-float(np.mean([r.control_cost for r in rows if r.policy == p])) for p in references)
    env = DataCollector(gym.make(env_id, config=task), step_data_callback=LawnStepData, record_infos=True)
    for i in tqdm(range(episodes), desc=f"dataset {dataset_id}", unit="ep", disable=None if progress else True):
        rollout(env, agent, seed + i)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="`author_email` is set to None")
        plain = gym.make(env_id, config=task)  # the recorded env without the recorder: Minari checks the scores
        dataset = env.create_dataset(
            dataset_id=dataset_id, eval_env=plain.spec, algorithm_name=policy, author="lawn dataset create",
            code_permalink=provenance(),
            description=f"{episodes} full episodes (seeds {seed}-{seed + episodes - 1}) of {policy} on {env_id}, "
                        f"task {task!r}: the unmodified scenario",
            requirements=[f"lawn=={lawn_env.__version__}"], ref_min_score=low, ref_max_score=high)
    plain.close()
    env.close()
    return dataset


def _check_dataset_id(dataset_id: str) -> None:
    """ValueError naming ``--dataset-id`` unless the id has Minari's form ``(NAMESPACE/)NAME-vN``."""
    from minari.utils import parse_dataset_id

    try:
        name, version = parse_dataset_id(dataset_id)[1:]
    except (ValueError, TypeError):
        name = version = None
    if not name or version is None:
        raise ValueError(f"--dataset-id {dataset_id!r}: Minari ids have the form NAMESPACE/NAME-vN (the namespace "
                         "optional), e.g. lawn/comm/rg-mpc-v0")


def load_dataset(dataset_id: str) -> minari.MinariDataset:
    """``minari.load_dataset``, naming the extra when minari is missing and the local ids otherwise."""
    minari = _minari()
    local = minari.list_local_datasets()
    if dataset_id not in local:
        raise ValueError(f"unknown dataset {dataset_id!r} under MINARI_DATASETS_PATH; local datasets: "
                         f"{', '.join(local) or 'none'} (lawn dataset create records one)")
    return minari.load_dataset(dataset_id)
