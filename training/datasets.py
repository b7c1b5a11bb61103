"""Episodes of any policy as a Minari dataset (``lawn dataset create``), and reading them back.

``create_dataset("rg-mpc", "lawn/Comm-v0", episodes=100, seed=0, dataset_id="lawn/comm/rg-mpc-v0")``
plays seeded, full episodes of the unmodified scenario (seed ``seed + i`` for episode i, as
``lawn evaluate --seed``) under a policy (an expert, a baseline, an anchor or a learned agent),
through Minari's ``DataCollector``, and stores them under ``MINARI_DATASETS_PATH`` (default
``~/.minari/datasets``): observations, actions, rewards, terminations, truncations and the env's
per-step info (every key but the episode-end summary ``episode_metrics``, whose structure is not
per step; the first info of an episode is the reset's). The env is made from a preset name
(``config="default"`` or a suite task), so its spec is plain JSON and
``dataset.recover_environment()`` rebuilds it. Each episode's summed ``infos["stage_cost"]``
(steps 1..T) is the episode's control cost, which ``lawn evaluate`` reports for that seed.

The dataset carries Minari's reference scores: ``ref_min_score`` the mean return of ``epa`` and
``ref_max_score`` that of the best expert (``dv-mpc``) on the same seeds, task and env (run beside the recording), so
``minari.get_normalized_score(dataset, returns)`` is the package's normalized score / 100
(:mod:`training.score`: 0 equal power, 1 the best expert). Behaviour cloning trains from such a dataset (``lawn train --algo bc --dataset ID``,
:func:`training.bc.dataset_transitions`). ``minari`` is in the ``data`` extra (``pip install -e '.[data]'``).
"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING, Any, Iterator

import gymnasium as gym
import numpy as np

from agents import make_policy, rollout
from agents.errors import MissingExtra
import lawn_env
from lawn_env import ENV_IDS, presets

from .provenance import provenance

if TYPE_CHECKING:
    import minari

__all__ = ["create_dataset", "check_dataset_id", "load_dataset", "episodes_of", "dataset_task", "DATA_EXTRA"]

DATA_EXTRA = "datasets need the data extra (minari): pip install -e '.[data]' (bash scripts/setup.sh full installs it)"
#: Policies act on these envs; the RL ids reshape the reward and end episodes early.
DATASET_ENV_IDS = ("lawn/Joint-v0", "lawn/Comm-v0")


def _minari():
    try:
        import minari
    except ImportError:
        raise MissingExtra(DATA_EXTRA) from None
    return minari


def _step_data_callback():
    from minari import StepDataCallback

    class LawnStepData(StepDataCallback):
        """The env's per-step info without ``episode_metrics`` (present on the last step only)."""

        def __call__(self, env, **kwargs):
            data = super().__call__(env, **kwargs)
            data["info"] = {k: np.asarray(v) for k, v in data["info"].items() if k != "episode_metrics"}
            return data

    return LawnStepData


def check_dataset_id(dataset_id: str) -> None:
    """ValueError naming ``--dataset-id`` unless the id has Minari's form ``(NAMESPACE/)NAME-vN``."""
    from minari.utils import parse_dataset_id

    try:
        _, name, version = parse_dataset_id(dataset_id)
    except (ValueError, TypeError):
        name, version = None, None
    if not name or version is None:
        raise ValueError(f"--dataset-id {dataset_id!r}: Minari ids have the form NAMESPACE/NAME-vN (the namespace "
                         "optional), e.g. lawn/comm/rg-mpc-v0")


