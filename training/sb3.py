"""Stable-Baselines3 runs of ``lawn train``: the seeded training envs (:func:`make_train_env`: single
envs, lawn's batched vector env or the PettingZoo env with parameter sharing), the model and the
learning loop of a new or resumed run (:func:`train_sb3`, :func:`setup`, :func:`learn`)."""

from __future__ import annotations

import json
import pickle
import shutil
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecMonitor, VecNormalize
from stable_baselines3.common.vec_env.base_vec_env import VecEnv

from agents import make_policy
from agents.learned import load_saved
from agents.residual import PARTS, AnchorResidual
from agents.runs import AgentRecord, algorithm_class, read_run
from agents.timing import DecisionClock
from evaluation.seeds import TRAIN_SEED_BASE
from lawn_env import ENV_IDS, PARALLEL_ENV_ID, ScenarioConfig, parallel_env, role_env_id
from lawn_env.interface import InterfaceLike
from training.paired import PairedReward

from .callbacks import ActorWarmup, Checkpoint, ControlCostValidation, RunCheckpoint, save_model
from .spec import Hyperparameters
from .validation import RunSummary, limit_torch_threads, versions, write_learning_curve

__all__ = ["NativeVecEnv", "make_marl_vec_env", "make_train_env", "train_sb3", "setup", "learn", "init_from",
           "start_at_anchor"]


class NativeVecEnv(VecEnv):
    """``n_envs`` scenarios of ``env_id`` in one batched simulation (same-step autoreset, SB3's
    convention), on ``interface`` (None: the id's own). With ``independent_draws`` (the default) each
    scenario draws its slots' randomness from its own generator, so scenario i's episodes are those of
    SB3's ``DummyVecEnv`` of single envs seeded ``seed + i``, step for step, and a run on either is the
    same run; without, every scenario's draws come from scenario 0's generator (a few microseconds a
    step less)."""

    def __init__(self, config: ScenarioConfig, n_envs: int, env_id: str = "lawn/Joint-v1",
                 interface: InterfaceLike = None, independent_draws: bool = True):
        kwargs: dict[str, Any] = {} if interface is None else {"interface": interface}
        self.venv = gym.make_vec(env_id, num_envs=n_envs, vectorization_mode="vector_entry_point", config=config,
                                 autoreset_mode="SameStep", **kwargs)
        super().__init__(n_envs, self.venv.single_observation_space, self.venv.single_action_space)
        self._seed: int | None = None
        self._actions: np.ndarray | None = None
        self.render_mode = None
        self.independent_draws = bool(independent_draws)

    def reset(self) -> np.ndarray:
        obs: np.ndarray
        obs, _ = self.venv.reset(seed=self._seed, options={"independent_draws": self.independent_draws})
        self._seed = None
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions  # SB3 clips Box actions before stepping; the env rejects what it cannot take

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        obs, reward, terminated, truncated, info = self.venv.step(self._actions)
        done = terminated | truncated
        infos: list[dict[str, Any]] = [{"stage_cost": float(c)} for c in info["stage_cost"]]
        for i in np.flatnonzero(done).tolist():
            infos[i]["terminal_observation"] = info["final_obs"][i]
            infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
        return obs, reward.astype(np.float32), done, infos

    def seed(self, seed: int | None = None) -> list[int | None]:
        self._seed = seed
        return [None if seed is None else seed + i for i in range(self.num_envs)]

    def close(self) -> None:
        self.venv.close()

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:  # one batched env: one answer for every index
        return [getattr(self.venv, attr_name)] * len(list(self._get_indices(indices)))

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any) -> list[Any]:
        raise NotImplementedError(f"env_method({method_name!r}): the native vector env has no per-env objects")

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False] * len(list(self._get_indices(indices)))


def make_marl_vec_env(config: ScenarioConfig, n_envs: int, seed: int, interface: InterfaceLike = None) -> Any:
    """An SB3 VecEnv with one sub-environment per agent per copy of the PettingZoo env, seeded: SuperSuit
    pads the agents' observations and actions and appends a one-hot agent indicator, or in the entity
    layout (every agent sees the fleet and which entity it is) pads the drone's action only."""
    import supersuit as ss
    from supersuit.vector.sb3_vector_wrapper import SB3VecEnvWrapper

    class _Seeded(SB3VecEnvWrapper):  # type: ignore[misc]  # supersuit ships no type information
        """SuperSuit's SB3 adapter with SB3's ``seed`` (the next reset uses it)."""

        _next_seed = None

        def seed(self, seed: int | None = None) -> list[Any]:
            self._next_seed = seed
            return [seed]

        def reset(self, seed: int | None = None, options: Any = None) -> Any:
            seed = seed if seed is not None else self._next_seed
            self._next_seed = None
            observations, self.reset_infos = self.venv.reset(seed=seed)
            return observations

    env = parallel_env(config, interface=interface)
    if env.entities is None:
        env = ss.agent_indicator_v0(ss.pad_action_space_v0(ss.pad_observations_v0(env)), type_only=False)
    else:
        env = ss.pad_action_space_v0(env)
    venv = ss.concat_vec_envs_v1(ss.pettingzoo_env_to_vec_env_v1(env), n_envs, num_cpus=0, base_class="gymnasium")
    wrapped = _Seeded(venv)
    wrapped.seed(seed)
    return wrapped


