"""Learned policies behind the common policy protocol, always acting on the benchmark environments.

``make_policy("sb3:DIR", config)`` loads a ``lawn train`` run directory (``bc:DIR`` the same for
behaviour-cloned runs, ``marl:DIR`` a parameter-shared multi-agent run) and ``zoo:NAME`` a
shipped agent (``agents/zoo/NAME``: policy weights, observation statistics and ``agent.json``).
Whatever interface an agent was trained with (:mod:`lawn_env.interface`: anchored actions,
clipped features), the wrapper reproduces it around the network and hands the benchmark environment
the equivalent v0 action, so every comparison runs the unmodified scenario. torch and SB3 are
imported only here, when such a policy is built.
"""

from __future__ import annotations

import json
import pickle
import zipfile
from collections.abc import Callable, Mapping
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from lawn_env import PARALLEL_ENV_ID, ScenarioConfig, env_role
from lawn_env.entities import MAX_AGVS, EntityLayout
from lawn_env.interface import InterfaceLike, resolve_interface

from .anchors import InterfacePolicy, load_anchor
from .base import COMM, JOINT, Policy
from .errors import MissingExtra
from .runs import RL_EXTRA, AgentRecord, RunDir, algorithm_class, policy_network_class, read_json, read_record, read_run

__all__ = ["ObsNormalizer", "SB3Policy", "MARLPolicy", "marl_policy", "LOADERS", "learned_name_forms", "ZOO_DIR",
           "zoo_agents", "zoo_record", "export_agent", "check_scenario", "trained_config", "zoo_agents_for",
           "GUARDED_SETTINGS"]

#: Shipped agents: one folder per agent (``lawn zoo`` lists them).
ZOO_DIR = Path(__file__).parent / "zoo"
def _sb3() -> ModuleType:
    try:
        import stable_baselines3
        import torch
    except ImportError:  # exercised only without the extra
        raise MissingExtra(f"trained agents need the rl extra: {RL_EXTRA}") from None
    torch.set_num_threads(1)  # small networks, one observation at a time
    return stable_baselines3


def _selected(path: Path) -> tuple[Path, Path]:
    """The model a run directory stands for and its statistics: the one selected on the
    validation seeds (``best_model.zip``) when the run kept one, else the final model."""
    path = Path(path)
    if (path / "best_model.zip").exists():
        return path / "best_model.zip", path / "best_vecnormalize.pkl"
    return path / "model.zip", path / "vecnormalize.pkl"


#: What reading a damaged or truncated archive raises: the zip's directory (``zipfile.BadZipFile``;
#: torch's own reader: ``RuntimeError``), a member cut short (``RuntimeError``, ``EOFError``), the
#: pickled part (``UnpicklingError``).
DAMAGED = (zipfile.BadZipFile, RuntimeError, EOFError, pickle.UnpicklingError)
#: What an archive that lost its data also raises (SB3: ``AssertionError`` "No data found", a JSON
#: ``ValueError``, a missing ``KeyError``), and a readable one for other reasons (mismatched spaces):
#: damage only when the zip itself does not read back.
_MAYBE_DAMAGED = (ValueError, AssertionError, KeyError)


def _zip_reads(path: Path) -> bool:
    try:
        with zipfile.ZipFile(path) as zf:
            return zf.testzip() is None and bool(zf.namelist())
    except (zipfile.BadZipFile, OSError, EOFError):
        return False


def load_saved(load: Callable[[str], Any], path: Path, what: str) -> Any:
    """``load(path)`` for a saved model or network; a damaged or truncated file raises a
    ``ValueError`` that names it (not a library's internal error); other errors pass unchanged."""
    path = Path(path)
    try:
        return load(str(path))
    except DAMAGED + _MAYBE_DAMAGED as exc:
        if isinstance(exc, _MAYBE_DAMAGED) and not isinstance(exc, DAMAGED) and _zip_reads(path):
            raise
        detail = str(exc).splitlines()[0][:200] if str(exc) else "no detail"
        raise ValueError(f"{path}: cannot read this {what}: the file is damaged or truncated "
                         f"({type(exc).__name__}: {detail}); restore it (git checkout, a copy) or retrain it") from exc


