"""Cost against the rate threshold at three power budgets (the paper's rate figure)."""

from __future__ import annotations

import math
from pathlib import Path

from evaluation.sweep import SweepSpec

from .base import EXPERTS, REPORT_SLOT, SEEDS, Experiment, Metric, Tables, by_seed, slot_cost, spec, values
from .claims import Claim, multi_claim
from .plots import curve, label_axes, new_figure, save


def _rate_sweeps(quick: bool) -> dict[str, SweepSpec]:
    grid = {"channel.rate_threshold_bps_hz": [6.0, 10.0] if quick else [6.0, 8.0, 10.0],
            "power_budget_dbw": [0.0, 3.0] if quick else [-3.0, 0.0, 3.0]}
    return {"rate": spec("rate", grid, EXPERTS, quick)}


def _rate_plot(tables: Tables, path: Path) -> None:
    rows = tables["rate"]
    fig = new_figure(ncols=2, width=4.6)
    panels: tuple[tuple[Metric, str], ...] = (("control_cost", "episode control cost"),
                                              (slot_cost, f"stage cost at slot {REPORT_SLOT}"))
    for j, (metric, label) in enumerate(panels):
        ax = fig.add_subplot(1, 2, j + 1)
        for i, p in enumerate(values(rows, "power_budget_dbw")):
            sub = [r for r in rows if float(r.grid["power_budget_dbw"]) == p]
            for policy in EXPERTS:
                curve(ax, sub, "channel.rate_threshold_bps_hz", metric, policy, label=f"{policy}, {p:g} dBW",
                      color=f"C{i}", ls="-" if policy == "rg-mpc" else "--")
        ax.set_yscale("log")
        label_axes(ax, f"{label} vs rate threshold", "rate threshold R_th (bit/s/Hz)", label)
    save(fig, path)


def _rate_claims(tables: Tables) -> list[Claim]:
    rows = tables["rate"]
    rates, budgets = values(rows, "channel.rate_threshold_bps_hz"), values(rows, "power_budget_dbw")
    r0, r1 = rates[0], rates[-1]
    out = []
    for e in EXPERTS:
        for metric, mlabel, tag in (("control_cost", "episode control cost", ""),
                                    (slot_cost, f"stage cost at slot {REPORT_SLOT}", "-slot")):
            at = {(rate, b): by_seed(rows, metric, e, {"channel.rate_threshold_bps_hz": rate, "power_budget_dbw": b})
                  for rate in (r0, r1) for b in budgets}
            out.append(multi_claim("rate", f"rate.rises{tag}.{e}", f"{e}: cost rises with R_th ({r0:g} → {r1:g}), at "
                                   "every P_max", f"{mlabel}, paired per seed",
                                   [(f"{b:g} dBW", at[r1, b], at[r0, b]) for b in budgets], "positive"))
            log_rise = {b: {s: math.log(max(v, 1e-12) / max(at[r0, b][s], 1e-12)) for s, v in at[r1, b].items()}
                        for b in budgets}
            out.append(multi_claim("rate", f"rate.steeper{tag}.{e}", f"{e}: the rise is steeper at lower P_max",
                                   f"log(cost at R_th {r1:g} / at {r0:g}), {mlabel}, paired per seed",
                                   [(f"{budgets[0]:g} vs {budgets[-1]:g} dBW", log_rise[budgets[0]],
                                     log_rise[budgets[-1]])], "positive", relative=False))
    return out


EXPERIMENT = Experiment("rate",
                        f"default, R_th ∈ {{6, 8, 10}}, P_max ∈ {{−3, 0, 3}} dBW, rg-mpc and ao-mpc, {SEEDS} seeds",
                        sweeps=_rate_sweeps, plot=_rate_plot, claims=_rate_claims)
