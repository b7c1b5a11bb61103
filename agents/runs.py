"""Run directories on disk (``lawn train`` output, shipped agents) and the algorithms they hold:
the one reader of ``run.json`` (:func:`read_run`), the one map of Stable-Baselines3 algorithms
(:data:`ALGORITHMS`), and JSON reading with errors that name the file and what is wrong with it.
Nothing here imports SB3 or torch until a class is asked for."""

from __future__ import annotations

import importlib
import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pydantic import BaseModel, ConfigDict, ValidationError

from lawn_env import LEGACY_ENV_IDS, PARALLEL_ENV_ID, ScenarioConfig

from .errors import MissingExtra

if TYPE_CHECKING:
    from stable_baselines3.common.base_class import BaseAlgorithm
    from stable_baselines3.common.policies import BasePolicy

__all__ = ["ALGORITHMS", "RL_EXTRA", "AgentRecord", "Benchmark", "RunDir", "algorithm_class", "policy_network_class",
           "read_json", "read_run", "read_record"]

#: The SB3 algorithms of runs and shipped agents: name -> (algorithm class, the class of the policy
#: network a shipped agent keeps: the whole actor-critic policy, or the actor alone for SAC/TD3).
ALGORITHMS: dict[str, tuple[str, str]] = {
    "ppo": ("stable_baselines3:PPO", "stable_baselines3.common.policies:ActorCriticPolicy"),
    "a2c": ("stable_baselines3:A2C", "stable_baselines3.common.policies:ActorCriticPolicy"),
    "sac": ("stable_baselines3:SAC", "stable_baselines3.sac.policies:Actor"),
    "td3": ("stable_baselines3:TD3", "stable_baselines3.td3.policies:Actor"),
    "fleet": ("stable_baselines3:PPO", "agents.fleet:FleetPolicy"),  # lawn train --algo fleet: a PPO model
}
#: How to install what training and trained agents need.
RL_EXTRA = "bash scripts/setup.sh full, or pip install torch==2.13.0 && pip install -e '.[rl]'"


def _import(spec: str) -> Any:  # the class named by spec, known at run time
    module, name = spec.split(":")
    try:
        return getattr(importlib.import_module(module), name)
    except ImportError:  # exercised only without the extra
        raise MissingExtra(f"trained agents and training need the rl extra: {RL_EXTRA}") from None


def _check_algorithm(algo: str, where: str) -> None:
    if algo not in ALGORITHMS:
        raise ValueError(f"{where}unknown algorithm {algo!r}; valid: {', '.join(ALGORITHMS)}")


def algorithm_class(algo: str, where: str = "") -> type[BaseAlgorithm]:
    """The SB3 algorithm class of ``algo`` (``ppo``, ``a2c``, ``sac``, ``td3``); ``where`` prefixes the
    error (the file or option the name came from)."""
    _check_algorithm(algo, where)
    cls: type[BaseAlgorithm] = _import(ALGORITHMS[algo][0])
    return cls


def policy_network_class(algo: str, where: str = "") -> type[BasePolicy]:
    """The class of the network a shipped agent of ``algo`` keeps (:data:`ALGORITHMS`)."""
    _check_algorithm(algo, where)
    cls: type[BasePolicy] = _import(ALGORITHMS[algo][1])
    return cls


def read_json(path: Path, context: str = "", missing: str = "") -> Any:
    """The parsed JSON file at ``path``; a ``ValueError`` naming the file if it is absent
    (with the hint ``missing``) or is not valid JSON (with the line and column)."""
    path = Path(path)
    prefix = f"{context} {path.parent}: " if context else ""
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise ValueError(f"{prefix}no {path.name} in {path.parent}" + (f" ({missing})" if missing else "")) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{prefix}cannot read {path}: {exc}") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{prefix}{path} is not valid JSON (line {exc.lineno}, column {exc.colno}: "
                         f"{exc.msg})") from None


