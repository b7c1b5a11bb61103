"""``lawn train``: Stable-Baselines3 agents on the lawn environments (needs the ``rl`` extra).

One run directory holds everything needed to reload, evaluate, resume or audit the agent:

=========================  ==========================================================
``model.zip``              the SB3 model (final)
``vecnormalize.pkl``       observation/reward normalization statistics (if used)
``best_model.zip``         the model selected on the validation seeds (lowest paired difference
                           against rg-mpc among the start and the validations significantly better
                           than it: :func:`training.protocol.selected_validation`), and
``best_vecnormalize.pkl``  its statistics; ``sb3:DIR`` loads these when present
``run.json``               algorithm, env id, seed, timesteps, interface, versions, hyperparameter file version
``config.json``            the exact scenario config
``hyperparams.json``       the resolved hyperparameters (file + command-line overrides)
``learning_curve.csv``     periodic validation: timesteps, mean realized control cost of full
                           episodes of the unmodified scenario on the validation seeds, paired
                           differences against rg-mpc and against the start
``validation_start.json``  the starting policy's cost on each validation seed
``learning_curve.png``     the same, plotted
``summary.md``             a short human-readable summary
``checkpoints/<N>/``       the newest checkpoint (model, normalization, replay buffer, selected model,
                           history lengths; :mod:`training.checkpoints`), used by ``--resume``
``tb/``                    TensorBoard logs
=========================  ==========================================================

Hyperparameters come from ``training/hyperparams/<algo>.yml`` (versioned, per env id, in the
spirit of rl-baselines3-zoo) and can be overridden with ``--hp key=value``. Each entry names the
interface the agent trains with (:mod:`lawn_env.interface`; ``rl`` by default, ``--interface v0``
trains on the plain v0 interface). Whatever the interface, the periodic validation and every
comparison run full 120-slot episodes of the unmodified scenario and report their realized
control cost.

Seeds: :mod:`training.protocol` (training, validation and test seeds never meet).
"""

from __future__ import annotations

import json
import pickle
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

from agents.learned import load_saved
from agents.runs import ALGORITHMS, algorithm_class, read_json, read_run
from lawn_env import ENV_IDS, PARALLEL_ENV_ID, ScenarioConfig
from lawn_env.interface import InterfaceLike, resolve_interface

from .options import RunOptions, split_params, start_at_anchor
from .checkpoints import Checkpoint, clear_history, latest_checkpoint, restore_history
from .protocol import TRAIN_SEED_BASE, VALIDATION_SEED_BASE, limit_torch_threads, versions, write_learning_curve

__all__ = ["ALGOS", "TRAIN_ENV_IDS", "load_hyperparams", "train", "train_seeds", "train_task", "resume", "RunSpec",
           "TRAIN_SEED_BASE", "VALIDATION_SEED_BASE"]


HYPERPARAMS_DIR = Path(__file__).parent / "hyperparams"
#: Environment ids ``lawn train`` accepts; ``lawn/Parallel-v0`` is the PettingZoo env (parameter sharing).
TRAIN_ENV_IDS = (*ENV_IDS, PARALLEL_ENV_ID, "CartPole-v1")


#: The algorithm names ``lawn train`` accepts (``bc`` is behaviour cloning, training/bc.py).
ALGOS = (*ALGORITHMS, "bc")  # "fleet" (training/fleet.py) is in ALGORITHMS: its model is a PPO one


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


