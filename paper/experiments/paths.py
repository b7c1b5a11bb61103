"""The drone's and AGVs' paths (the paper's trajectory figure) and the path-length and RMSE claims
about them."""

from __future__ import annotations

from pathlib import Path

from evaluation.sweep import SweepSpec

from .base import EXPERTS, SEEDS, Builder, Experiment, Tables, by_seed, spec
from .claims import Claim, paired_claim
from .plots import plot_traces, trace_rows
from .rows import TraceRow

PATH_CASES = [("K=3", "k3", "rg-mpc"), ("K=3", "k3", "ao-mpc"), ("K=4", "default", "rg-mpc"),
              ("K=4", "default", "ao-mpc"), ("K=4", "default", "epa")]


def _paths_sweeps(quick: bool) -> dict[str, SweepSpec]:
    return {"paths-k3": spec("paths-k3", {}, EXPERTS, quick, preset="k3"),
            "paths-k4": spec("paths-k4", {}, (*EXPERTS, "epa"), quick)}


def _paths_plot(tables: Tables, path: Path) -> None:
    plot_traces(tables.rows("paths", TraceRow), path, PATH_CASES)


def _paths_claims(tables: Tables) -> list[Claim]:
    k3, k4 = tables["paths-k3"], tables["paths-k4"]
    length, rmse = "drone_path_length_m", "rmse_m"
    out = []
    for e in EXPERTS:  # (key, claim, metric, a, b, expected sign of a - b)
        for key, claim, metric, a, b, expect in (
            ("k3-shorter", f"{e}: with K = 3 the drone flies a shorter path than with K = 4", "drone path length",
             by_seed(k3, length, e), by_seed(k4, length, e), "negative"),
            ("epa-longer", f"EPA's drone flies a longer path than {e}'s (K = 4)", "drone path length",
             by_seed(k4, length, "epa"), by_seed(k4, length, e), "positive"),
            ("epa-worse", f"EPA tracks worse than {e} (K = 4)", "RMSE",
             by_seed(k4, rmse, "epa"), by_seed(k4, rmse, e), "positive"),
        ):
            out.append(paired_claim("paths", f"paths.{key}.{e}", claim, f"{metric}, paired per seed", a, b, expect))
    return out


EXPERIMENT = Experiment("paths", "`k3` (rg-mpc, ao-mpc) and default (rg-mpc, ao-mpc, epa): paths of seed 0, path "
                        f"lengths and RMSE over {SEEDS} seeds", sweeps=_paths_sweeps,
                        builders={"paths": Builder(lambda out, quick: trace_rows(PATH_CASES, quick),
                                                   TraceRow.from_row)},
                        plot=_paths_plot, claims=_paths_claims)
