"""The protocol every training run follows (``lawn train``'s algorithms and behaviour cloning alike):
disjoint seed ranges, one torch thread per run, the versions stamped into ``run.json``, and the
learning curve and summary written from the periodic validation.

Seeds. Training seed s draws its environments from ``TRAIN_SEED_BASE + 1000 s`` on; model
selection uses the validation seeds ``VALIDATION_SEED_BASE + i``; learned agents are tested on the
seeds 0..TEST_EPISODES-1 (``lawn benchmark --protocol learned``, ``lawn zoo build``; ``lawn
benchmark`` alone tests on 0-19 by default). The three ranges never meet.
"""

from __future__ import annotations

import csv
import platform
from pathlib import Path
from typing import Any, Mapping

import numpy as np

import lawn_env
from agents import make_policy

from .results.run import episode_row, read_csv
from .provenance import provenance
from .results.stats import mean_ci, paired_difference

__all__ = ["TRAIN_SEED_BASE", "VALIDATION_SEED_BASE", "TEST_EPISODES", "VALIDATION_REFERENCE", "CURVE_FIELDS",
           "limit_torch_threads", "versions", "read_learning_curve", "selection_key", "selected_validation",
           "validation_reference", "validation_row", "append_learning_curve", "write_learning_curve"]

#: Training environments of seed s start at TRAIN_SEED_BASE + 1000 s (disjoint from test seeds 0-19).
TRAIN_SEED_BASE = 1_000_000
#: Validation (model selection) episodes use VALIDATION_SEED_BASE + i.
VALIDATION_SEED_BASE = 500_000
#: Test episodes of the learned protocol: seeds 0..TEST_EPISODES-1. Per-seed relative differences
#: between agents have a standard deviation of 10-20 %, so a +-3 % interval needs about 100 seeds.
TEST_EPISODES = 100


def limit_torch_threads() -> None:
    """One torch thread: these networks are small, and several threads per run oversubscribe the
    cores when runs go side by side (measured: SAC's update 100x slower with two concurrent runs)."""
    import torch

    torch.set_num_threads(1)


def versions() -> dict:
    """The versions of lawn, SB3, torch, Gymnasium and Python, and the source commit."""
    import gymnasium
    import stable_baselines3
    import torch

    return {"lawn": lawn_env.__version__, "stable_baselines3": stable_baselines3.__version__,
            "torch": torch.__version__, "gymnasium": gymnasium.__version__, "python": platform.python_version(),
            "source": provenance()}


#: The columns of ``learning_curve.csv``: the mean realized control cost on the validation seeds,
#: the mean per-seed relative difference against ``rg-mpc`` on the same seeds (paired) and the one
#: against the run's own starting policy (its first validation: the anchor, or the clone it
#: fine-tunes), each with its 95 % half-width.
CURVE_FIELDS = ("timesteps", "control_cost", "control_cost_ci95", "vs_reference", "vs_reference_ci95",
                "vs_start", "vs_start_ci95")
#: The policy whose costs on the validation seeds pair every validation.
VALIDATION_REFERENCE = "rg-mpc"


def read_learning_curve(run_dir: Path) -> list[dict[str, float]]:
    """The periodic validation of a run (``learning_curve.csv``): rows of :data:`CURVE_FIELDS` as
    floats, in order (empty before the first validation); a column a row leaves empty (behaviour
    cloning has no start to pair with) or a run made before it existed is absent from the row."""
    return [{k: float(v) for k, v in r.items() if v not in ("", None)}
            for r in read_csv(Path(run_dir) / "learning_curve.csv")]


def selection_key(row: Mapping[str, float]) -> float:
    """What model selection minimizes over validations: the paired relative difference against
    ``rg-mpc`` on the validation seeds. Pairing on the same seeds (the same fading draws) keeps a
    seed that every policy finds hard from deciding the choice, which the mean cost lets one
    heavy-tailed episode do. Runs recorded without it fall back to the mean cost."""
    return float(row["vs_reference"]) if "vs_reference" in row else float(row["control_cost"])