def _load_model(run: RunDir) -> Any:
    _sb3()
    cls = algorithm_class(run.algo, f"{run.path}: run.json: ")
    return load_saved(lambda p: cls.load(p, device="cpu"), _selected(run.path)[0], f"{run.algo} model")


class ObsNormalizer:
    """SB3 ``VecNormalize``'s observation transform, frozen: ``clip((x - mean) / sqrt(var + eps))``."""

    def __init__(self, mean: np.ndarray, var: np.ndarray, clip: float, epsilon: float):
        self.mean, self.var = np.asarray(mean, dtype=np.float64), np.asarray(var, dtype=np.float64)
        self.clip, self.epsilon = float(clip), float(epsilon)

    @classmethod
    def from_vecnormalize(cls, venv: Any) -> ObsNormalizer | None:
        if venv is None or not getattr(venv, "norm_obs", False):
            return None
        return cls(venv.obs_rms.mean, venv.obs_rms.var, venv.clip_obs, venv.epsilon)

    @classmethod
    def load(cls, path: Path) -> ObsNormalizer | None:
        """From ``vecnormalize.pkl`` (a run directory) or ``normalizer.npz`` (a shipped agent)."""
        path = Path(path)
        if not path.exists():
            return None
        if path.suffix == ".npz":
            data = np.load(path)
            return cls(data["mean"], data["var"], float(data["clip"]), float(data["epsilon"]))
        try:
            with open(path, "rb") as fh:
                return cls.from_vecnormalize(pickle.load(fh))
        except Exception as exc:  # a truncated or foreign pickle: say which file
            raise ValueError(f"{path}: not a readable VecNormalize file ({type(exc).__name__}: {exc})") from None

    def save(self, path: Path) -> None:
        np.savez(path, mean=self.mean.astype(np.float32), var=self.var.astype(np.float32), clip=self.clip,
                 epsilon=self.epsilon)

    def normalize_obs(self, obs: np.ndarray) -> np.ndarray:
        x = (np.asarray(obs, dtype=np.float64) - self.mean) / np.sqrt(self.var + self.epsilon)
        return np.clip(x, -self.clip, self.clip).astype(np.float32)