class Benchmark(BaseModel):
    """A shipped agent's figures, recorded when the zoo was built: its test seeds, the reference and
    its anchor, its score (version, value and interval) and its paired differences (mean, half-width)
    against the reference and the anchor, or, for an agent of the steady tasks, the geometric change
    per task, reference and test range."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    test_seeds: str | None = None
    reference: str | None = None
    anchor: str | None = None
    score_version: int | None = None
    score: list[float] | None = None
    shipped_vs_reference: list[float] | None = None
    shipped_vs_anchor: list[float] | None = None
    across_training_seeds_vs_anchor: list[float] | None = None
    tasks: dict[str, dict[str, list[float]]] | None = None


class AgentRecord(BaseModel):
    """What a trained agent's files say of it: ``run.json`` of a ``lawn train`` run, ``agent.json`` of
    a shipped one (the run's fields with the zoo's). ``algo`` and ``env`` are always there; the
    interface and the residual scheme are the records :func:`lawn_env.interface.resolve_interface`
    and :func:`agents.residual.check_residual` read; a field a later version adds is kept
    (``model_extra``), not refused."""

    model_config = ConfigDict(frozen=True, extra="allow")

    algo: str
    env: str
    trainer: str | None = None
    target: str | None = None
    interface: Mapping[str, Any] | str | None = None
    residual: Mapping[str, Any] | None = None
    config: Mapping[str, Any] | None = None
    seed: int | None = None
    timesteps: int | None = None
    num_timesteps: int | None = None
    eval_every: int | None = None
    eval_episodes: int | None = None
    checkpoint_every: int | None = None
    vec: str | None = None
    init_from: str | None = None
    wall_time_s: float | list[float] | None = None
    expert_decision_s: float | None = None
    versions: Mapping[str, Any] | None = None
    selection: str | None = None  # the model-selection rule (training.validation.SELECTIONS; None: relative)
    # the zoo's fields (agent.json)
    name: str | None = None
    label: str | None = None
    trained_on: str | None = None
    evaluated_on: str | None = None
    command: str | None = None
    budget_steps: int | None = None
    training_seeds: list[int] | None = None
    shipped_seed: int | None = None
    selected_on: str | None = None
    selected_at_steps: int | None = None
    benchmark: Benchmark | None = None

    @property
    def layout(self) -> str | None:
        """The observation layout of its interface (``entities``, ``flat``; None: the v0 interface)."""
        return self.interface.get("layout") if isinstance(self.interface, Mapping) else None

    def require(self, name: str) -> Any:
        """The value of field ``name``; a ``ValueError`` naming it when the record does not hold it (not
        written by lawn train, or by an older one)."""
        value = getattr(self, name, None) if name in type(self).model_fields else (self.model_extra or {}).get(name)
        if value is None:
            raise ValueError(f"the run's record has no {name!r} (run.json or agent.json not written by lawn train)")
        return value

    @property
    def run_seconds(self) -> float:
        """A run's wall time (``run.json``'s ``wall_time_s``); a ``ValueError`` where it is not one number
        (not recorded, or a shipped agent's one per training seed)."""
        seconds = self.require("wall_time_s")
        if not isinstance(seconds, (int, float)):
            raise ValueError(f"the run's record has wall_time_s={seconds!r}, not one run's wall time")
        return float(seconds)

    @property
    def steps_per_s(self) -> float | None:
        """Environment steps per second of wall time: a run's steps over its wall time, a shipped agent's
        budget over its training runs' mean wall time; None where either is not recorded."""
        steps = self.num_timesteps if self.num_timesteps is not None else self.budget_steps
        seconds = self.wall_time_s if isinstance(self.wall_time_s, list) else [self.wall_time_s]
        known = [float(x) for x in seconds if x]
        return steps / (sum(known) / len(known)) if steps and known else None

    def steps(self, default: int) -> int:
        """The steps the run trained (``num_timesteps``), ``default`` where it does not record them."""
        return default if self.num_timesteps is None else self.num_timesteps

    @property
    def scenario(self) -> Mapping[str, Any]:
        """The scenario config a shipped agent records (``agent.json``'s ``config``)."""
        config: Mapping[str, Any] = self.require("config")
        return config

    def as_json(self) -> dict[str, Any]:
        """The record as its file holds it (the fields it was read or built with)."""
        return self.model_dump(mode="json", exclude_unset=True)


def read_record(path: Path, context: str = "", missing: str = "") -> AgentRecord:
    """The :class:`AgentRecord` of ``run.json`` or ``agent.json`` at ``path``; a ``ValueError`` naming
    the file and the field when it is not one (no ``env`` and ``algo``: not written by lawn train)."""
    data = read_json(path, context, missing)
    prefix = f"{context} {path.parent}: " if context else f"{path.parent}: "
    if not isinstance(data, dict) or not {"env", "algo"} <= set(data):
        raise ValueError(f"{prefix}{path.name} has no 'env' and 'algo' (not written by lawn train)")
    try:
        return AgentRecord.model_validate(data)
    except ValidationError as exc:
        first = exc.errors()[0]
        raise ValueError(f"{prefix}{path.name}: {'.'.join(map(str, first['loc']))}: {first['msg']} "
                         f"(got {first.get('input')!r})") from None


@dataclass(frozen=True)
class RunDir:
    """A ``lawn train`` run directory and its ``run.json`` record."""

    path: Path
    record: AgentRecord

    @property
    def env(self) -> str:
        """The env the run trained on, by its current id: a run recorded under a v0 id
        (``lawn_env.LEGACY_ENV_IDS``) plays that id's current version, the same scenario."""
        env = self.record.env
        return LEGACY_ENV_IDS[env][0] if env in LEGACY_ENV_IDS else env

    @property
    def algo(self) -> str:
        """The algorithm of the model it holds (behaviour cloning: the target algorithm's; a fleet
        run: ``fleet``, a PPO model whose policy is :class:`agents.fleet.FleetPolicy`)."""
        if self.record.trainer == "fleet":
            return "fleet"
        return self.record.target or self.record.algo

    @property
    def kind(self) -> str:
        """The prefix of its policy name: ``marl`` (the parallel env), ``bc`` (behaviour cloning)
        or ``sb3``."""
        if self.record.env == PARALLEL_ENV_ID:
            return "marl"
        return "bc" if self.record.trainer == "bc" else "sb3"

    @property
    def interface(self) -> Any:
        """The RL interface the agent trained with (None: the v0 interface)."""
        return self.record.interface

    def load_config(self, context: str = "", missing: str = "") -> ScenarioConfig:
        """The exact scenario config of the run (``config.json``)."""
        return ScenarioConfig.from_dict(read_json(self.path / "config.json", context, missing))

    @property
    def policy_name(self) -> str:
        """The name ``make_policy`` and ``lawn evaluate --policy`` take for it."""
        return f"{self.kind}:{self.path}"


def read_run(path: Path | str, context: str = "", require_model: bool = False) -> RunDir:
    """The run directory at ``path``: a ``ValueError`` (prefixed by ``context``) when it has no
    valid ``run.json`` with an ``env`` and an ``algo``, or, with ``require_model``, no ``model.zip``."""
    path = Path(path)
    record = read_record(path / "run.json", context, "not a lawn train run directory")
    prefix = f"{context} {path}: " if context else f"{path}: "
    if require_model and not (path / "model.zip").exists():
        raise ValueError(f"{prefix}no model.zip: the run has not finished (lawn train --resume {path} continues it)")
    return RunDir(path, record)
