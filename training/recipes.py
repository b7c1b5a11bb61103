"""The recipes of the shipped learned agents (:data:`RECIPES`; ``lawn zoo train`` runs them,
:func:`training.train.train_recipes`) and lawn's PPO hyperparameters in rl-baselines3-zoo's form
(:func:`zoo_hyperparams`; this module's ``hyperparams``, made when read)::

    python -m rl_zoo3.train --algo ppo --env lawn/CommRL-v1 --gym-packages lawn_env --conf-file training.recipes
"""

from __future__ import annotations

import json
import shlex
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from agents.runs import read_run
from lawn_env import PARALLEL_ENV_ID, RL_ENV_IDS, ScenarioConfig, central_env_id, presets

from .spec import LAWN_KEYS, Hyperparameters, TrainSpec, load_hyperparams

__all__ = ["Recipe", "RECIPES", "SECTIONS", "DISTIL_TASKS", "recipe", "finished",
           "ZOO_VALIDATION_EPISODES", "zoo_hyperparams"]


@dataclass(frozen=True)
class Recipe:
    """One learned comparator: ``lawn train`` arguments, its training seeds and its table label."""

    name: str
    label: str
    algo: str
    env_id: str
    timesteps: int
    seeds: tuple[int, ...] = (0, 1, 2)
    hp: Hyperparameters = field(default_factory=dict)
    init_from: str | None = None  # another recipe's name: seed s starts from that recipe's seed s
    eval_every: int = 25_000
    vec: Literal["dummy", "native"] = "dummy"  # lawn train --vec: "native" trains on lawn's batched vector env
    section: str = "main"  # where docs/LEARNED.md shows it: the page's tables, or the "fleet" block (SECTIONS)
    num_agvs: int = 4  # the fleet it trains on (lawn train --set num_agvs=K); every recipe is evaluated at K = 4
    preset: str = "default"  # the scenario it trains and validates on (lawn train --preset)
    settings: dict[str, Any] = field(default_factory=dict)  # config keys over the preset (lawn train --set)
    eval_episodes: int = 20  # validation episodes (ZOO_VALIDATION_EPISODES unless the recipe needs more)
    checkpoint_every: int = 10_000  # steps between the run's checkpoints (lawn train --checkpoint-every)

    @property
    def config(self) -> ScenarioConfig:
        """The scenario it trains on: its preset with its settings and fleet size."""
        base = presets.get(self.preset)
        size = {} if self.num_agvs == base.num_agvs else {"num_agvs": self.num_agvs}
        return base.override(dict(self.settings), **size)

    @property
    def evaluated_on(self) -> str:
        return central_env_id(self.env_id)

    def spec(self, runs: Path, seed: int) -> TrainSpec:
        """The run of ``seed`` under ``runs`` (``runs/<name>/seed-<s>``; a fine-tune starts from its
        source recipe's run of the same seed)."""
        return TrainSpec(algo=self.algo, env_id=self.env_id, config=self.config, timesteps=self.timesteps, seed=seed,
                         out_dir=runs / self.name / f"seed-{seed}", hp_overrides=dict(self.hp),
                         eval_every=self.eval_every, eval_episodes=self.eval_episodes,
                         checkpoint_every=self.checkpoint_every, progress=False,
                         vec=self.vec, init_from=runs / self.init_from / f"seed-{seed}" if self.init_from else None)

    def command(self) -> str:
        parts = [f"lawn train --algo {self.algo} --env {self.env_id} --timesteps {self.timesteps}",
                 f"--seeds {' '.join(map(str, self.seeds))}", f"--out RUNS/{self.name}",
                 f"--eval-every {self.eval_every} --eval-episodes {self.eval_episodes}"]
        if self.checkpoint_every != 10_000:
            parts.append(f"--checkpoint-every {self.checkpoint_every}")
        parts += [f"--hp {shlex.quote(f'{k}={json.dumps(v)}')}" for k, v in self.hp.items()]
        if self.vec != "dummy":
            parts.append(f"--vec {self.vec}")
        if self.preset != "default":
            parts.append(f"--preset {self.preset}")
        sets = {**self.settings, **({} if self.num_agvs == presets.get(self.preset).num_agvs else
                                    {"num_agvs": self.num_agvs})}
        parts += [f"--set {k}={v}" for k, v in sets.items()]
        if self.init_from:
            parts.append(f"--init-from RUNS/{self.init_from}/seed-<s>")
        return " ".join(parts)