class SB3Policy(InterfacePolicy):
    """A trained single-agent network acting on ``lawn/Joint-v1`` or ``lawn/Comm-v1``.

    ``network(obs) -> action`` is any deterministic SB3 predictor (a model or a bare policy);
    observations pass through the training interface's clipping and the normalizer, actions
    through the training scheme's decode and the v0 encode (:func:`lawn_env.action_codec`). With
    the interface's ``layout="entities"`` the observation is rearranged into the entity layout and
    the network's entity action gathered back (:mod:`lawn_env.entities`), so one network trained on
    one fleet size acts on any other (up to ``MAX_AGVS``).
    """

    name = "sb3"
    env_ids = (JOINT, COMM)

    def __init__(self, network: Any, config: ScenarioConfig, env_id: str, interface: InterfaceLike = None,
                 normalizer: ObsNormalizer | None = None, seed: int | None = None, label: str = "sb3"):
        super().__init__(config, env_id, interface, seed)
        self.network = network
        self.normalizer = normalizer
        self.name = label
        self.entities = None
        self.residual: Any = None  # agents.residual.ResidualActions: with_residual
        #: the residual scheme the agent's run records ({"anchor": NAME, "scale": s, "moves": [...]}; None: none)
        self.residual_settings: Mapping[str, Any] | None = None
        self._predict = _predictor(network)
        if self.interface.layout == "entities":
            self.entities = EntityLayout(self.config, env_role(env_id), self.interface.obs_bound,
                                         self.interface.action_scheme)
            seen = getattr(network.observation_space, "spaces", {})
            if {k: v for k, v in seen.items() if k != "me"} != self.entities.observation_space.spaces:
                raise ValueError(f"{label} expects observations {network.observation_space}; this scenario gives "
                                 f"{self.entities.observation_space}: evaluate it on the scenario it was trained for "
                                 "(agents.trained_config)")
        elif tuple(network.observation_space.shape) != (self.layout.size,):
            raise ValueError(f"{label} expects observations of shape {tuple(network.observation_space.shape)}; this "
                             f"scenario gives ({self.layout.size},): evaluate it on the scenario it was trained for "
                             "(agents.trained_config)")

    @classmethod
    def from_run(cls, path: str | Path, config: ScenarioConfig | None = None, env_id: str | None = None,
                 seed: int | None = None) -> SB3Policy:
        path = Path(path)
        run = read_run(path, require_model=True)
        trained_env = run.env
        if trained_env not in cls.env_ids:
            raise ValueError(f"{path} was trained on {trained_env}; use marl:{path} for multi-agent runs")
        if env_id not in (None, trained_env):
            raise ValueError(f"{path} was trained on {trained_env}, not {env_id}")
        trained = run.load_config()
        played = config if config is not None else trained
        check_scenario(f"sb3:{path}", trained_env, trained, played, run.interface)
        policy = cls(_load_model(run), played, trained_env, run.interface, ObsNormalizer.load(_selected(path)[1]), seed,
                     label=f"sb3:{path}")
        return policy._recorded(run.record.residual)

    def with_residual(self, actions: Any) -> SB3Policy:
        """Act by the residual scheme (an :class:`agents.residual.ResidualActions` around its anchor:
        the network's action moves the anchor's; :func:`agents.policies.attach_residual` builds it from
        the run's record, ``residual_settings``); returns the policy."""
        if self.entities is not None:
            raise ValueError(f"{self.name}: the residual scheme moves flat actions, not the entity layout's")
        self.residual = actions
        self.stateful = True  # the anchor keeps per-episode state
        return self

    def at_zero(self) -> SB3Policy:
        """The network's zero action every slot: the anchor of its own action scheme (a residual
        agent's anchor policy through the scheme, else its interface's anchor), what a run started at
        the anchor starts from; named ``zero:<name>``."""
        shape = self.network.action_space.shape
        self._predict = lambda inputs: np.zeros(shape, dtype=np.float32)
        self.name = f"zero:{self.name}"
        return self

    def _recorded(self, residual: Mapping[str, Any] | None) -> SB3Policy:
        """Keep the residual scheme a run records, for :func:`agents.make_policy` to attach."""
        self.residual_settings = residual
        return self

    def _on_reset(self, rng: np.random.Generator) -> None:
        super()._on_reset(rng)
        if self.residual is not None:
            self.residual.reset(int(rng.integers(2**31)))

    def observation_hint(self, shape: tuple[int, ...]) -> str:
        return _built_for(self, shape, self.entities is not None)

    def act(self, obs: np.ndarray) -> np.ndarray:
        raw = self.check_observation(obs)
        x = self.interface.observe(raw.copy())
        if self.normalizer is not None:
            x = self.normalizer.normalize_obs(x)
        inputs: np.ndarray | dict[str, np.ndarray] = x  # the network's: a dict under the entity layout
        if self.entities is not None:
            inputs = {key: value[0] for key, value in self.entities.observe(x[None]).items()}
        action = np.clip(np.asarray(self._predict(inputs), dtype=np.float64), -1.0, 1.0)
        if self.entities is not None:
            action = self.entities.to_flat_actions(action)
        if self.residual is not None:
            action = self.residual.action(action, raw)
        return self.to_v0(action, raw)


