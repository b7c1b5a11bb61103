"""The protocol every training run follows: disjoint seed ranges (training, validation and test
never meet), one torch thread per run, the versions in ``run.json``, and the learning curve and
summary written from the periodic validation."""

from __future__ import annotations

import csv
import dataclasses
import platform
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import lawn_env
from agents import Policy, make_policy, rollout
from agents.runs import AgentRecord, read_record
from evaluation.episode import read_csv
from evaluation.provenance import provenance
from evaluation.seeds import VALIDATION_SEED_BASE
from evaluation.stats import mean_ci, paired_difference, paired_geometric

__all__ = ["RunSummary", "VALIDATION_REFERENCE", "CURVE_FIELDS",
           "limit_torch_threads", "versions", "read_learning_curve", "selection_key", "selected_validation",
           "SELECTIONS", "selection_of", "run_key",
           "validation_costs", "validation_reference", "validation_row", "append_learning_curve",
           "write_learning_curve"]

def limit_torch_threads(threads: int = 1) -> None:
    """``threads`` torch threads (default one: the networks are small, and more oversubscribe the cores of
    runs side by side; SAC's update was 100x slower with two concurrent runs)."""
    import torch

    torch.set_num_threads(threads)


def versions() -> dict[str, str]:
    """The versions of lawn, SB3, torch, Gymnasium and Python, and the source commit."""
    import gymnasium
    import stable_baselines3
    import torch

    return {"lawn": lawn_env.__version__, "stable_baselines3": stable_baselines3.__version__,
            "torch": torch.__version__, "gymnasium": gymnasium.__version__, "python": platform.python_version(),
            "source": provenance()}


#: The columns of ``learning_curve.csv``: the mean control cost on the validation seeds and the paired
#: relative differences against ``rg-mpc`` and against the run's starting policy (its first validation),
#: each with its 95 % half-width.
CURVE_FIELDS = ("timesteps", "control_cost", "control_cost_ci95", "vs_reference", "vs_reference_ci95",
                "vs_start", "vs_start_ci95", "vs_reference_geometric", "vs_start_geometric", "vs_start_geometric_low",
                "vs_start_geometric_high")
#: Model selection's rules (``lawn train --hp selection=...``, :func:`selected_validation`).
SELECTIONS = ("relative", "geometric")
#: The policy whose costs on the validation seeds pair every validation.
VALIDATION_REFERENCE = "rg-mpc"


def read_learning_curve(run_dir: Path) -> list[dict[str, float]]:
    """The rows of ``learning_curve.csv`` as floats, in order; an empty column (behaviour cloning has
    no start to pair with; older runs) is absent from its row."""
    return [{k: float(v) for k, v in r.items() if v not in ("", None)}
            for r in read_csv(Path(run_dir) / "learning_curve.csv")]


def selection_key(row: Mapping[str, float], rule: str = "relative") -> float:
    """What model selection minimizes: by the ``relative`` rule the paired relative difference against
    ``rg-mpc`` (pairing on the same seeds keeps one heavy-tailed episode from deciding, as it can the
    mean cost, which runs recorded without the column fall back to); by the ``geometric`` rule the
    geometric mean of the per-seed cost ratios against it, less one (a halving and a doubling weigh
    alike, so neither the seeds where an AGV is lost nor the cheap ones decide)."""
    if rule == "geometric" and "vs_reference_geometric" in row:
        return float(row["vs_reference_geometric"])
    return float(row["vs_reference"]) if "vs_reference" in row else float(row["control_cost"])


def _beats_start(row: Mapping[str, float], rule: str) -> bool:
    """The row's paired 95 % interval against the run's start lies below no change (by the rule's measure;
    a row without the rule's columns by the relative one; a row without any: an older run, eligible)."""
    if rule == "geometric" and "vs_start_geometric_high" in row:
        return float(row["vs_start_geometric_high"]) < 0
    return "vs_start" not in row or float(row["vs_start"]) + float(row["vs_start_ci95"]) < 0


def selected_validation(rows: Sequence[Mapping[str, float]], rule: str = "relative") -> Mapping[str, float] | None:
    """The lowest :func:`selection_key` among the starting policy (the first row) and the validations
    significantly better than it (paired 95 % interval against the start below zero, by ``rule``'s
    measure, :data:`SELECTIONS`): the plain minimum of a few validations on 20 seeds often picks a
    policy better only by chance (the winner's curse). Rows without ``vs_start`` (behaviour cloning,
    older runs) are all eligible; None for none."""
    if rule not in SELECTIONS:
        raise ValueError(f"selection rule {rule!r}: valid: {', '.join(SELECTIONS)}")
    eligible = [r for i, r in enumerate(rows) if i == 0 or _beats_start(r, rule)]
    return min(eligible, key=lambda r: selection_key(r, rule), default=None)