def make_train_env(env_id: str, config: ScenarioConfig, n_envs: int, seed: int, normalize: bool | Mapping[str, Any],
                   monitor_dir: Path | None, vecnormalize_path: Path | None = None, **kwargs: Any) -> Any:
    """A seeded, monitored SB3 VecEnv with optional VecNormalize (``normalize``: true or its options;
    ``vecnormalize_path``: saved statistics). Keywords: ``interface``, ``append_monitor`` (a resumed
    run's monitor logs), ``vec`` (``"native"``: :class:`NativeVecEnv`, no monitor files), ``paired``
    (:class:`training.paired.PairedReward`'s keywords: every env's reward paired with an anchor's; the
    monitor logs keep the env's own rewards), ``residual`` (the residual scheme's settings,
    :func:`agents.residual.check_residual`) and ``clock`` (the :class:`agents.timing.DecisionClock`
    both anchors decide on)."""
    from stable_baselines3.common.env_util import make_vec_env

    unknown = set(kwargs) - {"interface", "append_monitor", "vec", "paired", "residual", "clock"}
    if unknown:
        raise TypeError(f"make_train_env: unexpected keywords {sorted(unknown)}")
    interface, paired, residual = kwargs.get("interface"), kwargs.get("paired"), kwargs.get("residual")
    for name, value in (("paired reward", paired), ("residual scheme", residual)):
        if value is not None and (kwargs.get("vec", "dummy") == "native" or env_id not in ENV_IDS):
            raise ValueError(f"the {name} wraps single envs of {', '.join(ENV_IDS)}: train with --vec dummy "
                             f"(got env {env_id}, vec {kwargs.get('vec', 'dummy')})")
    if kwargs.get("vec", "dummy") == "native":
        venv: VecEnv = VecMonitor(NativeVecEnv(config, n_envs, env_id, interface=interface))
        venv.seed(seed)
    elif env_id == PARALLEL_ENV_ID:
        venv = make_marl_vec_env(config, n_envs, seed, interface=interface)
    else:
        env_kwargs = {} if env_id == "CartPole-v1" else {"config": config, "interface": interface}
        venv = make_vec_env(env_id, n_envs=n_envs, seed=seed, env_kwargs=env_kwargs,
                            monitor_dir=str(monitor_dir) if monitor_dir else None,
                            monitor_kwargs={"override_existing": not kwargs.get("append_monitor", False)},
                            wrapper_class=_lawn_wrappers if paired or residual else None,  # type: ignore[arg-type]
                            wrapper_kwargs={"paired": paired, "residual": residual,
                                            "clock": kwargs.get("clock") or DecisionClock()})
    if vecnormalize_path is not None:
        return VecNormalize.load(str(vecnormalize_path), venv)
    if normalize:
        return VecNormalize(venv, **(dict(normalize) if isinstance(normalize, Mapping) else {}))
    return venv


def _lawn_wrappers(env: Any, paired: Mapping[str, Any] | None, residual: Mapping[str, Any] | None,
                   clock: DecisionClock) -> Any:
    """A monitored env with the residual scheme (:class:`agents.residual.AnchorResidual`) and then
    the paired reward (:class:`training.paired.PairedReward`), each when given its keywords; both
    anchors decide on ``clock`` (the run's expert time)."""
    base = env.unwrapped
    env_id = role_env_id(base.role)
    if residual is not None:
        anchor = clock.timed(make_policy(residual["anchor"], base.config, env_id=env_id))
        env = AnchorResidual(env, anchor, residual["scale"], residual.get("moves", PARTS))
    if paired is None:
        return env
    shadow = clock.timed(make_policy(paired["anchor"], base.config, env_id=env_id))
    return PairedReward(env, shadow, **{k: v for k, v in paired.items() if k != "anchor"})