def make_train_env(env_id: str, config: ScenarioConfig, n_envs: int, seed: int, normalize: bool | Mapping[str, Any],
                   monitor_dir: Path | None, vecnormalize_path: Path | None = None, training: bool = True,
                   interface: InterfaceLike = None, append_monitor: bool = False,
                   vec: str = "dummy") -> Any:
    """A seeded SB3 VecEnv (Monitor-wrapped) with optional VecNormalize, on the given interface;
    ``append_monitor`` continues existing monitor logs (a resumed run) instead of replacing them.
    ``vec="native"`` runs the copies in lawn's batched vector env (:mod:`training.vec`; episode
    statistics through ``VecMonitor``, no monitor files) instead of one SB3 ``DummyVecEnv`` of
    single envs."""
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    if vec not in ("dummy", "native"):
        raise ValueError(f"--vec {vec!r}; valid: dummy, native")
    if vec == "native":
        from .vec import NATIVE_ENV_IDS, NativeVecEnv

        if env_id not in NATIVE_ENV_IDS:
            raise ValueError(f"--vec native runs {', '.join(NATIVE_ENV_IDS)} (got {env_id}); pass --vec dummy")
        venv = VecMonitor(NativeVecEnv(config, n_envs, env_id, interface=interface))
        venv.seed(seed)
    elif env_id == PARALLEL_ENV_ID:
        from .marl import make_marl_vec_env

        venv = make_marl_vec_env(config, n_envs, seed, interface=interface)
    else:
        kwargs = {} if env_id == "CartPole-v1" else {"config": config, "interface": interface}
        venv = make_vec_env(env_id, n_envs=n_envs, seed=seed, env_kwargs=kwargs,
                            monitor_dir=str(monitor_dir) if monitor_dir else None,
                            monitor_kwargs={"override_existing": not append_monitor})
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
          init_from: Path | None = None, interface: str | Mapping | None = None, callbacks: list | None = None,
          vec: str = "dummy", dataset: str | None = None) -> dict:
    """Train an agent from scratch; returns the run summary (also written to ``out_dir``).

    ``callbacks`` are extra SB3 callbacks, run after the run's own (validation, checkpoints);
    ``vec="native"`` trains on lawn's batched vector env (:func:`make_train_env`).
    ``interface`` (``"rl"``, ``"v0"`` or a dict of :class:`lawn_env.RLInterface` fields) replaces
    the hyperparameter file's choice. ``dataset`` (behaviour cloning only) is a Minari dataset id whose
    episodes are the expert data (:mod:`training.datasets`) instead of live expert rollouts."""
    if dataset is not None and algo != "bc":
        raise ValueError(f"--dataset {dataset!r}: only behaviour cloning (--algo bc) trains from a dataset")
    if timesteps < 1:
        raise ValueError(f"--timesteps must be >= 1, got {timesteps}")
    params, version = load_hyperparams(algo, env_id, hp_overrides)
    if n_envs is not None:
        params["n_envs"] = n_envs
    if interface is not None:
        params["interface"] = interface
    if env_id != "CartPole-v1":
        params["interface"] = resolve_interface(params.get("interface", "v0")).to_dict()
    out_dir = Path(out_dir)
    if (out_dir / "run.json").exists():
        raise ValueError(f"{out_dir} already holds a run; use --resume {out_dir} or another --out")
    if algo not in ("bc", "fleet"):
        split_params(algo, env_id, params, vec)  # every option checked before anything is written
    if algo == "bc":
        from .bc import train_bc_run

        return train_bc_run(env_id, config, timesteps, seed, out_dir, params, version, progress=progress,
                            dataset=dataset, eval_episodes=eval_episodes)
    if algo == "fleet":
        from .fleet import train_fleet_run

        return train_fleet_run(env_id, config, timesteps, seed, out_dir, params, version, eval_episodes=eval_episodes)
    if init_from is not None:
        _check_init_from(Path(init_from), algo, params)
    spec = RunSpec(algo=algo, env=env_id, seed=seed, timesteps=timesteps, hyperparams_version=version,
                   interface=params.get("interface"),
                   eval_every=eval_every, eval_episodes=eval_episodes, checkpoint_every=checkpoint_every,
                   init_from=str(init_from) if init_from else None, vec=vec, versions=versions())
    existed = out_dir.exists()
    out_dir.mkdir(parents=True, exist_ok=True)
    written = [out_dir / name for name in ("config.json", "hyperparams.json", "run.json", "monitor", "tb")]
    (out_dir / "config.json").write_text(json.dumps(config.to_dict(), indent=2))
    (out_dir / "hyperparams.json").write_text(json.dumps(params, indent=2))
    (out_dir / "run.json").write_text(json.dumps(spec, indent=2))
    try:
        run = _setup(spec, params, config, out_dir, start=None, callbacks=callbacks)
    except BaseException:  # a model SB3 refuses to build: nothing of the run is left behind
        if not existed:
            shutil.rmtree(out_dir, ignore_errors=True)
        for path in written:
            shutil.rmtree(path, ignore_errors=True) if path.is_dir() else path.unlink(missing_ok=True)
        raise
    return _learn(run, progress=progress)