def create_dataset(policy: str, env_id: str, episodes: int, seed: int, dataset_id: str, task: str = "default",
                   progress: bool = True, description: str | None = None) -> "minari.MinariDataset":
    """Record ``episodes`` seeded episodes of ``policy`` on ``env_id`` (the scenario of preset ``task``)
    as the Minari dataset ``dataset_id``; returns the ``MinariDataset``."""
    minari = _minari()
    from minari import DataCollector
    from tqdm.auto import tqdm

    if env_id not in DATASET_ENV_IDS:
        raise ValueError(f"--env {env_id!r}: datasets record {' or '.join(DATASET_ENV_IDS)} (the unmodified "
                         f"scenario every policy acts on); registered ids: {', '.join(ENV_IDS)}")
    if episodes < 1:
        raise ValueError(f"episodes={episodes}: must be >= 1")
    if seed < 0:
        raise ValueError(f"seed={seed}: must be >= 0")
    check_dataset_id(dataset_id)
    config = presets.get(task)
    agent = make_policy(policy, config, env_id=env_id)  # fails fast on a bad name or a mismatched agent
    if dataset_id in minari.list_local_datasets():
        raise ValueError(f"--dataset-id {dataset_id!r} already exists under MINARI_DATASETS_PATH; choose another id "
                         f"or delete it (minari delete {dataset_id})")
    low, high = _reference_returns(env_id, config, seed, episodes)
    env = DataCollector(gym.make(env_id, config=task), step_data_callback=_step_data_callback(), record_infos=True)
    for i in tqdm(range(episodes), desc=f"dataset {dataset_id}", unit="ep", disable=None if progress else True):
        rollout(env, agent, seed + i)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="`author_email` is set to None")
        dataset = env.create_dataset(
            dataset_id=dataset_id, eval_env=_plain_spec(env_id, task), algorithm_name=policy, author="lawn dataset create",
            code_permalink=provenance(),
            description=description or (f"{episodes} full episodes (seeds {seed}-{seed + episodes - 1}) of {policy} "
                                        f"on {env_id}, task {task!r}: the unmodified scenario"),
            requirements=[f"lawn=={lawn_env.__version__}"], ref_min_score=low, ref_max_score=high)
    env.close()
    return dataset


def _plain_spec(env_id: str, task: str) -> gym.envs.registration.EnvSpec:
    """The spec of the env the dataset was recorded on, without the recording wrapper (Minari makes
    it again to check the reference scores)."""
    env = gym.make(env_id, config=task)
    spec = env.spec
    env.close()
    return spec


def _reference_returns(env_id: str, config: Any, seed: int, episodes: int) -> tuple[float, float]:
    """The mean returns (minus the control cost: the v0 envs' reward) of ``epa`` and the best expert on the
    dataset's seeds, task and env: Minari's ``ref_min_score`` and ``ref_max_score``."""
    from .evaluate import evaluate
    from .score import SCORE_HIGH, SCORE_LOW

    tasks = [(p, env_id, config, seed + i, {}) for p in (SCORE_LOW, SCORE_HIGH) for i in range(episodes)]
    rows = evaluate(tasks, progress=False)
    low, high = (-float(np.mean([r["control_cost"] for r in rows if r["policy"] == p])) for p in (SCORE_LOW, SCORE_HIGH))
    return low, high


def load_dataset(dataset_id: str) -> "minari.MinariDataset":
    """``minari.load_dataset`` with the extra's message when minari is missing and the valid ids
    when the id is unknown."""
    minari = _minari()
    local = minari.list_local_datasets()
    if dataset_id not in local:
        raise ValueError(f"unknown dataset {dataset_id!r} under MINARI_DATASETS_PATH; local datasets: "
                         f"{', '.join(local) or 'none'} (lawn dataset create records one)")
    return minari.load_dataset(dataset_id)


def dataset_task(dataset: "minari.MinariDataset") -> tuple[str, Any]:
    """The env id and the ``config`` argument the dataset's episodes were recorded with."""
    spec = dataset.spec.env_spec
    return spec.id, (spec.kwargs or {}).get("config", "default")


def episodes_of(dataset: "minari.MinariDataset") -> Iterator[tuple[int | None, np.ndarray, np.ndarray]]:
    """(seed, observations (T, n) the actions were chosen from, actions (T, m)) per episode, in
    recorded order."""
    metadata = dataset.storage.get_episode_metadata(dataset.episode_indices)
    for episode, meta in zip(dataset.iterate_episodes(), metadata):
        obs = np.asarray(episode.observations, dtype=np.float32)
        yield meta.get("seed"), obs[:-1], np.asarray(episode.actions, dtype=np.float32)
