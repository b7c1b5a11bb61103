"""``lawn train``: Stable-Baselines3 agents, behaviour cloning and multi-agent training (rl extra)."""

from __future__ import annotations

import argparse
from pathlib import Path

from agents.errors import MissingExtra
from training.spec import ALGOS, TRAIN_ENV_IDS, TrainSpec
from training.train import resume, train, train_seeds
from training.validation import RunSummary

from .common import command, config_of, count, parse_overrides, seed


def add(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> argparse.ArgumentParser:
    tr = command(sub, "train", "workers", "quiet", "seed", "config", "backend")
    tr.add_argument("--algo", choices=ALGOS,
                    help="algorithm: SB3's, bc (behaviour cloning of an expert) or fleet (DAgger, one network "
                         "for any K)")
    tr.add_argument("--env", choices=TRAIN_ENV_IDS,
                    help="lawn/Parallel-v0 is the multi-agent PettingZoo env; CartPole-v1 checks the training "
                         "pipeline in seconds (it has no control cost: no validation on it)")
    tr.add_argument("--timesteps", type=count, help="environment steps (for bc: expert transitions)")
    tr.add_argument("--seeds", type=seed, nargs="+", metavar="SEED",
                    help="train one run per seed into OUT/seed-<s> (--workers, --backend) and summarize across seeds")
    tr.add_argument("--interface", default=None, choices=["rl", "v0"],
                    help="the RL interface (default: the hyperparameter file's, rl) or the plain v0 interface")
    tr.add_argument("--out", help="run directory")
    tr.add_argument("--n-envs", type=count, default=None,
                    help="parallel environments (default: the hyperparameter file)")
    tr.add_argument("--hp", action="append", default=[], metavar="KEY=VALUE",
                    help="hyperparameter override, e.g. --hp learning_rate=1e-4 (repeatable)")
    tr.add_argument("--eval-every", type=count, default=10000,
                    help="steps between validations (full unmodified episodes, realized control cost; "
                         "default: %(default)s)")
    tr.add_argument("--eval-episodes", type=count, default=5,
                    help="validation episodes (seeds 500000 + i; default: %(default)s)")
    tr.add_argument("--checkpoint-every", type=count, default=10000,
                    help="steps between checkpoints (default: %(default)s)")
    tr.add_argument("--init-from", metavar="DIR", help="start from a behaviour-cloned run of the same algorithm")
    tr.add_argument("--resume", metavar="DIR", help="continue an interrupted run from its last checkpoint")
    tr.add_argument("--vec", choices=["dummy", "native"], default="dummy",
                    help="SB3 DummyVecEnv of single envs (default) or lawn's batched vector env (Joint-v1, "
                         "Comm-v1 and their RL ids, any --interface)")
    tr.add_argument("--dataset", metavar="ID",
                    help="bc: clone the episodes of this Minari dataset (lawn dataset create) instead of live expert "
                         "rollouts; --timesteps caps the transitions")
    return tr


def run(args: argparse.Namespace) -> int:
    try:
        import stable_baselines3  # noqa: F401
        import supersuit  # noqa: F401
    except ImportError as exc:
        raise MissingExtra(f"training needs the rl extra ({exc.name} is missing): bash scripts/setup.sh full, "
                           "or pip install torch==2.13.0 && pip install -e '.[rl]'") from None
    if args.resume:
        return _resume(args)
    missing = [flag for flag, value in (("--algo", args.algo), ("--env", args.env), ("--out", args.out)) if not value]
    if missing:
        raise ValueError(f"lawn train needs {', '.join(missing)} (or --resume DIR)")
    if args.timesteps is None:
        raise ValueError("lawn train needs --timesteps")

    spec = TrainSpec(algo=args.algo, env_id=args.env, config=config_of(args), timesteps=args.timesteps,
                     seed=args.seed, out_dir=Path(args.out), hp_overrides=parse_overrides(args.hp, "--hp"),
                     n_envs=args.n_envs, interface=args.interface, vec=args.vec, eval_every=args.eval_every,
                     eval_episodes=args.eval_episodes, checkpoint_every=args.checkpoint_every,
                     init_from=Path(args.init_from) if args.init_from else None, dataset=args.dataset,
                     progress=not args.quiet)
    if not args.seeds:
        _report(train(spec), args.out)
        return 0
    result = train_seeds(spec, args.seeds, workers=args.workers, backend=args.backend)
    print(f"lawn train: {args.algo} on {args.env}, seeds {args.seeds}")
    for r in result.runs:
        print(f"  seed {r.seed}: best validation cost {r.best_validation_cost:.6g} "
              f"at {r.best_at_timesteps} steps, {r.timesteps} steps in {r.wall_time_s or 0.0:.0f} s"
              f"{_rate_part(r)}{_expert_part(r)}")
    print(f"  across seeds: {result.best_validation_cost_mean:.6g} ± "
          f"{result.best_validation_cost_ci95:.3g} (95 % interval)")
    print(f"wrote {args.out}/seed-*/ and {args.out}/seeds.json")
    return 0


def _resume(args: argparse.Namespace) -> int:
    summary = resume(Path(args.resume), timesteps=args.timesteps, progress=not args.quiet)
    start = summary.resumed_from
    print(f"lawn train: resumed {args.resume} from its checkpoint at {start} steps" if start is not None else
          f"lawn train: {args.resume} had no checkpoint; trained it again from the start")
    _report(summary, args.resume)
    return 0


def _report(summary: RunSummary, out: str) -> None:
    print(f"lawn train: {summary.algo} on {summary.env}, seed {summary.seed}, "
          f"{summary.timesteps} steps in {summary.wall_time_s or 0.0:.1f} s{_rate_part(summary)}"
          f"{_expert_part(summary)}")
    for key in ("final_validation_cost", "best_validation_cost", "best_at_timesteps", "bc_loss_first", "bc_loss_last"):
        value = getattr(summary, key)
        if value is not None:
            print(f"  {key:<24}{value:.6g}")
    print(f"wrote {out}/ (model.zip, run.json, config.json, hyperparams.json, learning curve, summary.md)")


def _rate_part(summary: RunSummary) -> str:
    """The run's environment steps per second of wall time (validation and checkpoints included)."""
    return f", {summary.steps_per_s:,.0f} steps/s" if summary.steps_per_s else ""


def _expert_part(summary: RunSummary) -> str:
    """How much of the run the expert's decisions took (a run where no expert decides: nothing)."""
    share = summary.expert_share
    return f" ({100 * share:.0f} % of it in the expert's decisions)" if share else ""