def selected_validation(rows: list[Mapping[str, float]]) -> Mapping[str, float] | None:
    """The validation model selection keeps: the lowest :func:`selection_key` among the run's
    starting policy (the first row) and the validations significantly better than it (the upper
    end of the paired 95 % interval against the start below zero). With a handful of validations
    on 20 seeds, the plain minimum picks a policy that only looks better by chance about as often
    as not (the winner's curse), and ships a learner worse than the start it never improved on; the
    gate keeps that start instead. Rows without the ``vs_start`` column (behaviour cloning, which
    has no start to beat, and older runs) are all eligible. ``None`` for no rows."""
    eligible = [r for i, r in enumerate(rows)
                if i == 0 or "vs_start" not in r or float(r["vs_start"]) + float(r["vs_start_ci95"]) < 0]
    return min(eligible, key=selection_key, default=None)


def validation_reference(env_id: str, config: Any, episodes: int, seed_base: int = VALIDATION_SEED_BASE
                         ) -> dict[int, float]:
    """``rg-mpc``'s control cost on the validation seeds ``seed_base + i`` of ``env_id``."""
    policy = make_policy(VALIDATION_REFERENCE, config, env_id=env_id)
    return {seed_base + i: float(episode_row(policy, env_id, config, seed_base + i)["control_cost"])
            for i in range(episodes)}


def validation_row(costs: Mapping[int, float], reference: Mapping[int, float],
                   start: Mapping[int, float] | None = None) -> dict[str, float]:
    """The learning-curve columns of one validation: mean cost and paired difference against the
    reference, and against the run's starting policy when ``start`` (its costs on the same seeds)
    is given, each with its 95 % half-width."""
    mean, half = mean_ci(list(costs.values()))
    diff, diff_half, _ = paired_difference(costs, reference)
    row = {"control_cost": mean, "control_cost_ci95": half, "vs_reference": diff, "vs_reference_ci95": diff_half}
    if start is not None:
        row["vs_start"], row["vs_start_ci95"], _ = paired_difference(costs, start)
    return row


def append_learning_curve(run_dir: Path, timesteps: int, row: Mapping[str, float]) -> None:
    """One validation (:func:`validation_row`) appended to ``learning_curve.csv`` (its header
    first on a new file; a file of an older run keeps its own columns)."""
    path = Path(run_dir) / "learning_curve.csv"
    fields = list(CURVE_FIELDS) if not path.exists() else next(csv.reader(path.open()))
    new = not path.exists()
    with path.open("a", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=fields, extrasaction="ignore")
        if new:
            writer.writeheader()
        writer.writerow({"timesteps": timesteps, **row})


def write_learning_curve(out_dir: Path, spec: Mapping[str, Any]) -> dict:
    """learning_curve.png and summary.md from the periodic validation (``learning_curve.csv``)."""
    out_dir = Path(out_dir)
    rows = read_learning_curve(out_dir)
    if rows:
        _plot_curve(rows, out_dir / "learning_curve.png", f"{spec['algo']} on {spec['env']}, seed {spec['seed']}")
    best = selected_validation(rows)
    summary = {
        "algo": spec["algo"], "env": spec["env"], "seed": spec["seed"], "timesteps": spec.get("num_timesteps"),
        "wall_time_s": spec.get("wall_time_s"), "interface": spec.get("interface"),
        "final_validation_cost": rows[-1]["control_cost"] if rows else None,
        "best_validation_cost": best["control_cost"] if best else None,
        "best_validation_vs_reference": best.get("vs_reference") if best else None,
        "best_at_timesteps": int(best["timesteps"]) if best else None,
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
    m = np.array([r["control_cost"] for r in rows])
    s = np.array([r["control_cost_ci95"] for r in rows])
    ax.plot(t, m, "-o", ms=3)
    ax.fill_between(t, np.maximum(m - s, m * 0.1), m + s, alpha=0.2)
    ax.set_yscale("log")
    ax.set_xlabel("environment steps")
    ax.set_ylabel("validation control cost (mean, 95 % CI)")
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
