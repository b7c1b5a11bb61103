"""``lawn train``: Stable-Baselines3 agents on the lawn environments (needs the ``rl`` extra).

One run directory holds everything needed to reload, evaluate, resume or audit the agent:

=====================  ==========================================================
``model.zip``          the SB3 model (final)
``vecnormalize.pkl``   observation/reward normalization statistics (if used)
``run.json``           algorithm, env id, seed, timesteps, versions, hyperparameter file version
``config.json``        the exact scenario config
``hyperparams.json``   the resolved hyperparameters (file + command-line overrides)
``learning_curve.csv`` periodic evaluation: timesteps, mean and std episode return
``learning_curve.png`` the same, plotted
``summary.md``         a short human-readable summary
``checkpoints/``       periodic checkpoints (model and normalization), used by ``--resume``
``tb/``                TensorBoard logs
=====================  ==========================================================

Hyperparameters come from ``training/hyperparams/<algo>.yml`` (versioned, per env id, in the
spirit of rl-baselines3-zoo) and can be overridden with ``--hp key=value``.
"""

from __future__ import annotations

import inspect
import json
import pickle
import platform
import re
import time
from pathlib import Path
from typing import Any, Mapping

import numpy as np

import lawn_env
from lawn_env import ScenarioConfig

__all__ = ["ALGOS", "TRAIN_ENV_IDS", "load_hyperparams", "train", "resume", "RunSpec"]

HYPERPARAMS_DIR = Path(__file__).parent / "hyperparams"
#: Environment ids ``lawn train`` accepts; ``lawn/Parallel-v0`` is the PettingZoo env (parameter sharing).
TRAIN_ENV_IDS = ("lawn/Joint-v0", "lawn/Comm-v0", "lawn/Parallel-v0", "CartPole-v1")


def _algos() -> dict[str, Any]:
    try:
        from stable_baselines3 import A2C, PPO, SAC, TD3
    except ImportError:  # exercised only without the extra
        from agents.errors import MissingExtra

        raise MissingExtra("training needs the rl extra: bash scripts/setup.sh full, "
                           "or pip install torch==2.13.0 && pip install -e '.[rl]'") from None
    return {"ppo": PPO, "sac": SAC, "td3": TD3, "a2c": A2C}


#: The algorithm names ``lawn train`` accepts (``bc`` is behaviour cloning, training/bc.py).
ALGOS = ("ppo", "sac", "td3", "a2c", "bc")
_OWN_KEYS = ("n_envs", "normalize", "policy")


def load_hyperparams(algo: str, env_id: str, overrides: Mapping[str, Any] | None = None) -> tuple[dict, int]:
    """Hyperparameters of ``algo`` for ``env_id`` from the versioned file, with overrides."""
    if algo not in ALGOS:
        raise ValueError(f"unknown algorithm {algo!r}; valid: {', '.join(ALGOS)}")
    if env_id not in TRAIN_ENV_IDS:
        raise ValueError(f"unknown env id {env_id!r}; valid: {', '.join(TRAIN_ENV_IDS)}")
    import yaml  # the rl extra

    data = yaml.safe_load((HYPERPARAMS_DIR / f"{algo}.yml").read_text())
    if env_id not in data:
        have = [k for k in data if k != "version"]
        raise ValueError(f"no {algo} hyperparameters for {env_id!r} in {algo}.yml; it has: {', '.join(have)}")
    params = dict(data[env_id])
    params.update(overrides or {})
    return params, int(data["version"])


def _check_algo_kwargs(cls, kwargs: Mapping[str, Any]) -> None:
    valid = set(inspect.signature(cls.__init__).parameters) - {"self", "env", "policy"}
    unknown = sorted(set(kwargs) - valid)
    if unknown:
        raise ValueError(f"unknown {cls.__name__} hyperparameters {unknown}; valid: {', '.join(sorted(valid))}")


def make_train_env(env_id: str, config: ScenarioConfig, n_envs: int, seed: int, normalize, monitor_dir: Path | None,
                   vecnormalize_path: Path | None = None, training: bool = True):
    """A seeded SB3 VecEnv (Monitor-wrapped) with optional VecNormalize."""
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecNormalize

    if env_id == "lawn/Parallel-v0":
        from .marl import make_marl_vec_env

        venv = make_marl_vec_env(config, n_envs, seed)
    else:
        kwargs = {} if env_id == "CartPole-v1" else {"config": config}
        venv = make_vec_env(env_id, n_envs=n_envs, seed=seed, env_kwargs=kwargs,
                            monitor_dir=str(monitor_dir) if monitor_dir else None)
    if vecnormalize_path is not None:
        venv = VecNormalize.load(str(vecnormalize_path), venv)
        venv.training = training
        if not training:
            venv.norm_reward = False
    elif normalize:
        opts = dict(normalize) if isinstance(normalize, Mapping) else {}
        venv = VecNormalize(venv, training=training, **opts)
        if not training:
            venv.norm_reward = False
    return venv