#: Validation episodes of every zoo run (model selection; the test seeds are never used).
ZOO_VALIDATION_EPISODES = 20
#: Imitation at scale: 100,000 labels of rg-mpc, then 4 DAgger rounds of 10,000 on the clone's own
#: states, a 256 x 256 network (at 12,000 + 4 x 4,800 labels and 128 x 128 the clone was
#: +2.8 % of rg-mpc on the test seeds; at this budget +0.1 %, 13-14 minutes a run two side by side).
_BC_AT_SCALE = {"dagger_iterations": 4, "dagger_timesteps": 10_000,
                "policy_kwargs": {"net_arch": [256, 256], "log_std_init": -1.0}}
_FINE_TUNE = {"learning_rate": "lin_5e-5", "clip_range": 0.1, "init_log_std": -2.5, "actor_warmup_steps": 10_000,
              "policy_kwargs": {"net_arch": [256, 256], "log_std_init": -1.0}}  # the clone's network
#: From scratch at RL scale: the distance prior and the centroid drone (no MPC in the action; the Comm
#: env's own MPC still drives the AGVs), started at that prior (the output layer zeroed: the untrained
#: policy's mean is the zero action, so the curve's "vs start" is the change against the prior), on 256
#: scenarios of the native vector env. A rollout is one whole episode of each (120 slots: every update
#: sees every phase of the episode, the transient and the steady part alike), 30,720 steps, taken in 4
#: minibatches of 7,680 for 4 epochs; a 64 x 64 network (the update is most of a run's time, and 128 x 128
#: learned no faster per step on the ladder's first rung). At 8 scenarios, 2,048-step rollouts in
#: minibatches of 256 for 10 epochs and 128 x 128 (the version before), a million steps moved nothing
#: (+0.4 % +- 1.7 % against the prior) at a ninth of the speed (benchmarks/scratch_throughput.py).
_SCRATCH: Hyperparameters = {"interface": {"base": "rl", "power_anchor": "distance", "reward": "log",
                                          "cost_clip": 10_000.0}, "start_at_anchor": True,
                            "n_envs": 256, "n_steps": 120, "batch_size": 7680, "n_epochs": 4,
                            "learning_rate": "lin_3e-4", "policy_kwargs": {"net_arch": [64, 64], "log_std_init": -1.0}}
#: From scratch on Joint: the same, with the LQR baseline's increments under the residual.
#: Its runs are selected by the geometric mean of the per-seed cost ratios: the prior's validation costs
#: are heavy-tailed (1,249 +- 775 on 50 seeds: the seeds where an AGV is lost), and on a first run by the
#: relative rule the final network closed 45 % [17, 63] of the prior's gap to dv-mpc on the validation
#: seeds while its relative mean against the prior, -8 % +- 13 %, never cleared the gate (it shipped the prior).
_SCRATCH_JOINT = {**_SCRATCH, "interface": {**_SCRATCH["interface"], "increment_anchor": "lqr", "residual_scale": 0.2},
                  "selection": "geometric"}
#: The scratch runs' budget (10 M steps, as RL is compared) and their validation: every 500,000 steps
#: on 50 seeds (at 20 the interval on the change against the start was +-12 % on default).
_SCRATCH_STEPS, _SCRATCH_EVERY, _SCRATCH_EPISODES = 10_000_000, 500_000, 50

#: One network for every fleet size (agents/fleet.py, training/hyperparams/fleet.yml): one training
#: seed (a run is about 25 minutes, two side by side on 2 cores).
_FLEET_SEEDS = (0,)
#: Distillation of dv-mpc into one fleet network for the steady suite tasks (each at its own K: the
#: entity layout serves K = 4 and 8 alike): 10,000 labels a task, then 4 DAgger rounds of 2,500 a task.
DISTIL_TASKS = ("steady", "steady-low-power", "steady-gusty", "wide-k8")
_DISTIL = {"expert": "dv-mpc", "tasks": list(DISTIL_TASKS), "dagger_timesteps": 10_000}
#: dv-mpc's AGVs on Comm: the env's MPC applies the delivery law the shipped clones were trained with (each
#: command planned as if it arrives, every later one priced as delivered: the certainty-equivalent tail).
_DELIVERY = {"control.law": "delivery-certainty-equivalent"}
#: On Joint the network's increments are a residual on the delivery-law MPC's (the anchored interface's
#: increment anchor plans as the scenario's law says), so what it learns is dv-mpc's power and drone, as
#: on Comm. Around the LQR's increments instead (the fleet networks' interface, no MPC in the decision)
#: the clone was +25 % to +47 % against dv-mpc on the four tasks with AGVs diverging (wide-k8: 26 % of
#: the seeds over 1.5x dv-mpc, one 1358x).
_DISTIL_JOINT = {**_DISTIL, "task_settings": _DELIVERY,
                 "interface": {"base": "rl", "power_anchor": "distance", "increment_anchor": "mpc",
                               "residual_scale": 2.0, "power_log_range": 4.0}}