#: The settings a network is tied to by its training: the AGVs' control law (where the agent acts
#: through it), the actuator (the buffer in its observations and actions), the horizon (its reference
#: window) and, for a network that is not a fleet network (the entity layout), the fleet size.
GUARDED_SETTINGS = ("control.law", "control.actuator", "control.horizon", "num_agvs")


def check_scenario(label: str, env_id: str, trained: ScenarioConfig, config: ScenarioConfig,
                   interface: InterfaceLike = None) -> None:
    """Refuse to build an agent for a scenario that differs from its training scenario in a setting of
    :data:`GUARDED_SETTINGS`: one error naming the setting, the value it was trained with and this
    scenario's, whichever entry point builds the agent (``make_policy``, ``compare``, the CLI, the
    protocols). The law counts where the agent acts through it: on Comm the env's AGVs apply it (its
    power and drone decisions assume their increments), on Joint an anchored interface's MPC increment
    anchor plans by it. A fleet network acts at any K up to ``MAX_AGVS``."""
    iface = resolve_interface(interface)
    fleet = iface.layout == "entities"
    uses_law = env_id == COMM or (iface.action_scheme == "anchored" and iface.increment_anchor == "mpc")
    unused = {name for name, skip in (("control.law", not uses_law), ("num_agvs", fleet)) if skip}
    for setting in GUARDED_SETTINGS:
        was, now = _setting(trained, setting), _setting(config, setting)
        if setting not in unused and was != now:
            raise ValueError(f"{label} was trained on {env_id} with {setting}={was!r} and acts only there; this "
                             f"scenario has {setting}={now!r} (command line: --set {setting}={was}; Python: "
                             f"config=trained_config({label!r}) or a config with {setting}={was!r})")
    if fleet and config.num_agvs > MAX_AGVS:
        raise ValueError(f"{label} is a fleet network: it acts at K <= {MAX_AGVS}; this scenario has "
                         f"num_agvs={config.num_agvs}")


def _setting(config: ScenarioConfig, dotted: str) -> object:
    """The value of a config field by its dotted name (``control.law``)."""
    value: object = config
    for part in dotted.split("."):
        value = getattr(value, part)
    return value


def zoo_agents_for(config: ScenarioConfig) -> list[str]:
    """The shipped agents (``zoo:NAME``) that act on ``config``: those :func:`check_scenario` lets
    through (the learned protocol's and the suite's agents on the default scenario; ``zoo:dv-comm`` and
    ``zoo:dv-joint``, trained under the delivery law, are compared on their own scenarios)."""
    names = []
    for name, record in zoo_agents().items():
        try:
            check_scenario(f"zoo:{name}", record.env, ScenarioConfig.from_dict(dict(record.scenario)), config,
                           record.interface)
        except ValueError:
            continue
        names.append(f"zoo:{name}")
    return names


def trained_config(name: str) -> ScenarioConfig:
    """The scenario a learned agent (``zoo:NAME``, ``sb3:DIR``, ``bc:DIR``, ``marl:DIR``, ``zero:AGENT``)
    was trained on: ``make_policy(name, config=trained_config(name))`` builds it there, and
    ``gym.make(env_id, config=trained_config(name))`` is its env."""
    prefix, _, rest = name.partition(":")
    if prefix == "zero":
        return trained_config(rest)
    if prefix == "zoo":
        return ScenarioConfig.from_dict(dict(zoo_record(rest).scenario))
    if prefix in ("sb3", "bc", "marl"):
        return read_run(rest).load_config()
    raise ValueError(f"trained_config({name!r}): not a learned agent; valid forms: zoo:NAME, sb3:DIR, bc:DIR, "
                     "marl:DIR, zero:AGENT")


def _predictor(network: Any) -> Any:
    """The deterministic action of a network for one observation: a fleet network
    (:class:`agents.fleet.FleetPolicy`) through its compiled copy (:class:`agents.fleet.FleetInference`,
    the same actions to float32 rounding, several times faster on one observation), any other
    through SB3's ``predict``."""
    from .fleet import FleetInference, FleetPolicy

    policy = getattr(network, "policy", network)
    if isinstance(policy, FleetPolicy):
        return FleetInference(policy)
    return lambda x: network.predict(x, deterministic=True)[0]