def _check_init_from(init_from: Path, algo: str, params: Mapping[str, Any]) -> None:
    """``--init-from``: a finished run of the same algorithm, interface and network as this run's."""
    source = read_run(init_from, "--init-from")
    theirs = source.record.get("target", source.record.get("algo"))
    if theirs != algo:
        raise ValueError(f"--init-from {init_from}: it holds a {theirs} policy, not {algo}")
    if not (Path(init_from) / "model.zip").exists():
        raise ValueError(f"--init-from {init_from}: no model.zip there (the run did not finish)")
    if source.interface != params.get("interface"):
        raise ValueError(f"--init-from {init_from}: it was trained with interface {source.interface}, "
                         f"this run uses {params.get('interface')}; pass the same --interface")
    hp_file = Path(init_from) / "hyperparams.json"
    theirs = _net_arch(json.loads(hp_file.read_text())) if hp_file.exists() else None
    if theirs is not None and theirs != _net_arch(params):
        raise ValueError(f"--init-from {init_from}: its network is net_arch={theirs}, this run builds "
                         f"net_arch={_net_arch(params)}; pass --hp 'policy_kwargs={{\"net_arch\": {theirs}}}'")


def resume(out_dir: Path, timesteps: int | None = None, progress: bool = True) -> dict:
    """Continue an interrupted run from its last checkpoint up to its (or a new) timestep target.

    The resumed run reaches the target with the update count of an uninterrupted run, its history
    (learning curve, monitor logs) appended to what the checkpoint had, and the replay buffer of
    an off-policy algorithm restored (:mod:`training.checkpoints`). A run killed before its first
    checkpoint restarts from scratch; a finished run is left alone unless ``timesteps`` extends it."""
    out_dir = Path(out_dir)
    run = read_run(out_dir, "--resume")
    spec = RunSpec(run.record)
    for key in ("algo", "env", "seed", "timesteps", "checkpoint_every", "eval_every", "eval_episodes"):
        if key not in spec:
            raise ValueError(f"--resume {out_dir}: run.json has no {key!r} (not written by lawn train)")
    if spec["algo"] == "bc":
        raise ValueError("behaviour cloning runs are not resumable; rerun lawn train --algo bc")
    params = read_json(out_dir / "hyperparams.json", "--resume", "the run directory is incomplete")
    config = run.load_config("--resume", "the run directory is incomplete")
    target = int(spec["timesteps"]) if timesteps is None else int(timesteps)
    checkpoint = latest_checkpoint(out_dir)
    done = int(spec.get("num_timesteps") or 0)
    if done >= target and (out_dir / "model.zip").exists():
        raise ValueError(f"--resume {out_dir}: the run is finished ({done} steps, target {target}); "
                         f"pass --timesteps above {done} to train it further")
    if checkpoint is not None and checkpoint.steps >= target:
        raise ValueError(f"--resume {out_dir}: --timesteps {target} is not above the last checkpoint's "
                         f"{checkpoint.steps} steps")
    split_params(spec["algo"], spec["env"], params, spec.get("vec", "dummy"))  # before any file is touched
    spec["timesteps"] = target
    spec.pop("num_timesteps", None)
    if checkpoint is None and any((out_dir / "checkpoints").glob("model_*_steps.zip")):
        raise ValueError(f"--resume {out_dir}: its checkpoints (checkpoints/model_<N>_steps.zip) were written by an "
                         "older lawn, which checkpointed before the update; retrain the run")
    if checkpoint is None:  # killed before its first checkpoint: start over, cleanly
        clear_history(out_dir)
        spec["wall_time_s"] = 0.0
    else:
        restore_history(out_dir, checkpoint)
        spec["wall_time_s"] = float(checkpoint.state.get("wall_time_s", 0.0))
    (out_dir / "run.json").write_text(json.dumps(spec, indent=2))
    summary = _learn(_setup(spec, params, config, out_dir, start=checkpoint), progress=progress)
    summary["resumed_from"] = checkpoint.steps if checkpoint is not None else None
    return summary