#: RL past the anchor: PPO whose action moves dv-mpc's decision (agents/residual.py: a quarter of the
#: action range), on the paired reward against dv-mpc on the same seed (training/paired.py), started at
#: dv-mpc (the output layer zeroed) with small exploration; the interface decodes without an MPC. The
#: critic learns the paired return for 20,000 steps before the actor moves, at half the step size (without
#: the warm-up and at lin_1e-4 the first 30,000 steps took the validation cost 8.7 % above the start).
_RESIDUAL_DV: Hyperparameters = {
    "interface": {"base": "rl", "power_anchor": "distance", "increment_anchor": "lqr", "residual_scale": 2.0,
                  "power_log_range": 4.0},
    "residual": {"anchor": "dv-mpc", "scale": 0.25}, "paired_anchor": "dv-mpc", "start_at_anchor": True,
    "actor_warmup_steps": 20_000, "n_envs": 4, "n_steps": 256, "batch_size": 256, "learning_rate": "lin_5e-5",
    "policy_kwargs": {"net_arch": [128, 128], "log_std_init": -2.0}}
# On the poor-link task k16 (65 % of the commands lost) the same scheme, with the reward unclipped
# (interface cost_clip 1e4: 8 % of k16's slots cost over the default clip of 100 and carry its tail), found
# nothing either (150,000 steps, seeds 0 and 1, 24 minutes each two side by side, 72 % of it in dv-mpc's
# decisions). Moving the power and the drone (``"moves": ["power", "drone"]``, scale 0.25, lin_5e-5): no
# validation beat the start (the best -1.4 % ± 1.4 %, 50 seeds), and the final networks were +1.5 / -0.2 %
# and +1.1 / +1.6 % against dv-mpc on 50 test seeds of each range. Moving the drone alone (``["drone"]``,
# scale 0.5, lin_2e-4, 100 validation seeds): +1.4 % ± 0.9 % after 30,000 steps, +5.7 % ± 2.0 % and
# +4.8 % ± 3.0 % at the end. A change of one slot's power or drone flips deliveries that send the episode
# elsewhere, so the per-slot credit PPO assigns is mostly that noise; constant reshapings of dv-mpc's split
# (sharper or flatter, 24 seeds) and of its drone target (nearer the centroid, 40 seeds) were not
# significantly better than it. The runs: lawn train --algo ppo --env lawn/Joint-v1 --preset k16
# --timesteps 150000 --seeds 0 1 --eval-every 25000 --eval-episodes 50 --hp 'interface={"base": "rl",
# "power_anchor": "distance", "increment_anchor": "lqr", "residual_scale": 2.0, "power_log_range": 4.0,
# "cost_clip": 10000.0}' --hp 'residual={"anchor": "dv-mpc", "scale": 0.25, "moves": ["power", "drone"]}'
# --hp paired_anchor=dv-mpc --hp start_at_anchor=true --hp actor_warmup_steps=20000 --hp n_envs=4
# --hp n_steps=256 --hp batch_size=256 --hp learning_rate=lin_5e-5 --hp 'policy_kwargs={"net_arch": [128, 128],
# "log_std_init": -2.0}' --out RUNS/ppo-link-k16; the drone alone: --eval-every 30000 --eval-episodes 100,
# "scale": 0.5, "moves": ["drone"], actor_warmup_steps=10000, learning_rate=lin_2e-4, log_std_init -1.5;
# the test seeds: evaluation.api.compare(["dv-mpc", "sb3:DIR", "zero:sb3:DIR", "noise:dv-mpc"],
# config="k16", seeds=range(S, S + 50)) for S = 0 and 100000, .geometric (DIR: a copy of the run without
# best_model.zip, so that sb3:DIR loads the final model).
#: Multi-agent PPO with the fleet network (training/sb3.py): every agent sees the fleet and which
#: entity it is, and acts with its own row; started at the anchor (the heads zeroed), small steps.
_MARL_FLEET = {"interface": {"base": "rl", "layout": "entities"}, "policy": "FleetPolicy", "normalize": False,
               "start_at_anchor": True, "n_steps": 64, "batch_size": 256, "learning_rate": "lin_1e-4",
               "policy_kwargs": {"width": 32, "heads": 4, "layers": 2, "log_std_init": -3.0}}
