"""Algorithm 2's convergence at four slots of one episode (the paper's Fig. 3): the objective over
the AO's iterations against a global reference."""

from __future__ import annotations

import itertools
from pathlib import Path

from agents import AOSettings
from lawn_env import ScenarioConfig

from .base import QUICK_SET, Builder, Experiment, Tables
from .claims import Claim
from .gap import CONVERGENCE_SLOTS, convergence, plot_convergence
from .rows import ConvergenceRow


def _convergence_table(out: Path, quick: bool) -> list[ConvergenceRow]:
    cfg = ScenarioConfig().override(QUICK_SET) if quick else ScenarioConfig()
    slots = CONVERGENCE_SLOTS[:2] if quick else CONVERGENCE_SLOTS
    glob = {"psi_points": 41, "drone_spacing_m": 2.5, "power_levels": 40} if quick else {}
    return convergence(cfg, slots, seed=0, driver="ao-mpc", iterations=20, global_settings=glob)


def _convergence_plot(tables: Tables, path: Path) -> None:
    rows = tables.rows("convergence", ConvergenceRow)
    plot_convergence(rows, path.with_suffix(".png"))
    plot_convergence(rows, path.with_suffix(".pdf"))


def _convergence_claims(tables: Tables) -> list[Claim]:
    tol = AOSettings().tolerance
    out = []
    rows = tables.rows("convergence", ConvergenceRow)
    for slot in dict.fromkeys(r.slot for r in rows):
        sel = [r for r in rows if r.slot == slot]
        trace = [r.objective for r in sel]
        ends = [r.objective for r in sel if r.block == "drone"]  # J^ after each iteration
        glob = sel[0].global_objective
        monotone = all(b <= a * (1 + 1e-12) for a, b in itertools.pairwise(trace))
        stop = next((i + 1 for i in range(1, len(ends)) if ends[i - 1] - ends[i] <= tol * abs(ends[i - 1])), len(ends))
        gap_stop, gap_end = ends[stop - 1] / glob - 1, ends[-1] / glob - 1
        out.append(Claim("convergence", f"convergence.monotone.{slot}",
                         f"slot {slot}: the objective is non-increasing over the AO's iterations",
                         "J^ after every block", "non-increasing" if monotone else "increases",
                         "holds" if monotone else "differs"))
        out.append(Claim("convergence", f"convergence.few-iterations.{slot}",
                         f"slot {slot}: the AO converges within a few iterations (≤ 10)",
                         f"Algorithm 2's stopping rule (relative decrease <= {tol:g})",
                         f"stops after {stop} iterations, {gap_stop:.2%} above the global reference",
                         "holds" if stop <= 10 else "differs"))
        out.append(Claim("convergence", f"convergence.optimum.{slot}",
                         f"slot {slot} (project's check, not the paper's): within 0.1 % of a global optimum after 20 "
                         "iterations", "J^ vs global-mpc",
                         f"{gap_end:.2%} above (rg-mpc {sel[0].rg_mpc_objective / glob - 1:.3%})",
                         "holds" if gap_end < 1e-3 else "differs"))
    return out


EXPERIMENT = Experiment("convergence", "default (K = 4, R_th = 10, 0 dBW, l = 1024), episode seed 0 driven by "
                        "`ao-mpc`; slots 11, 19, 28, 41; 20 AO iterations without early stop; `global-mpc` as the "
                        "reference",
                        builders={"convergence": Builder(_convergence_table, ConvergenceRow.from_row)},
                        plot=_convergence_plot,
                        claims=_convergence_claims)