class MARLPolicy(InterfacePolicy):
    """A parameter-shared multi-agent policy driving ``lawn/Joint-v1`` from the central observation:
    each agent's observation is rebuilt as SuperSuit built it in training (padding, one-hot agent
    indicator), the agents' actions are assembled into the central action of the training scheme
    and carried to the v0 action like :class:`SB3Policy`."""

    name = "marl"
    env_ids = (JOINT,)

    def __init__(self, network: Any, config: ScenarioConfig, interface: InterfaceLike = None,
                 normalizer: ObsNormalizer | None = None, seed: int | None = None, label: str = "marl"):
        super().__init__(config, JOINT, interface, seed)
        self.network = network
        self.normalizer = normalizer
        self.name = label
        k = self.config.num_agvs
        self.n_agents = k + 1
        self.obs_width = network.observation_space.shape[0] - self.n_agents
        if self.obs_width != self.layout.size:
            raise ValueError(f"{label} expects {network.observation_space.shape[0]} inputs; this scenario "
                             f"has K={k}: evaluate it on the scenario it was trained for (agents.trained_config)")

    @classmethod
    def from_run(cls, path: str | Path, config: ScenarioConfig | None = None, env_id: str | None = None,
                 seed: int | None = None) -> InterfacePolicy:
        path = Path(path)
        run = read_run(path, require_model=True)
        if run.env != PARALLEL_ENV_ID:
            raise ValueError(f"{path} was trained on {run.env}, not the multi-agent env; use sb3:{path}")
        if env_id not in (None, JOINT):
            raise ValueError(f"{path} is a multi-agent policy; it drives {JOINT}, not {env_id}")
        trained = run.load_config()
        check_scenario(f"marl:{path}", run.env, trained, config if config is not None else trained, run.interface)
        return marl_policy(_load_model(run), config if config is not None else trained, run.interface,
                           ObsNormalizer.load(_selected(path)[1]), seed, label=f"marl:{path}")

    def observation_hint(self, shape: tuple[int, ...]) -> str:
        return _built_for(self, shape, False)

    def agent_observations(self, obs: np.ndarray) -> np.ndarray:
        """(K+1, width): the drone's and each AGV's padded observation with its one-hot indicator,
        in PettingZoo's agent order (drone, agv_0, ...), as the agents see them (clipped)."""
        central = self.interface.observe(self.check_observation(obs).copy())
        blocks = self.layout.agv_blocks(central)
        glob = central[-self.layout.global_features:]
        out = np.zeros((self.n_agents, self.obs_width + self.n_agents), dtype=np.float32)
        out[0, : central.size] = central
        for i in range(self.n_agents - 1):
            own = np.concatenate([blocks[i], glob])
            out[i + 1, : own.size] = own
        out[np.arange(self.n_agents), self.obs_width + np.arange(self.n_agents)] = 1.0
        return out

    def act(self, obs: np.ndarray) -> np.ndarray:
        x = self.agent_observations(obs)
        if self.normalizer is not None:
            x = self.normalizer.normalize_obs(x)
        actions, _ = self.network.predict(x, deterministic=True)
        actions = np.clip(np.asarray(actions, dtype=np.float64), -1.0, 1.0)
        k = self.config.num_agvs
        plan = self.scheme.plan_size // k  # each AGV's plan after its increment (the buffered actuator's)
        central = np.concatenate([actions[1:, :2].reshape(-1), actions[0, : k + 2],
                                  actions[1:, 2 : 2 + plan].reshape(-1)])
        return self.to_v0(central, np.asarray(obs, dtype=np.float32))


