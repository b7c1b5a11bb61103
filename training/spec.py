"""What ``lawn train`` runs, checked before anything runs: the typed run spec (:class:`TrainSpec`),
the algorithm registry (:data:`ALGORITHMS`), the versioned hyperparameter files
(:func:`load_hyperparams`) and ``lawn train``'s own options among them (:class:`RunOptions`,
:func:`split_params`). :mod:`training.train` runs specs; this module imports without the ``rl`` extra
and without the rest of ``training``.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any, Literal, NamedTuple

import gymnasium as gym
from pydantic import ConfigDict, Field, StrictBool, TypeAdapter
from pydantic.dataclasses import dataclass

from agents.learned import LOADERS, learned_name_forms
from agents.policies import POLICIES
from agents.residual import check_residual
from lawn_env import ENV_IDS, PARALLEL_ENV_ID, RL_ENV_IDS, ScenarioConfig
from lawn_env.errors import raises_config_errors
from lawn_env.interface import resolve_interface

__all__ = ["ALGORITHMS", "ALGOS", "Algorithm", "TRAIN_ENV_IDS", "NATIVE_ENV_IDS", "LAWN_KEYS", "RunOptions",
           "Hyperparams", "Hyperparameters",
           "TrainSpec", "load_hyperparams", "split_params", "HYPERPARAMS_DIR"]

HYPERPARAMS_DIR = Path(__file__).parent / "hyperparams"
_LAWN, _CARTPOLE = ("lawn/Joint-v1", "lawn/Comm-v1"), "CartPole-v1"
#: Environment ids ``lawn train`` accepts; ``lawn/Parallel-v0`` is the PettingZoo env (parameter sharing).
TRAIN_ENV_IDS = (*ENV_IDS, PARALLEL_ENV_ID, _CARTPOLE)
#: The ids registered with a native vector env (``--vec native``: :class:`training.sb3.NativeVecEnv`).
NATIVE_ENV_IDS = tuple(i for i in (*ENV_IDS, *RL_ENV_IDS) if gym.spec(i).vector_entry_point is not None)

#: Hyperparameter keys that ``lawn train`` reads itself (the rest go to the SB3 algorithm), with the
#: algorithms each applies to (None: all).
LAWN_KEYS: dict[str, tuple[str, ...] | None] = {
    "n_envs": None, "normalize": None, "policy": None, "interface": None, "torch_threads": None, "selection": None,
    "actor_warmup_steps": ("ppo", "a2c"), "init_log_std": ("ppo", "a2c"), "start_at_anchor": ("ppo", "sac"),
    "paired_anchor": ("ppo", "sac", "a2c", "td3"), "residual": ("ppo", "sac", "a2c", "td3"),
}
#: Constructor arguments ``lawn train`` sets itself: not hyperparameters.
_SET_BY_LAWN = {"self", "env", "policy", "seed", "verbose", "tensorboard_log"}


#: Hyperparameters as a file and ``--hp`` give them: the algorithm's keyword arguments (SB3's, or an
#: imitation trainer's settings), free-form by design (each algorithm takes its own, and checks them),
#: with lawn train's own options (:data:`LAWN_KEYS`, checked by :class:`RunOptions`).
Hyperparameters = dict[str, Any]


# ---------------------------------------------------------------- the options of an SB3 run
@raises_config_errors(prefix="--hp ", noun="lawn train option")
@dataclass(config=ConfigDict(extra="forbid", arbitrary_types_allowed=True))
class RunOptions:
    """``lawn train``'s own options of an SB3 run (:data:`LAWN_KEYS`), checked, and the SB3 keyword
    arguments (:func:`split_params`)."""

    n_envs: Annotated[int, Field(ge=1, strict=True)] = 1
    normalize: StrictBool | dict[str, Any] = False
    policy: Any = "MlpPolicy"
    interface: Any = None
    actor_warmup_steps: Annotated[int, Field(ge=0, strict=True)] = 0
    init_log_std: Annotated[float, Field(ge=-20, strict=True)] | None = None
    start_at_anchor: bool = False
    paired_anchor: str | None = None
    """Train on the paired reward against this policy (:class:`training.paired.PairedReward`)."""
    residual: Mapping[str, Any] | None = None
    """Act by the residual scheme around a policy, ``{"anchor": NAME, "scale": s, "moves": [...]}``
    (:mod:`agents.residual`)."""
    torch_threads: Annotated[int, Field(ge=1, le=256, strict=True)] = 1
    """Threads of torch's CPU kernels: 1 (the default) for runs side by side, the cores of the machine for
    one run alone (a large batch's update is most of an RL-scale run's time)."""
    selection: Literal["relative", "geometric"] = "relative"
    """Model selection's measure against the run's start and the reference (:data:`training.validation.SELECTIONS`):
    the paired relative difference, or the geometric mean of the per-seed cost ratios (where the start's
    costs are heavy-tailed, a relative mean follows its cheap seeds)."""
    algo_kwargs: Hyperparameters = Field(default_factory=dict)


def lr_schedule(value: Any, key: str = "learning_rate") -> Any:
    """``lin_3e-4`` (rl-zoo's notation): linear decay from 3e-4 to 0 over the run; numbers as they are."""
    if isinstance(value, str) and value.startswith("lin_"):
        try:
            start = float(value[4:])
        except ValueError:
            raise ValueError(f"--hp {key}={value!r}: lin_<number> expected, e.g. lin_3e-4") from None
        return lambda progress_remaining: progress_remaining * start
    return value


def _check_anchor(key: str, anchor: str | None, env_id: str) -> None:
    """A paired-reward or residual anchor: a registered policy of a central lawn env (the wrappers'
    errors, early)."""
    if anchor is None:
        return
    if env_id not in _LAWN:
        what = "paired reward" if key == "paired_anchor" else "residual scheme"
        raise ValueError(f"--hp {key}={anchor!r}: the {what} wraps {', '.join(_LAWN)}, not {env_id}")

    prefix = anchor.split(":", 1)[0] if ":" in anchor else None
    if (anchor not in POLICIES) if prefix is None else (prefix not in LOADERS):
        raise ValueError(f"--hp {key}={anchor!r}: unknown policy; valid: {', '.join(POLICIES)}, or "
                         f"{learned_name_forms()}")


def _check_residual(options: RunOptions, env_id: str) -> None:
    """The residual scheme: its settings, its anchor, an anchored flat interface and single envs."""
    if options.residual is None:
        return

    try:
        options.residual = check_residual(options.residual)
    except ValueError as exc:
        raise ValueError(f"--hp {exc}") from None
    _check_anchor("residual anchor", options.residual["anchor"], env_id)
    iface = resolve_interface(options.interface)
    if iface.action_scheme != "anchored" or iface.layout != "flat":
        raise ValueError(f"--hp residual: moves an anchored interface's flat actions; --hp interface gives "
                         f"action_scheme={iface.action_scheme!r}, layout={iface.layout!r} (e.g. --hp interface=rl)")


def _check_normalize(normalize: bool | dict[str, Any]) -> None:
    if isinstance(normalize, dict):
        from stable_baselines3.common.vec_env import VecNormalize

        allowed = sorted(k for k in inspect.signature(VecNormalize.__init__).parameters if k not in ("self", "venv"))
        unknown = sorted(set(normalize) - set(allowed))
        if unknown:
            raise ValueError(f"--hp normalize: unknown VecNormalize options {unknown}; valid: {', '.join(allowed)}")


def _policy(algo: str, env_id: str, options: RunOptions, cls: Any) -> Any:
    """The policy class or alias of ``options`` (``FleetPolicy``: lawn's attention policy, agents/fleet.py)."""
    policy = options.policy
    fleet = policy == "FleetPolicy"
    if fleet and algo not in ("ppo", "a2c"):
        raise ValueError(f"--hp policy=FleetPolicy is an actor-critic policy: ppo or a2c, not {algo}")
    if not fleet and isinstance(policy, str) and policy not in getattr(cls, "policy_aliases", {}):
        allowed = ", ".join([*cls.policy_aliases, "FleetPolicy"])
        raise ValueError(f"--hp policy={policy!r}: {cls.__name__} takes {allowed}")
    if env_id == PARALLEL_ENV_ID and not fleet and options.interface is not None \
            and resolve_interface(options.interface).layout == "entities":
        raise ValueError(f"--hp policy={policy!r}: the multi-agent env's entity layout trains --hp policy=FleetPolicy "
                         "(each agent acts with its own row of the fleet network)")
    if fleet:
        from agents.fleet import FleetPolicy

        return FleetPolicy
    return policy


def split_params(algo: str, env_id: str, params: Mapping[str, Any]) -> RunOptions:
    """``lawn train``'s options and the SB3 keyword arguments of ``params``, every one checked (an
    error names the key, the value and what is allowed)."""
    cls = ALGORITHMS[algo].load()
    params = dict(params)
    for key, algos in LAWN_KEYS.items():
        if key in params and algos is not None and algo not in algos:
            raise ValueError(f"--hp {key}: applies to {', '.join(algos)}, not {algo}")
    options = RunOptions(**{k: params.pop(k) for k in list(params) if k in LAWN_KEYS})
    _check_normalize(options.normalize)
    _check_anchor("paired_anchor", options.paired_anchor, env_id)
    _check_residual(options, env_id)
    options.policy = _policy(algo, env_id, options, cls)
    for key in ("learning_rate", "clip_range"):
        if key in params:
            params[key] = lr_schedule(params[key], key)
    valid = sorted(p for p in inspect.signature(cls.__init__).parameters
                   if not p.startswith("_") and p not in _SET_BY_LAWN)
    unknown = sorted(set(params) - set(valid))
    if unknown:
        mine = [k for k, algos in LAWN_KEYS.items() if algos is None or algo in algos]
        raise ValueError(f"unknown {cls.__name__} hyperparameters {unknown}; valid: {', '.join(sorted(valid + mine))}")
    options.algo_kwargs = params
    return options


class Hyperparams(NamedTuple):
    """A run's hyperparameters and the version of the file they come from."""

    params: Hyperparameters
    version: int


def load_hyperparams(algo: str, env_id: str, overrides: Mapping[str, Any] | None = None) -> Hyperparams:
    """Hyperparameters of ``algo`` for ``env_id`` from its versioned file, with overrides; and the version."""
    if algo not in ALGORITHMS:
        raise ValueError(f"unknown algorithm {algo!r}; valid: {', '.join(ALGORITHMS)}")
    if env_id not in TRAIN_ENV_IDS:
        raise ValueError(f"unknown env id {env_id!r}; valid: {', '.join(TRAIN_ENV_IDS)}")
    import yaml

    name = ALGORITHMS[algo].hyperparams
    data = yaml.safe_load((HYPERPARAMS_DIR / name).read_text())
    if env_id not in data:
        have = [k for k in data if k != "version"]
        raise ValueError(f"no {algo} hyperparameters for {env_id!r} in {name}; it has: {', '.join(have)}")
    params = dict(data[env_id])
    params.update(overrides or {})
    return Hyperparams(params, int(data["version"]))


# ---------------------------------------------------------------- the spec
_SPEC = ConfigDict(extra="forbid", arbitrary_types_allowed=True)
Count = Annotated[int, Field(ge=1)]


@raises_config_errors(noun="TrainSpec field")
@dataclass(frozen=True, config=_SPEC)
class TrainSpec:
    """One ``lawn train`` run, checked on construction: the algorithm and env (:data:`ALGORITHMS`),
    the counts and every hyperparameter with ``hp_overrides`` (a :class:`~lawn_env.ConfigError` names a bad one)."""

    algo: str
    env_id: str
    timesteps: Count
    out_dir: Path
    seed: Annotated[int, Field(ge=0)] = 0
    config: ScenarioConfig = Field(default_factory=ScenarioConfig)
    hp_overrides: Hyperparameters = Field(default_factory=dict)
    n_envs: Count | None = None
    interface: str | dict[str, Any] | None = None
    vec: Literal["dummy", "native"] = "dummy"
    eval_every: Count = 5000
    eval_episodes: Count = 5
    checkpoint_every: Count = 10000
    init_from: Path | None = None
    dataset: str | None = None
    progress: bool = True

    def __post_init__(self) -> None:
        if self.algo not in ALGORITHMS:
            raise ValueError(f"algo={self.algo!r}: unknown algorithm; valid: {', '.join(ALGORITHMS)}")
        envs = ALGORITHMS[self.algo].envs
        if self.env_id not in envs:
            raise ValueError(f"env_id={self.env_id!r}: {self.algo} trains on {', '.join(envs)}")
        if self.dataset is not None and self.algo != "bc":
            raise ValueError(f"--dataset {self.dataset!r}: only behaviour cloning (--algo bc) trains from a dataset")
        if self.vec == "native" and self.env_id not in NATIVE_ENV_IDS:
            raise ValueError(f"--vec native runs {', '.join(NATIVE_ENV_IDS)} (got {self.env_id}); pass --vec dummy")
        ALGORITHMS[self.algo].check(self, self.hyperparams()[0])

    def hyperparams(self) -> Hyperparams:
        """The run's hyperparameters (the interface resolved to a dict) and the file's version."""
        params, version = load_hyperparams(self.algo, self.env_id, self.hp_overrides)
        if self.n_envs is not None:
            params["n_envs"] = self.n_envs
        if self.interface is not None:
            params["interface"] = self.interface
        if self.env_id != "CartPole-v1":
            params["interface"] = resolve_interface(params.get("interface", "v0")).to_dict()
        return Hyperparams(params, version)

    def write(self) -> None:
        """``spec.json`` in the run directory (``TrainSpec(**json.load(...))`` is the spec again)."""
        fields = TypeAdapter(TrainSpec).dump_python(self, mode="json")
        (self.out_dir / "spec.json").write_text(json.dumps(fields, indent=2))


# ---------------------------------------------------------------- the registry
@dataclasses.dataclass(frozen=True)
class Algorithm:
    """One algorithm of ``lawn train``: what learns (``module:name`` of the SB3 class, or of the trainer
    that takes the spec, its hyperparameters and their version), the env ids it trains on (SAC and TD3
    act in continuous spaces: not CartPole's), its hyperparameter file and, for a trainer, the
    ``module:name`` of the function that resolves its hyperparameters (an error names a bad one)."""

    learner: str
    envs: tuple[str, ...]
    hyperparams: str
    settings: str | None = None  # None: an SB3 algorithm (split_params)

    def load(self, which: str | None = None) -> Any:
        """The SB3 class or the trainer (``which``: another ``module:name``), imported."""
        module, name = (which or self.learner).split(":")
        return getattr(importlib.import_module(module), name)

    def check(self, spec: TrainSpec, params: Hyperparameters) -> None:
        if self.settings is None:
            split_params(spec.algo, spec.env_id, params)
        else:
            self.load(self.settings)(params)


#: The algorithms ``lawn train`` runs, by ``--algo`` name: SB3's, ``fleet`` (DAgger of one network for
#: any fleet size, saved as a PPO model: :mod:`training.fleet`) and ``bc`` (behaviour cloning:
#: :mod:`training.bc`).
ALGORITHMS: dict[str, Algorithm] = {
    "ppo": Algorithm("stable_baselines3:PPO", (*_LAWN, PARALLEL_ENV_ID, _CARTPOLE), "ppo.yml"),
    "a2c": Algorithm("stable_baselines3:A2C", (*_LAWN, PARALLEL_ENV_ID), "a2c.yml"),
    "sac": Algorithm("stable_baselines3:SAC", _LAWN, "sac.yml"),
    "td3": Algorithm("stable_baselines3:TD3", _LAWN, "td3.yml"),
    "fleet": Algorithm("training.fleet:train_fleet", _LAWN, "fleet.yml", "training.fleet:fleet_settings"),
    "bc": Algorithm("training.bc:train_bc", _LAWN, "bc.yml", "training.bc:bc_settings"),
}
#: The ``--algo`` names.
ALGOS = tuple(ALGORITHMS)