def train_sb3(spec: Any, params: Hyperparameters, options: Any, version: int,
              callbacks: list[Any] | None = None) -> RunSummary:
    """Train the SB3 run of ``spec`` (a :class:`training.spec.TrainSpec`) with its hyperparameters and
    their :class:`~training.spec.RunOptions`; a model SB3 refuses to build leaves nothing behind."""
    if spec.init_from is not None:
        _check_init_from(spec.init_from, spec.algo, params)
    record = AgentRecord.model_validate({
        "algo": spec.algo, "env": spec.env_id, "seed": spec.seed, "timesteps": spec.timesteps,
        "hyperparams_version": version, "interface": params.get("interface"), "eval_every": spec.eval_every,
        "eval_episodes": spec.eval_episodes, "checkpoint_every": spec.checkpoint_every,
        "init_from": str(spec.init_from) if spec.init_from else None, "vec": spec.vec,
        **({"residual": options.residual} if options.residual else {}),
        **({"selection": options.selection} if options.selection != "relative" else {}), "versions": versions()})
    out_dir = spec.out_dir
    existed = out_dir.exists()
    out_dir.mkdir(parents=True, exist_ok=True)
    for name, data in (("config.json", spec.config.to_dict()), ("hyperparams.json", params),
                       ("run.json", record.as_json())):
        (out_dir / name).write_text(json.dumps(data, indent=2))  # before SB3 adds its defaults to policy_kwargs
    spec.write()
    try:
        run = setup(record, options, spec.config, out_dir, None, callbacks)
    except BaseException:
        written = ("config.json", "hyperparams.json", "run.json", "spec.json", "monitor", "tb")
        for path in [out_dir] if not existed else [out_dir / name for name in written]:
            if path.is_dir():
                shutil.rmtree(path, ignore_errors=True)
            else:
                path.unlink(missing_ok=True)
        raise
    return learn(run, progress=spec.progress)


def _net_arch(params: Mapping[str, Any]) -> Any:  # None: SB3's default
    return (params.get("policy_kwargs") or {}).get("net_arch")


def _check_init_from(init_from: Path, algo: str, params: Mapping[str, Any]) -> None:
    """``--init-from``: a finished run of the same algorithm, interface and network as this run's."""
    source = read_run(init_from, "--init-from")
    theirs = source.record.target or source.record.algo
    if theirs != algo:
        raise ValueError(f"--init-from {init_from}: it holds a {theirs} policy, not {algo}")
    if not (init_from / "model.zip").exists():
        raise ValueError(f"--init-from {init_from}: no model.zip there (the run did not finish)")
    if source.interface != params.get("interface"):
        raise ValueError(f"--init-from {init_from}: it was trained with interface {source.interface}, "
                         f"this run uses {params.get('interface')}; pass the same --interface")
    hp_file = init_from / "hyperparams.json"
    arch = _net_arch(json.loads(hp_file.read_text())) if hp_file.exists() else None
    if arch is not None and arch != _net_arch(params):
        raise ValueError(f"--init-from {init_from}: its network is net_arch={arch}, this run builds "
                         f"net_arch={_net_arch(params)}; pass --hp 'policy_kwargs={{\"net_arch\": {arch}}}'")


@dataclass
class Run:
    """A run ready to learn: its record (``run.json``), model, env and callbacks."""

    record: AgentRecord
    model: Any
    env: Any
    hooks: list[Any]
    out_dir: Path
    wall_before: float
    resumed: bool
    clock: DecisionClock  # the anchors' decisions: the residual's, the paired reward's shadow, validation's


def setup(record: AgentRecord, options: Any, config: ScenarioConfig, out_dir: Path, start: Checkpoint | None,
          callbacks: list[Any] | None = None) -> Run:
    """The env, the model and the callbacks of a run (new, or resumed from ``start``)."""
    from stable_baselines3.common.utils import set_random_seed

    limit_torch_threads(options.torch_threads)
    done_steps = start.steps if start else 0
    seed = int(record.require("seed"))
    env_seed = TRAIN_SEED_BASE + 1000 * seed + done_steps  # a resumed run: fresh, seeded episodes
    clock = DecisionClock()
    set_random_seed(env_seed)
    env = make_train_env(record.env, config, options.n_envs, env_seed, options.normalize, out_dir / "monitor",
                         vecnormalize_path=start.file("vecnormalize.pkl") if start else None,
                         interface=options.interface, append_monitor=start is not None, vec=record.vec or "dummy",
                         paired=None if options.paired_anchor is None else
                         {"anchor": options.paired_anchor, "gamma": float(options.algo_kwargs.get("gamma", 0.99))},
                         residual=options.residual, clock=clock)
    try:
        model = _model(record, env, start, out_dir, options)
    except BaseException:
        env.close()
        raise
    wall_before = 0.0 if record.wall_time_s is None else record.run_seconds
    hooks: list[BaseCallback] = []
    if record.env != "CartPole-v1":
        hooks.append(ControlCostValidation(record.env, config, options.interface, int(record.require("eval_episodes")),
                                           max(int(record.require("eval_every")), 1), out_dir, options.residual, clock))
    hooks.append(RunCheckpoint(out_dir, max(int(record.require("checkpoint_every")), 1), wall_time_before=wall_before,
                               clock=clock, expert_before=record.expert_decision_s or 0.0))
    if options.actor_warmup_steps > 0:
        hooks.append(ActorWarmup(options.actor_warmup_steps))
    return Run(record, model, env, hooks + list(callbacks or []), out_dir, wall_before, start is not None, clock)