@dataclass
class _Run:
    """A run ready to learn: its spec, model, env, callbacks and where it writes."""

    spec: RunSpec
    model: Any
    env: Any
    hooks: list
    out_dir: Path
    wall_before: float
    resumed: bool


def _setup(spec: RunSpec, params: dict, config: ScenarioConfig, out_dir: Path, start: Checkpoint | None,
           callbacks: list | None = None) -> _Run:
    """The env, the model and the callbacks of a run (new or resumed from ``start``)."""
    from stable_baselines3.common.utils import set_random_seed

    limit_torch_threads()
    cls = algorithm_class(spec["algo"])
    options = split_params(spec["algo"], spec["env"], params, spec.get("vec", "dummy"))
    seed = int(spec["seed"])
    done_steps = start.steps if start else 0
    env_seed = TRAIN_SEED_BASE + 1000 * seed + done_steps  # a resumed run continues with fresh, still seeded, episodes
    set_random_seed(env_seed)
    env = make_train_env(spec["env"], config, options.n_envs, env_seed, options.normalize, out_dir / "monitor",
                         vecnormalize_path=start.vecnormalize if start else None, interface=options.interface,
                         append_monitor=start is not None, vec=spec.get("vec", "dummy"))
    try:
        model = _model(cls, spec, env, start, out_dir, options)
    except BaseException:
        env.close()
        raise
    wall_before = float(spec.get("wall_time_s", 0.0))
    hooks = _hooks(spec, config, options.interface, out_dir, wall_before, options.actor_warmup_steps)
    return _Run(spec, model, env, hooks + list(callbacks or []), out_dir, wall_before, start is not None)


def _learn(run: _Run, progress: bool) -> dict:
    """Train a set-up run to its timestep target; save the model, its statistics and the curve."""
    model, env, spec, out_dir = run.model, run.env, run.spec, run.out_dir
    remaining = int(spec["timesteps"]) - model.num_timesteps
    began = time.perf_counter()
    if remaining > 0:
        model.learn(total_timesteps=remaining, callback=run.hooks, reset_num_timesteps=not run.resumed,
                    progress_bar=progress, tb_log_name="run")
    elapsed = time.perf_counter() - began
    model.save(str(out_dir / "model.zip"))
    from stable_baselines3.common.vec_env import VecNormalize

    if isinstance(env, VecNormalize):
        env.save(str(out_dir / "vecnormalize.pkl"))
    spec_out = dict(spec)
    spec_out["num_timesteps"] = int(model.num_timesteps)
    spec_out["updates"] = int(getattr(model, "_n_updates", 0))
    spec_out["wall_time_s"] = float(elapsed + run.wall_before)
    (out_dir / "run.json").write_text(json.dumps(spec_out, indent=2))
    summary = write_learning_curve(out_dir, spec_out)
    env.close()
    return summary