class RunSpec(dict):
    """The contents of ``run.json``."""


def train(algo: str, env_id: str, config: ScenarioConfig, timesteps: int, seed: int, out_dir: Path,
          hp_overrides: Mapping[str, Any] | None = None, n_envs: int | None = None, eval_every: int = 5000,
          eval_episodes: int = 5, checkpoint_every: int = 10000, progress: bool = True,
          init_from: Path | None = None) -> dict:
    """Train an agent from scratch; returns the run summary (also written to ``out_dir``)."""
    if timesteps < 1:
        raise ValueError(f"--timesteps must be >= 1, got {timesteps}")
    params, version = load_hyperparams(algo, env_id, hp_overrides)
    if n_envs is not None:
        params["n_envs"] = n_envs
    out_dir = Path(out_dir)
    if (out_dir / "run.json").exists():
        raise ValueError(f"{out_dir} already holds a run; use --resume {out_dir} or another --out")
    if algo == "bc":
        from .bc import train_bc_run

        return train_bc_run(env_id, config, timesteps, seed, out_dir, params, version, progress=progress)
    spec = RunSpec(algo=algo, env=env_id, seed=seed, timesteps=timesteps, hyperparams_version=version,
                   eval_every=eval_every, eval_episodes=eval_episodes, checkpoint_every=checkpoint_every,
                   init_from=str(init_from) if init_from else None, versions=_versions())
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "config.json").write_text(json.dumps(config.to_dict(), indent=2))
    (out_dir / "hyperparams.json").write_text(json.dumps(params, indent=2))
    (out_dir / "run.json").write_text(json.dumps(spec, indent=2))
    return _learn(spec, params, config, out_dir, start_model=None, progress=progress)


def resume(out_dir: Path, timesteps: int | None = None, progress: bool = True) -> dict:
    """Continue an interrupted run from its last checkpoint up to its (or a new) timestep target."""
    out_dir = Path(out_dir)
    if not (out_dir / "run.json").exists():
        raise ValueError(f"--resume {out_dir}: no run.json there (not a lawn train run directory)")
    spec = RunSpec(json.loads((out_dir / "run.json").read_text()))
    if spec["algo"] == "bc":
        raise ValueError("behaviour cloning runs are not resumable; rerun lawn train --algo bc")
    if timesteps is not None:
        spec["timesteps"] = timesteps
        (out_dir / "run.json").write_text(json.dumps(spec, indent=2))
    params = json.loads((out_dir / "hyperparams.json").read_text())
    config = ScenarioConfig.from_dict(json.loads((out_dir / "config.json").read_text()))
    checkpoint = latest_checkpoint(out_dir)
    if checkpoint is None:
        raise ValueError(f"--resume {out_dir}: no checkpoint in {out_dir / 'checkpoints'}")
    return _learn(spec, params, config, out_dir, start_model=checkpoint, progress=progress)


def latest_checkpoint(out_dir: Path) -> tuple[Path, Path | None, int] | None:
    found = []
    for path in (Path(out_dir) / "checkpoints").glob("model_*_steps.zip"):
        m = re.fullmatch(r"model_(\d+)_steps\.zip", path.name)
        if m:
            found.append((int(m.group(1)), path))
    if not found:
        return None
    steps, path = max(found)
    norm = path.parent / f"model_vecnormalize_{steps}_steps.pkl"
    return path, (norm if norm.exists() else None), steps


def limit_torch_threads() -> None:
    """One torch thread: these networks are small, and several threads per run oversubscribe the
    cores when runs go side by side (measured: SAC's update 100x slower with two concurrent runs)."""
    import torch

    torch.set_num_threads(1)