def _built_for(policy: Any, shape: tuple[int, ...], fleet: bool) -> str:
    """The hint of a learned policy's observation-shape error when the observation is another
    fleet size's: the K the policy was built for and what to pass ``make_policy`` so that it acts
    on the env at hand (a fleet network acts at any K; another network at its training K only)."""
    seen = policy.layout.fleet_size_of(shape)
    if seen is None:  # not an observation of another K: the shape alone says what is wrong
        return ""
    label, k = policy.name, policy.config.num_agvs
    head = f"{label} was built for K = {k} and this observation is of K = {seen}"
    if fleet and seen > MAX_AGVS:
        return f"{head}; a fleet network acts at K <= {MAX_AGVS} only"
    if fleet:
        return (f"{head}; a fleet network acts at any K up to {MAX_AGVS} without retraining: "
                f"make_policy({label!r}, config=env.unwrapped.config)")
    return f"{head}; it acts on the fleet size it was trained at only (retrain it at K = {seen})"


def marl_policy(network: Any, config: ScenarioConfig, interface: InterfaceLike, normalizer: ObsNormalizer | None,
                seed: int | None, label: str) -> InterfacePolicy:
    """A multi-agent network on ``lawn/Joint-v1``: :class:`MARLPolicy`, or for the entity layout
    (a fleet network, which computes every agent's row at once) :class:`SB3Policy`."""
    if resolve_interface(interface).layout == "entities":
        from .fleet import FleetPolicy

        if not isinstance(getattr(network, "policy", network), FleetPolicy):
            raise ValueError(f"{label}: a multi-agent network of the entity layout drives {JOINT} when it is a "
                             f"FleetPolicy (lawn train --hp policy=FleetPolicy), got "
                             f"{type(getattr(network, 'policy', network)).__name__}")
        return SB3Policy(network, config, JOINT, interface, normalizer, seed, label=label)
    return MARLPolicy(network, config, interface, normalizer, seed, label=label)


# ---------------------------------------------------------------------- shipped agents (zoo)
def export_agent(run_dir: Path, out_dir: Path, record: Mapping[str, Any]) -> Path:
    """Write a run's policy network (weights only: no optimizer state, and for SAC/TD3 the actor
    alone, without critics) and observation statistics as a shipped agent with ``agent.json``."""
    run_dir, out_dir = Path(run_dir), Path(out_dir)
    run = read_run(run_dir, require_model=True)
    model = _load_model(run)
    # a fleet network is loaded by its own class (ALGORITHMS["fleet"]), whoever trained it
    algo = "fleet" if type(getattr(model, "policy", None)).__name__ == "FleetPolicy" else run.algo
    agent = {"algo": algo, "trainer": run.record.trainer or run.algo, "env": run.env, "interface": run.interface,
             **({"residual": run.record.residual} if run.record.residual else {}),
             "config": read_json(run_dir / "config.json"), **record}
    AgentRecord.model_validate(agent)  # what zoo_record will read back, checked before any file is written
    normalizer = ObsNormalizer.load(_selected(run_dir)[1])
    out_dir.mkdir(parents=True, exist_ok=True)
    (model.actor if algo in ("sac", "td3") else model.policy).save(str(out_dir / "policy.zip"))
    if normalizer is not None:
        normalizer.save(out_dir / "normalizer.npz")
    (out_dir / "agent.json").write_text(json.dumps(agent, indent=2) + "\n")
    return out_dir


def zoo_agents() -> dict[str, AgentRecord]:
    """Shipped agents by name: their ``agent.json`` records."""
    if not ZOO_DIR.is_dir():
        return {}
    return {p.parent.name: read_record(p, "zoo") for p in sorted(ZOO_DIR.glob("*/agent.json"))}


def zoo_record(name: str) -> AgentRecord:
    """The ``agent.json`` record of the shipped agent ``name``; an unknown name is an error listing the
    shipped ones."""
    agents = zoo_agents()
    if name not in agents:
        raise ValueError(f"unknown zoo agent {name!r}; shipped: {', '.join(agents) or 'none'} (lawn zoo lists them)")
    return agents[name]