def learn(run: Run, progress: bool) -> RunSummary:
    """Train a set-up run to its timestep target; save the model, its statistics and the curve."""
    model, env, out_dir = run.model, run.env, run.out_dir
    remaining = int(run.record.require("timesteps")) - model.num_timesteps
    began = time.perf_counter()
    if remaining > 0:
        model.learn(total_timesteps=remaining, callback=run.hooks, reset_num_timesteps=not run.resumed,
                    progress_bar=progress, tb_log_name="run")
    elapsed = time.perf_counter() - began
    save_model(model, out_dir)
    expert_s = (run.record.expert_decision_s or 0.0) + run.clock.seconds  # a resumed run: both parts
    record = run.record.model_copy(update={
        "num_timesteps": int(model.num_timesteps), "updates": int(getattr(model, "_n_updates", 0)),
        "wall_time_s": float(elapsed + run.wall_before), "expert_decision_s": expert_s})
    (out_dir / "run.json").write_text(json.dumps(record.as_json(), indent=2))
    summary = write_learning_curve(out_dir, record.as_json())
    env.close()
    return summary


def _model(record: AgentRecord, env: Any, start: Checkpoint | None, out_dir: Path, options: Any) -> Any:
    """The model a run trains: its checkpoint's, or a new one (from a cloned run's weights, at the
    anchor, with the fine-tuning's exploration noise as the options ask)."""
    cls = algorithm_class(record.algo)
    if start:
        model = load_saved(lambda p: cls.load(p, env=env, tensorboard_log=str(out_dir / "tb")),
                           start.path / "model.zip", "checkpoint model")
        buffer = start.file("replay_buffer.pkl")
        if buffer is not None:
            model.load_replay_buffer(str(buffer))
        return model
    seed = int(record.require("seed")) if record.env != PARALLEL_ENV_ID else None
    model = cls(options.policy, env, seed=seed, verbose=0,
                tensorboard_log=str(out_dir / "tb"), **options.algo_kwargs)
    if record.init_from:
        init_from(model, Path(record.init_from), env)
    elif options.start_at_anchor:
        start_at_anchor(model, record.algo)
    if options.init_log_std is not None:  # exploration noise of a fine-tuned policy (after the cloned weights)
        import torch

        log_std: Any = model.policy.log_std
        torch.nn.init.constant_(log_std, float(options.init_log_std))
    return model


def init_from(model: Any, source: Path, env: Any) -> None:
    """Start from a behaviour-cloned policy of the same algorithm (its weights and obs statistics)."""
    other = load_saved(type(model).load, source / "model.zip", "--init-from model")
    model.policy.load_state_dict(other.policy.state_dict())
    norm_path = source / "vecnormalize.pkl"
    if isinstance(env, VecNormalize) and norm_path.exists():
        with open(norm_path, "rb") as fh:
            env.obs_rms = pickle.load(fh).obs_rms


def start_at_anchor(model: Any, algo: str) -> None:
    """``start_at_anchor``: the output layer starts at zero, so the deterministic action is the zero
    action, the interface's anchor, and model selection compares training against the anchor itself
    (SAC's untrained mean acts far from zero; PPO's init near zero but not at it)."""
    import torch

    def heads() -> list[Any]:  # a fleet network's means are its two heads' outputs (its action_net is the identity)
        net = model.policy.mlp_extractor
        return [net.agv_head, net.drone_head] if hasattr(net, "agv_head") else [model.policy.action_net]

    layers = {"sac": lambda: [model.actor.mu], "ppo": heads}
    if algo not in layers:
        raise ValueError(f"start_at_anchor: supported for {', '.join(layers)}, not {algo!r}")
    with torch.no_grad():
        for layer in layers[algo]():
            layer.weight.zero_()
            layer.bias.zero_()
