"""The disturbance mode (MODEL.md §7): the experts against EPA with and without disturbances, and the
control-period ablation."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from evaluation.episode import parse_bool
from evaluation.stats import mean_ci
from evaluation.sweep import SpecValue, SweepRow, SweepSpec

from .base import EXPERTS, SEEDS, Builder, Experiment, Tables, by_seed, spec, values
from .claims import Claim, multi_claim, paired_claim
from .plots import STYLE, curve, label_axes, new_figure, plot_traces, save, trace_rows
from .rows import TraceRow

DIST_CASES = [("nominal", "default", "rg-mpc"), ("nominal", "default", "epa"), ("disturbed", "disturbed", "rg-mpc"),
              ("disturbed", "disturbed", "epa")]


def _disturbance_sweeps(quick: bool) -> dict[str, SweepSpec]:
    period: dict[str, list[SpecValue]] = {"disturbance.control_period_slots": [2] if quick else [1, 2, 3],
              "disturbance.period_aware_planning": [True, False]}
    return {"disturbance-costs": spec("disturbance-costs", {"preset": ["default", "disturbed"]}, (*EXPERTS, "epa"),
                                      quick),
            "disturbance-period": spec("disturbance-period", period, ("rg-mpc", "epa"), quick, preset="disturbed")}


def _disturbance_plot(tables: Tables, path: Path) -> None:
    fig = new_figure(ncols=3, width=4.0)
    rows = tables["disturbance-costs"]
    variants = list(dict.fromkeys(r.grid["preset"] for r in rows))
    policies = list(dict.fromkeys(r.policy for r in rows))
    width = 0.8 / len(policies)
    for j, metric in enumerate(("control_cost", "rmse_m")):
        ax = fig.add_subplot(1, 3, j + 1)
        for i, policy in enumerate(policies):
            st = [mean_ci([r.metric(metric) for r in rows if r.policy == policy and r.grid["preset"] == v])
                  for v in variants]
            ax.bar(np.arange(len(variants)) + i * width, [m for m, _ in st], width,
                   yerr=[h if math.isfinite(h) else 0.0 for _, h in st], color=STYLE.get(policy, ("k",))[0], capsize=3,
                   label=policy)
        ax.set_xticks(np.arange(len(variants)) + 0.4 - width / 2, variants)
        ax.set_title(metric.replace("_", " "), fontsize=9)
        if j == 0:
            ax.legend(fontsize=8)
    ax = fig.add_subplot(1, 3, 3)
    per = tables["disturbance-period"]
    for aware, ls in ((True, "-"), (False, ":")):
        sub = [r for r in per if parse_bool(r.grid["disturbance.period_aware_planning"]) == aware]
        for policy in dict.fromkeys(r.policy for r in sub):
            curve(ax, sub, "disturbance.control_period_slots", "control_cost", policy,
                  label=f"{policy}, {'plans with' if aware else 'ignores'} the period", ls=ls)
    ax.set_yscale("log")
    label_axes(ax, "disturbed: control period (ablation)", "commands every P slots", "control cost")
    save(fig, path)
    plot_traces(tables.rows("disturbance", TraceRow), path.with_name(path.name + "-paths"), DIST_CASES)


def _period_costs(rows: Sequence[SweepRow], policy: str, period: int, aware: bool) -> dict[int, float]:
    """{seed: control cost} of ``policy`` at control period ``period``, planning with it or not."""
    return {r.seed: r.result.control_cost for r in rows
            if r.policy == policy and int(float(r.grid["disturbance.control_period_slots"])) == period
            and parse_bool(r.grid["disturbance.period_aware_planning"]) == aware}


def _disturbance_claims(tables: Tables) -> list[Claim]:
    rows = tables["disturbance-costs"]
    out = []
    for variant in ("default", "disturbed"):
        for e in EXPERTS:
            trend = " (the same trend under disturbances)" if variant != "default" else ""
            out.append(paired_claim("disturbance", f"disturbance.beats-epa.{variant}.{e}",
                                    f"{variant}: {e} beats EPA{trend}", "episode control cost, paired per seed",
                                    by_seed(rows, "control_cost", e, {"preset": variant}),
                                    by_seed(rows, "control_cost", "epa", {"preset": variant}), "negative"))
    per = tables["disturbance-period"]
    periods = [int(p) for p in values(per, "disturbance.control_period_slots") if p > 1]
    for policy in dict.fromkeys(r.policy for r in per):
        parts = [(f"P={p}", _period_costs(per, policy, p, True), _period_costs(per, policy, p, False))
                 for p in periods]
        if parts:
            out.append(multi_claim("disturbance", f"disturbance.period-aware.{policy}",
                                   f"{policy} (project's check): planning with the control period beats ignoring it",
                                   "episode control cost, paired per seed", parts, "negative"))
    return out


EXPERIMENT = Experiment("disturbance", "default vs `disturbed` (wind, gusts, actuator lag, noise, commands every 2 "
                        f"slots), rg-mpc, ao-mpc, epa, {SEEDS} seeds; control period 1–3 with and without period-aware "
                        f"planning, {SEEDS} seeds", sweeps=_disturbance_sweeps,
                        builders={"disturbance": Builder(lambda out, quick: trace_rows(DIST_CASES, quick),
                                                         TraceRow.from_row)},
                        plot=_disturbance_plot, claims=_disturbance_claims)
