"""Robustness to channel-estimation error (the paper's CE figure): tracking RMSE against the CE error
variance, at -30 dBW and at the 0 dBW floor."""

from __future__ import annotations

from pathlib import Path

from evaluation.sweep import SweepSpec

from .base import BASELINES, EXPERTS, REPORT_SLOT, SEEDS, Experiment, Metric, Tables, by_seed, slot_cost, spec, values
from .claims import Claim, multi_claim
from .plots import curve, label_axes, new_figure, save

CE_BUDGET_DBW = -30.0


def _ce_sweeps(quick: bool) -> dict[str, SweepSpec]:
    policies, rhos = EXPERTS + BASELINES, [0.0, 0.1] if quick else [0.0, 0.01, 0.05, 0.1]
    return {"ce": spec("ce", {"channel.ce_error_var": rhos}, policies, quick, preset="paper-nominal",
                       set_={"power_budget_dbw": CE_BUDGET_DBW}),
            "ce-floor": spec("ce-floor", {"channel.ce_error_var": [0.0, 0.1]}, policies, quick, preset="paper-nominal")}


def _ce_plot(tables: Tables, path: Path) -> None:
    fig = new_figure(ncols=2, width=4.6)
    for j, (name, budget) in enumerate((("ce", CE_BUDGET_DBW), ("ce-floor", 0.0))):
        ax = fig.add_subplot(1, 2, j + 1)
        rows = tables[name]
        for policy in dict.fromkeys(r.policy for r in rows):
            curve(ax, rows, "channel.ce_error_var", "rmse_m", policy)
        label_axes(ax, f"R_th = 1, P_max = {budget:g} dBW" + (" (the floor: power cannot matter)" if j else ""),
                   "normalized CE error variance ρ", "tracking RMSE (m)")
    save(fig, path)


def _ce_claims(tables: Tables) -> list[Claim]:
    rows = tables["ce"]
    rhos = values(rows, "channel.ce_error_var")
    lo, hi = rhos[0], rhos[-1]
    policies = list(dict.fromkeys(r.policy for r in rows))

    def rmse(policy: str, rho: float, metric: Metric = "rmse_m") -> dict[int, float]:
        return by_seed(rows, metric, policy, {"channel.ce_error_var": rho})

    growth = {p: {s: v - rmse(p, lo)[s] for s, v in rmse(p, hi).items()} for p in policies}
    out = [multi_claim("ce", "ce.rmse-grows", f"RMSE grows with the CE error variance, every policy (ρ = {lo:g} → "
                       f"{hi:g}, {CE_BUDGET_DBW:g} dBW)", "RMSE, paired per seed",
                       [(p, rmse(p, hi), rmse(p, lo)) for p in policies], "positive")]
    for e in EXPERTS:
        out.append(multi_claim("ce", f"ce.expert-lowest.{e}", f"{e} has the lowest RMSE (ρ = {hi:g})",
                               "RMSE, paired per seed", [(b, rmse(e, hi), rmse(b, hi)) for b in BASELINES], "negative"))
        out.append(multi_claim("ce", f"ce.slowest-growth.{e}", f"{e} has the slowest RMSE growth (ρ = {lo:g} → {hi:g})",
                               "RMSE growth (m), paired per seed", [(b, growth[e], growth[b]) for b in BASELINES],
                               "negative", relative=False))
        out.append(multi_claim("ce", f"ce.expert-lowest-slot.{e}", f"{e} has the lowest cost at slot {REPORT_SLOT} "
                               f"(ρ = {hi:g})", f"stage cost at slot {REPORT_SLOT}, paired per seed",
                               [(b, rmse(e, hi, slot_cost), rmse(b, hi, slot_cost)) for b in BASELINES], "negative"))
    floor = {"channel.ce_error_var": 0.1}
    out.append(multi_claim("ce", "ce.floor", "at 0 dBW (project's check): power and position cannot lower the outage "
                           "floor, so the experts tie with EPA (within ±1 %)",
                           "RMSE vs EPA at ρ = 0.1, paired per seed",
                           [(e, by_seed(tables["ce-floor"], "rmse_m", e, floor),
                             by_seed(tables["ce-floor"], "rmse_m", "epa", floor)) for e in EXPERTS], "tie"))
    return out


EXPERIMENT = Experiment("ce", f"`paper-nominal` (R_th = 1) at P_max = {CE_BUDGET_DBW:g} dBW, "
                        f"ρ ∈ {{0, 0.01, 0.05, 0.1}}, rg-mpc, ao-mpc, epa, pid, lqr, {SEEDS} seeds; "
                        f"the 0 dBW floor panel at ρ ∈ {{0, 0.1}}, {SEEDS} seeds",
                        sweeps=_ce_sweeps, plot=_ce_plot, claims=_ce_claims)