def selection_of(run_dir: Path) -> str:
    """The model-selection rule a run recorded (``run.json``'s ``selection``; ``relative`` before the rule
    was a choice, and for a run whose record is not written yet)."""
    path = Path(run_dir) / "run.json"
    return (read_record(path).selection if path.exists() else None) or "relative"


def best_validation(run_dir: Path) -> Mapping[str, float]:
    """A run's selected validation (:func:`selected_validation` over its learning curve by its rule); a
    run without one: an infinite cost, which selection never prefers."""
    rows = read_learning_curve(Path(run_dir))
    return selected_validation(rows, selection_of(run_dir)) or {"control_cost": float("inf")}


def run_key(run_dir: Path) -> float:
    """What choosing among a recipe's runs minimizes: the :func:`selection_key` of each run's selected
    validation, by its rule."""
    return selection_key(best_validation(run_dir), selection_of(run_dir))


def selected_at(run_dir: Path) -> int | None:
    """The steps of a run's selected validation (0: the run ships its start, no validation beat it;
    None: a run without a learning curve)."""
    best = best_validation(run_dir)
    return int(best["timesteps"]) if "timesteps" in best else None


def validation_costs(policy: Policy, env_id: str, config: Any, seeds: Iterable[int]) -> dict[int, float]:
    """Seed -> the control cost of a full episode of the unmodified scenario under a built policy."""
    env = gym.make(env_id, config=config)
    try:
        return {int(s): float(rollout(env, policy, int(s)).metrics["control_cost"]) for s in seeds}
    finally:
        env.close()


def validation_reference(env_id: str, config: Any, episodes: int, seed_base: int = VALIDATION_SEED_BASE
                         ) -> dict[int, float]:
    """``rg-mpc``'s control cost on the validation seeds ``seed_base + i`` of ``env_id``."""
    policy = make_policy(VALIDATION_REFERENCE, config, env_id=env_id)
    return validation_costs(policy, env_id, config, range(seed_base, seed_base + episodes))


def validation_row(costs: Mapping[int, float], reference: Mapping[int, float],
                   start: Mapping[int, float] | None = None) -> dict[str, float]:
    """The learning-curve columns of one validation (:data:`CURVE_FIELDS`; ``vs_start`` given the
    starting policy's costs on the same seeds)."""
    mean, half = mean_ci(list(costs.values()))
    diff, diff_half, _ = paired_difference(costs, reference)
    row = {"control_cost": mean, "control_cost_ci95": half, "vs_reference": diff, "vs_reference_ci95": diff_half,
           "vs_reference_geometric": paired_geometric(costs, reference).change}
    if start is not None:
        row["vs_start"], row["vs_start_ci95"], _ = paired_difference(costs, start)
        g = paired_geometric(costs, start)
        row["vs_start_geometric"], row["vs_start_geometric_low"], row["vs_start_geometric_high"] = (
            g.change, g.low - 1.0, g.high - 1.0)
    return row


def append_learning_curve(run_dir: Path, timesteps: int, row: Mapping[str, float]) -> None:
    """One validation appended to ``learning_curve.csv`` (an older run's file keeps its columns)."""
    path = Path(run_dir) / "learning_curve.csv"
    fields = list(CURVE_FIELDS) if not path.exists() else next(csv.reader(path.open()))
    new = not path.exists()
    with path.open("a", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=fields, extrasaction="ignore")
        if new:
            writer.writeheader()
        writer.writerow({"timesteps": timesteps, **row})


@dataclass(frozen=True)
class RunSummary:
    """A training run's summary (``summary.md``, what ``lawn train`` prints): the run, its wall time
    and the share of it the expert's decisions took, the last and the selected validation (its cost,
    its paired change against the reference and against the run's start, and when it was), and, for
    an imitation run, its first and last loss; for a resumed run, the checkpoint it resumed from."""

    algo: str
    env: str
    seed: int
    timesteps: int | None
    wall_time_s: float | None
    expert_decision_s: float | None
    expert_share: float | None
    interface: Any
    final_validation_cost: float | None
    best_validation_cost: float | None
    best_validation_vs_reference: float | None
    best_validation_vs_start: float | None
    best_validation_vs_start_ci95: float | None
    best_at_timesteps: int | None
    steps_per_s: float | None = None
    bc_loss_first: float | None = None
    bc_loss_last: float | None = None
    resumed_from: int | None = None

    def as_json(self) -> dict[str, Any]:
        """The summary's fields, an imitation run's losses and a resume's checkpoint only where set."""
        data = dataclasses.asdict(self)
        return {k: v for k, v in data.items() if v is not None or k not in ("bc_loss_first", "bc_loss_last",
                                                                                "resumed_from")}