#: The learned comparators. Training runs them in this order, the longest first (a recipe that
#: starts from another runs in a second phase); the tables list them per env in this order.
RECIPES: dict[str, Recipe] = {r.name: r for r in (
    Recipe("bc-comm", "BC of rg-mpc, 100k labels + 4 DAgger rounds", "bc", "lawn/Comm-v1", 100_000, hp=_BC_AT_SCALE),
    Recipe("bc-joint", "BC of rg-mpc, 100k labels + 4 DAgger rounds", "bc", "lawn/Joint-v1", 100_000,
           hp=_BC_AT_SCALE),
    Recipe("dv-joint", "Fleet network, DAgger of dv-mpc on the steady suite tasks (increments around the MPC)",
           "fleet", "lawn/Joint-v1", 40_000, seeds=_FLEET_SEEDS, hp=_DISTIL_JOINT, section="distil", preset="steady",
           settings=_DELIVERY),
    Recipe("dv-comm", "Fleet network, DAgger of dv-mpc on the steady suite tasks (delivery law)", "fleet",
           "lawn/Comm-v1", 40_000, seeds=_FLEET_SEEDS, hp={**_DISTIL, "task_settings": _DELIVERY}, section="distil",
           preset="steady", settings=_DELIVERY),
    Recipe("ppo-dv-residual", "PPO, residual on dv-mpc, paired reward", "ppo", "lawn/Joint-v1", 120_000, seeds=(0, 1),
           hp=_RESIDUAL_DV, eval_every=30_000, section="distil", preset="steady"),
    Recipe("fleet-comm", "Fleet network (attention over the AGVs), DAgger of rg-mpc on K = 3-32", "fleet",
           "lawn/Comm-v1", 50_000, seeds=_FLEET_SEEDS, section="fleet"),
    # DAgger of dv-mpc instead (--hp expert=dv-mpc, the same budget, 19 minutes): +101 % ± 154 % against
    # rg-mpc on the validation seeds (804 against 417), two seeds diverging: dv-mpc's increments, planned
    # as if every command arrives, are harder to follow from the LQR's; rg-mpc stays the teacher.
    Recipe("fleet-joint", "Fleet network (attention over the AGVs), DAgger of rg-mpc on K = 3-32", "fleet",
           "lawn/Joint-v1", 50_000, seeds=_FLEET_SEEDS, section="fleet"),
    Recipe("ppo-marl-fleet-k16", "PPO multi-agent, fleet network, trained at K = 16", "ppo", PARALLEL_ENV_ID,
           100_000, seeds=_FLEET_SEEDS, hp=_MARL_FLEET, eval_every=25_000, section="fleet", num_agvs=16),
    Recipe("ppo-marl-fleet-k64", "PPO multi-agent, fleet network, trained at K = 64", "ppo", PARALLEL_ENV_ID,
           30_000, seeds=_FLEET_SEEDS, hp=_MARL_FLEET, eval_every=10_000, section="fleet", num_agvs=64),
    Recipe("ppo-comm-scratch", "PPO from the distance prior (no MPC in the action)", "ppo", "lawn/Comm-v1",
           _SCRATCH_STEPS, hp=_SCRATCH, eval_every=_SCRATCH_EVERY, eval_episodes=_SCRATCH_EPISODES,
           checkpoint_every=_SCRATCH_EVERY, vec="native", section="scratch"),
    Recipe("ppo-joint-scratch", "PPO from the distance prior and the LQR (no MPC in the action)", "ppo",
           "lawn/Joint-v1", _SCRATCH_STEPS, hp=_SCRATCH_JOINT, eval_every=_SCRATCH_EVERY,
           eval_episodes=_SCRATCH_EPISODES, checkpoint_every=_SCRATCH_EVERY, vec="native", section="scratch"),
    *(Recipe(f"ppo-{rung.preset}-scratch", f"PPO from the prior on the ladder's rung {rung.preset!r}: {rung.learns}",
             "ppo", rung.env_id, _SCRATCH_STEPS, hp=_SCRATCH if rung.env_id == "lawn/Comm-v1" else _SCRATCH_JOINT,
             eval_every=_SCRATCH_EVERY, eval_episodes=_SCRATCH_EPISODES, checkpoint_every=_SCRATCH_EVERY,
           vec="native", section="ladder",
             preset=rung.preset) for rung in presets.LADDER if rung.preset != "default"),
    Recipe("ppo-comm", "PPO (RL interface)", "ppo", "lawn/Comm-v1", 300_000, eval_every=50_000, vec="native"),
    Recipe("ppo-joint", "PPO (RL interface, residual on the MPC)", "ppo", "lawn/Joint-v1", 300_000, eval_every=50_000,
           vec="native"),
    Recipe("sac-comm", "SAC (RL interface)", "sac", "lawn/Comm-v1", 20_000, eval_every=5_000),
    Recipe("ppo-marl", "PPO multi-agent, shared weights", "ppo", PARALLEL_ENV_ID, 150_000, eval_every=25_000),
    Recipe("ppo-comm-from-bc", "BC then PPO fine-tuning", "ppo", "lawn/Comm-v1", 60_000, init_from="bc-comm",
           hp=_FINE_TUNE, eval_every=10_000),
    Recipe("ppo-joint-from-bc", "BC then PPO fine-tuning", "ppo", "lawn/Joint-v1", 60_000, init_from="bc-joint",
           hp=_FINE_TUNE, eval_every=10_000),
)}