def _load_zoo(name: str, config: ScenarioConfig | None = None, env_id: str | None = None, seed: int | None = None
              ) -> Policy:
    record = zoo_record(name)
    _sb3()
    network_class = policy_network_class(record.algo, f"zoo:{name}: agent.json: ")
    network = load_saved(lambda p: network_class.load(p, device="cpu"), ZOO_DIR / name / "policy.zip",
                         f"zoo agent's {record.algo} network")
    trained = ScenarioConfig.from_dict(dict(record.scenario))
    cfg = config if config is not None else trained
    check_scenario(f"zoo:{name}", record.env, trained, cfg, record.interface)
    normalizer = ObsNormalizer.load(ZOO_DIR / name / "normalizer.npz")
    if record.env == PARALLEL_ENV_ID:
        if env_id not in (None, JOINT):
            raise ValueError(f"zoo:{name} is a multi-agent policy; it drives {JOINT}, not {env_id}")
        return marl_policy(network, cfg, record.interface, normalizer, seed, label=f"zoo:{name}")
    if env_id not in (None, record.env):
        raise ValueError(f"zoo:{name} was trained on {record.env}, not {env_id}")
    policy = SB3Policy(network, cfg, record.env, record.interface, normalizer, seed, label=f"zoo:{name}")
    return policy._recorded(record.residual)


def _no_settings(loader: Callable[..., Policy]) -> Callable[..., Policy]:
    def load(path: str, config: ScenarioConfig | None = None, env_id: str | None = None, seed: int | None = None,
             **kwargs: Any) -> Policy:
        if kwargs:
            raise ValueError(f"learned policies take no settings; got {sorted(kwargs)}")
        return loader(path, config, env_id, seed)

    return load


def _load_zero(name: str, config: ScenarioConfig | None = None, env_id: str | None = None, seed: int | None = None,
               **kwargs: Any) -> Policy:
    """``zero:zoo:NAME``, ``zero:sb3:DIR``, ``zero:bc:DIR``: the agent's zero action in its own action
    scheme (:meth:`SB3Policy.at_zero`), on the agent's scenario and env."""
    prefix, _, rest = name.partition(":")
    if prefix not in ("zoo", "sb3", "bc"):
        raise ValueError(f"zero:{name}: the zero action of a learned agent is zero:zoo:NAME, zero:sb3:DIR or "
                         "zero:bc:DIR")
    policy = LOADERS[prefix](rest, config, env_id=env_id, seed=seed, **kwargs)
    if not isinstance(policy, SB3Policy):
        raise ValueError(f"zero:{name}: {type(policy).__name__} has no zero action of its own; zero: takes "
                         "single-agent networks")
    return policy.at_zero()


#: Prefixes of ``make_policy`` names for learned agents and their anchors: ``zoo:NAME``, ``sb3:DIR``,
#: ``bc:DIR``, ``marl:DIR``, ``anchor:NAME`` (the zero action of an interface, :mod:`agents.anchors`)
#: and ``zero:AGENT`` (a learned agent's zero action in its own scheme: a residual agent's start).
LOADERS: dict[str, Callable[..., Policy]] = {
    "zoo": _no_settings(_load_zoo), "sb3": _no_settings(SB3Policy.from_run), "bc": _no_settings(SB3Policy.from_run),
    "marl": _no_settings(MARLPolicy.from_run), "anchor": load_anchor, "zero": _load_zero}
_FORMS = {"zoo": "NAME", "anchor": "NAME", "zero": "AGENT"}


def learned_name_forms(sep: str = ", ") -> str:
    """The forms of learned agents' names, for messages and help texts: ``zoo:NAME, sb3:DIR, ...``."""
    return sep.join(f"{prefix}:{_FORMS.get(prefix, 'DIR')}" for prefix in LOADERS)