def _learn(spec: RunSpec, params: dict, config: ScenarioConfig, out_dir: Path, start_model, progress: bool) -> dict:
    from stable_baselines3.common.callbacks import CheckpointCallback, EvalCallback
    from stable_baselines3.common.utils import set_random_seed

    limit_torch_threads()
    algos = _algos()
    cls = algos[spec["algo"]]
    params = dict(params)
    n_envs = int(params.pop("n_envs", 1))
    normalize = params.pop("normalize", False)
    policy = params.pop("policy", "MlpPolicy")
    _check_algo_kwargs(cls, params)
    seed = int(spec["seed"])
    done_steps = start_model[2] if start_model else 0
    env_seed = seed + done_steps  # a resumed run continues with fresh, still seeded, episodes
    set_random_seed(env_seed)
    env = make_train_env(spec["env"], config, n_envs, env_seed, normalize, out_dir / "monitor",
                         vecnormalize_path=start_model[1] if start_model else None)
    eval_env = make_train_env(spec["env"], config, 1, seed + 10_000, normalize, None, training=False)
    if start_model:
        model = cls.load(str(start_model[0]), env=env, tensorboard_log=str(out_dir / "tb"))
    else:
        model = cls(policy, env, seed=seed if spec["env"] != "lawn/Parallel-v0" else None, verbose=0,
                    tensorboard_log=str(out_dir / "tb"), **params)
        if spec.get("init_from"):
            _init_from(model, Path(spec["init_from"]), env)
    remaining = int(spec["timesteps"]) - model.num_timesteps
    callbacks = [
        EvalCallback(eval_env, n_eval_episodes=int(spec["eval_episodes"]),
                     eval_freq=max(int(spec["eval_every"]) // n_envs, 1), log_path=str(out_dir / "eval"),
                     best_model_save_path=None, deterministic=True, verbose=0),
        CheckpointCallback(save_freq=max(int(spec["checkpoint_every"]) // n_envs, 1),
                           save_path=str(out_dir / "checkpoints"), name_prefix="model", save_vecnormalize=True),
    ]
    start = time.perf_counter()
    if remaining > 0:
        model.learn(total_timesteps=remaining, callback=callbacks, reset_num_timesteps=start_model is None,
                    progress_bar=progress, tb_log_name="run")
    elapsed = time.perf_counter() - start
    model.save(str(out_dir / "model.zip"))
    from stable_baselines3.common.vec_env import VecNormalize

    if isinstance(env, VecNormalize):
        env.save(str(out_dir / "vecnormalize.pkl"))
    spec_out = dict(spec)
    spec_out["num_timesteps"] = int(model.num_timesteps)
    spec_out["wall_time_s"] = float(elapsed + spec.get("wall_time_s", 0.0))
    (out_dir / "run.json").write_text(json.dumps(spec_out, indent=2))
    summary = write_learning_curve(out_dir, spec_out)
    env.close()
    eval_env.close()
    return summary


def _init_from(model, source: Path, env) -> None:
    """Start from a behaviour-cloned policy of the same algorithm (its weights and obs statistics)."""
    from stable_baselines3.common.vec_env import VecNormalize

    run = json.loads((source / "run.json").read_text())
    if run.get("target", run.get("algo")) != type(model).__name__.lower():
        raise ValueError(f"--init-from {source}: it holds a {run.get('target', run.get('algo'))} policy, "
                         f"not {type(model).__name__.lower()}")
    other = type(model).load(str(source / "model.zip"))
    model.policy.load_state_dict(other.policy.state_dict())
    norm_path = source / "vecnormalize.pkl"
    if isinstance(env, VecNormalize) and norm_path.exists():
        with open(norm_path, "rb") as fh:
            env.obs_rms = pickle.load(fh).obs_rms


def write_learning_curve(out_dir: Path, spec: Mapping[str, Any]) -> dict:
    """learning_curve.csv / .png and summary.md from the periodic evaluations."""
    out_dir = Path(out_dir)
    path = out_dir / "eval" / "evaluations.npz"
    rows = []
    if path.exists():
        data = np.load(path)
        for t, res in zip(data["timesteps"], data["results"]):
            rows.append({"timesteps": int(t), "mean_return": float(np.mean(res)), "std_return": float(np.std(res))})
    from .evaluate import write_rows

    if rows:
        write_rows(rows, out_dir / "learning_curve.csv")
        _plot_curve(rows, out_dir / "learning_curve.png", f"{spec['algo']} on {spec['env']}, seed {spec['seed']}")
    final = rows[-1] if rows else None
    summary = {
        "algo": spec["algo"], "env": spec["env"], "seed": spec["seed"], "timesteps": spec.get("num_timesteps"),
        "wall_time_s": spec.get("wall_time_s"),
        "final_eval_mean_return": final["mean_return"] if final else None,
        "best_eval_mean_return": max(r["mean_return"] for r in rows) if rows else None,
    }
    lines = [f"# {spec['algo']} on {spec['env']}", ""]
    lines += [f"- {k}: {v}" for k, v in summary.items()]
    (out_dir / "summary.md").write_text("\n".join(lines) + "\n")
    return summary


def _plot_curve(rows, path: Path, title: str) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6, 3.5), dpi=110)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(111)
    t = [r["timesteps"] for r in rows]
    m = np.array([r["mean_return"] for r in rows])
    s = np.array([r["std_return"] for r in rows])
    ax.plot(t, m, "-o", ms=3)
    ax.fill_between(t, m - s, m + s, alpha=0.2)
    ax.set_xlabel("environment steps")
    ax.set_ylabel("evaluation return (mean ± std)")
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)


def _versions() -> dict:
    import gymnasium
    import stable_baselines3
    import torch

    return {"lawn": lawn_env.__version__, "stable_baselines3": stable_baselines3.__version__,
            "torch": torch.__version__, "gymnasium": gymnasium.__version__, "python": platform.python_version()}