def _model(cls, spec: RunSpec, env, start: Checkpoint | None, out_dir: Path, options: RunOptions):
    """The model a run trains: its checkpoint's, or a new one (from a cloned run's weights, at the
    anchor, with the fine-tuning's exploration noise as the spec asks)."""
    if start:
        model = load_saved(lambda p: cls.load(p, env=env, tensorboard_log=str(out_dir / "tb")), start.model,
                           "checkpoint model")
        if start.replay_buffer is not None:
            model.load_replay_buffer(str(start.replay_buffer))
        return model
    model = cls(options.policy, env, seed=int(spec["seed"]) if spec["env"] != PARALLEL_ENV_ID else None, verbose=0,
                tensorboard_log=str(out_dir / "tb"), **options.algo_kwargs)
    if spec.get("init_from"):
        _init_from(model, Path(spec["init_from"]), env)
    if options.start_at_anchor and not spec.get("init_from"):
        start_at_anchor(model, spec["algo"])
    if options.init_log_std is not None:  # exploration noise of a fine-tuned policy (after the cloned weights)
        import torch

        with torch.no_grad():
            model.policy.log_std.fill_(float(options.init_log_std))
    return model


def _hooks(spec: RunSpec, config: ScenarioConfig, interface, out_dir: Path, wall_before: float, warmup: int) -> list:
    """The run's callbacks: validation on the real objective, checkpoints, the actor warm-up."""
    from .callbacks import ActorWarmup, ControlCostValidation, RunCheckpoint

    hooks = []
    if spec["env"] != "CartPole-v1":
        hooks.append(ControlCostValidation(
            spec["env"], config, interface, episodes=int(spec["eval_episodes"]),
            every=max(int(spec["eval_every"]), 1), out_dir=out_dir, seed_base=VALIDATION_SEED_BASE))
    hooks.append(RunCheckpoint(out_dir, max(int(spec["checkpoint_every"]), 1), wall_time_before=wall_before))
    if warmup > 0:
        hooks.append(ActorWarmup(warmup))
    return hooks


def train_task(task: dict) -> dict:
    """``train(**task)``: one run of a pool or Ray task list."""
    return train(**task)


def train_seeds(seeds: list[int], out_dir: Path, workers: int = 1, progress: bool = True, backend: str = "process",
                **kwargs: Any) -> dict:
    """Train one run per seed into ``out_dir/seed-<s>`` (a process pool when ``workers > 1``, or
    Ray with ``backend="ray"``, as ``lawn sweep``) and summarize the selected models' validation
    costs across seeds (mean and 95 % interval)."""
    from .sweep import execute
    from .tables import mean_ci

    if len(set(seeds)) != len(seeds) or not seeds:
        raise ValueError(f"--seeds {seeds}: give one or more distinct seeds")
    out_dir = Path(out_dir)
    tasks = [dict(kwargs, seed=s, out_dir=out_dir / f"seed-{s}", progress=progress and workers <= 1) for s in seeds]
    summaries = sorted(execute(train_task, tasks, workers, backend), key=lambda r: seeds.index(r["seed"]))
    best = [s["best_validation_cost"] for s in summaries]
    mean, half = mean_ci(best)
    result = {"algo": kwargs.get("algo"), "env": kwargs.get("env_id"), "seeds": list(seeds), "runs": summaries,
              "best_validation_cost_mean": mean, "best_validation_cost_ci95": half,
              "wall_time_s": [s["wall_time_s"] for s in summaries]}
    (out_dir / "seeds.json").write_text(json.dumps(result, indent=2))
    return result


def _net_arch(params: Mapping[str, Any]):
    """The ``net_arch`` of a run's hyperparameters (None: SB3's default)."""
    return (params.get("policy_kwargs") or {}).get("net_arch")


def _init_from(model, source: Path, env) -> None:
    """Start from a behaviour-cloned policy of the same algorithm (its weights and obs statistics)."""
    from stable_baselines3.common.vec_env import VecNormalize

    other = load_saved(type(model).load, source / "model.zip", "--init-from model")
    model.policy.load_state_dict(other.policy.state_dict())
    norm_path = source / "vecnormalize.pkl"
    if isinstance(env, VecNormalize) and norm_path.exists():
        with open(norm_path, "rb") as fh:
            env.obs_rms = pickle.load(fh).obs_rms