def write_learning_curve(out_dir: Path, spec: Mapping[str, Any]) -> RunSummary:
    """learning_curve.png and summary.md from the periodic validation (``learning_curve.csv``): the
    validation cost, and the paired change against the run's start with its 95 % interval (what model
    selection reads: a change within the interval is not one)."""
    out_dir = Path(out_dir)
    rows = read_learning_curve(out_dir)
    if rows:
        _plot_curve(rows, out_dir / "learning_curve.png", f"{spec['algo']} on {spec['env']}, seed {spec['seed']}")
    best = selected_validation(rows, str(spec.get("selection") or "relative"))
    summary = RunSummary(
        algo=spec["algo"], env=spec["env"], seed=spec["seed"], timesteps=spec.get("num_timesteps"),
        wall_time_s=spec.get("wall_time_s"), expert_decision_s=spec.get("expert_decision_s"),
        expert_share=_share(spec.get("expert_decision_s"), spec.get("wall_time_s")),
        interface=spec.get("interface"),
        final_validation_cost=rows[-1]["control_cost"] if rows else None,
        best_validation_cost=best["control_cost"] if best else None,
        best_validation_vs_reference=best.get("vs_reference") if best else None,
        best_validation_vs_start=best.get("vs_start") if best else None,
        best_validation_vs_start_ci95=best.get("vs_start_ci95") if best else None,
        best_at_timesteps=int(best["timesteps"]) if best else None,
        steps_per_s=_rate(AgentRecord.model_validate(spec).steps_per_s),
    )
    lines = [f"# {spec['algo']} on {spec['env']}", ""]
    lines += [f"- {k}: {v}" for k, v in summary.as_json().items()]
    (out_dir / "summary.md").write_text("\n".join(lines) + "\n")
    return summary


def _rate(steps_per_s: float | None) -> float | None:
    """A run's steps per second to 3 significant digits (None when not recorded)."""
    return float(f"{steps_per_s:.3g}") if steps_per_s else None


def _share(part: float | None, whole: float | None) -> float | None:
    """``part / whole`` rounded to 3 digits (None when either is unknown or ``whole`` is 0)."""
    return round(part / whole, 3) if part is not None and whole else None


def _plot_curve(rows: list[dict[str, float]], path: Path, title: str) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    paired = [r for r in rows if "vs_start" in r and "vs_start_ci95" in r]
    fig = Figure(figsize=(6, 5.5 if paired else 3.5), dpi=110)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(2 if paired else 1, 1, 1)
    t = [r["timesteps"] for r in rows]
    m = np.array([r["control_cost"] for r in rows])
    s = np.array([r["control_cost_ci95"] for r in rows])
    ax.plot(t, m, "-o", ms=3)
    ax.fill_between(t, np.maximum(m - s, m * 0.1), m + s, alpha=0.2)
    ax.set_yscale("log")
    ax.set_ylabel("validation control cost\n(mean, 95 % CI)")
    ax.set_title(title, fontsize=10)
    if paired:  # the same seeds as the start: common random numbers, so a few percent can show
        ax = fig.add_subplot(2, 1, 2, sharex=ax)
        t = [r["timesteps"] for r in paired]
        d = 100 * np.array([r["vs_start"] for r in paired])
        h = 100 * np.nan_to_num(np.array([r["vs_start_ci95"] for r in paired]))
        ax.plot(t, d, "-o", ms=3, color="C1")
        ax.fill_between(t, d - h, d + h, alpha=0.2, color="C1")
        ax.axhline(0.0, color="k", lw=0.8)
        for bound in (-2.0, 2.0):
            ax.axhline(bound, color="0.6", lw=0.8, ls=":")
        ax.set_ylabel("vs the run's start (%)\n(paired, 95 % CI)")
    ax.set_xlabel("environment steps")
    fig.tight_layout()
    fig.savefig(path)
