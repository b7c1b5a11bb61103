"""The CDF of tracking RMSE over seeds under power budgets (the paper's CDF figure)."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from evaluation.cells import fmt_paired
from evaluation.stats import paired_difference, verdict
from evaluation.sweep import SweepSpec

from .base import EXPERTS, SEEDS, Experiment, Tables, by_seed, spec, values
from .claims import Claim, paired_claim
from .plots import label_axes, new_figure, save


def _cdf_sweeps(quick: bool) -> dict[str, SweepSpec]:
    budgets = [-30.0, -15.0] if quick else [-30.0, -25.0, -20.0, -15.0]
    return {"cdf": spec("cdf", {"power_budget_dbw": budgets}, EXPERTS, quick, preset="paper-nominal")}


def _cdf_plot(tables: Tables, path: Path) -> None:
    rows = tables["cdf"]
    fig = new_figure()
    ax = fig.add_subplot(111)
    for i, p in enumerate(values(rows, "power_budget_dbw")):
        for policy in EXPERTS:
            vals = np.sort([r.metric("rmse_m") for r in rows
                            if r.policy == policy and float(r.grid["power_budget_dbw"]) == p])
            if vals.size:
                ax.step(vals, np.arange(1, vals.size + 1) / vals.size, where="post", color=f"C{i}",
                        ls="-" if policy == "rg-mpc" else "--", label=f"{policy}, {p:g} dBW")
    label_axes(ax, "CDF of RMSE under power budgets (R_th = 1)", "tracking RMSE (m)", "CDF over seeds")
    save(fig, path)


def _cdf_claims(tables: Tables) -> list[Claim]:
    rows = tables["cdf"]
    budgets = values(rows, "power_budget_dbw")
    out = []
    for e in EXPERTS:
        parts = [(f"{b:g} vs {a:g} dBW", by_seed(rows, "rmse_m", e, {"power_budget_dbw": b}),
                  by_seed(rows, "rmse_m", e, {"power_budget_dbw": a})) for a, b in itertools.pairwise(budgets)]
        overall = paired_claim("cdf", "", "", "", parts[-1][1], parts[0][2], "negative")
        steps = [verdict(*paired_difference(a, b)[:2], "negative") for _, a, b in parts]
        cells = "; ".join(f"{label}: {fmt_paired(*paired_difference(a, b)[:2])}" for label, a, b in parts)
        v = overall.verdict if overall.verdict != "holds" else ("holds" if "differs" not in steps else "differs")
        out.append(Claim("cdf", f"cdf.power.{e}", f"{e}: a higher power budget gives a lower RMSE",
                         "RMSE, paired per seed", f"{budgets[-1]:g} vs {budgets[0]:g} dBW: {overall.value} ({cells})",
                         v, overall.seeds))
    return out


EXPERIMENT = Experiment("cdf", f"`paper-nominal`, P_max ∈ {{−30, −25, −20, −15}} dBW, rg-mpc and ao-mpc, {SEEDS} seeds",
                        sweeps=_cdf_sweeps, plot=_cdf_plot, claims=_cdf_claims)