#: The sections of docs/LEARNED.md (``lawn zoo build`` rebuilds whole sections): ``main``, the
#: page's tables; ``fleet``, the fleet networks' tables (generated block ``zoo-fleet``); ``scratch``, the
#: agents learned from their prior at RL scale (``zoo-scratch``). The ladder's recipes (section
#: ``ladder``) ship no agent: ``python -m paper.ladder`` writes their block.
SECTIONS: tuple[str, ...] = ("main", "fleet", "distil", "scratch")


def recipe(name: str) -> Recipe:
    """The recipe called ``name`` (a clear error naming the recipes otherwise)."""
    if name not in RECIPES:
        raise ValueError(f"unknown recipe {name!r}; valid: {', '.join(RECIPES)}")
    return RECIPES[name]


def finished(run_dir: Path, timesteps: int) -> bool:
    """The run in ``run_dir`` has its run.json and its budget (a BC run: any)."""
    if not (run_dir / "run.json").exists():
        return False
    record = read_run(run_dir).record
    return (record.num_timesteps or 0) >= (timesteps if record.trainer != "bc" else 1)


def zoo_hyperparams(algo: str = "ppo") -> dict[str, Hyperparameters]:
    """rl-zoo3's hyperparameters of ``algo`` for every RL id whose base env's entry trains on the RL
    interface: without the keys only ``lawn train`` knows, dicts as the strings rl-zoo3 evaluates, and
    the budget (``n_timesteps``) of the plain recipe on that env."""
    plain = [r for r in RECIPES.values() if r.algo == algo and not r.hp and r.init_from is None]
    budgets = {r.env_id: r.timesteps for r in plain}
    if len(budgets) != len(plain):
        raise ValueError(f"more than one plain {algo} recipe per env: {[r.name for r in plain]}")
    zoo_keys = {"n_envs", "normalize", "policy"}  # rl-zoo3 reads these three itself
    out = {}
    for rl_id, base in RL_ENV_IDS.items():
        params, _ = load_hyperparams(algo, base)
        if params.get("interface", "rl") != "rl":
            continue
        zoo = {k: v for k, v in params.items() if k in zoo_keys or k not in LAWN_KEYS}
        if base in budgets:
            zoo["n_timesteps"] = budgets[base]
        for key in ("normalize", "policy_kwargs"):
            if isinstance(zoo.get(key), dict):
                zoo[key] = f"dict({', '.join(f'{k}={v!r}' for k, v in zoo[key].items())})"
        out[rl_id] = zoo
    return out


def __getattr__(name: str) -> Any:
    """``hyperparams``: what ``--conf-file training.recipes`` gives rl-zoo3 (PPO), made when read."""
    if name == "hyperparams":
        return zoo_hyperparams("ppo")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
