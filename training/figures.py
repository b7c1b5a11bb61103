"""``lawn figures``: the paper's experiments (MODEL.md §7) as records, from tidy tables.

Each :class:`Experiment` holds its tables (sweep specs, full and ``--quick``, or a builder for the
tables that are not episode sweeps), a plot that reads only those tables, and the paper's claims
about it, each checked with paired per-seed differences and 95 % t-intervals
(:func:`training.tables.paired_difference`). ``lawn figures [NAME...] --out DIR`` runs the missing
rows into ``DIR/data/<table>.csv`` (resuming partial tables), writes ``DIR/<name>.png`` and
``.pdf``, and the claim table ``DIR/claims.md``; with ``--docs DOCS`` it also writes
``DOCS/REPRODUCTION.md`` and copies the figures to ``DOCS/figures/reproduction/``.

Where the paper evaluates one slot (its rate, blocklength and CE figures use "a selected time slot",
n = 11), the claims are checked on the episode's realized control cost *and* on the realized stage
cost of slot 11 (the transition driven by the decision at slot 11, counted from 0 as everywhere in
this package), each labelled.
"""

from __future__ import annotations

import json
import math
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from .tables import mean_ci, paired_difference, parse_bool, verdict

__all__ = ["EXPERIMENTS", "Experiment", "Claim", "make_figures", "check_claims", "format_claims",
           "write_reproduction", "REPORT_SLOT"]

EXPERTS = ("rg-mpc", "ao-mpc")
BASELINES = ("epa", "pid", "lqr")
#: The paper's "selected time slot" of its rate, blocklength and CE figures.
REPORT_SLOT = 11
STYLE = {"rg-mpc": ("C3", "o", "-"), "ao-mpc": ("C0", "s", "-"), "epa": ("C1", "^", "--"), "sf": ("C2", "v", "--"),
         "pid": ("C4", "D", ":"), "lqr": ("C5", "x", ":")}
QUICK_SET = {"num_slots": 30}


# ---------------------------------------------------------------------- records
@dataclass(frozen=True)
class Claim:
    """One claim checked on the tables: the paper's statement, the metric it was checked on, the
    project's number (mean and 95 % interval of the paired per-seed difference) and the verdict
    ("holds", "not significant", "differs"; "project" rows are the project's own checks)."""

    figure: str
    key: str  # stable id, e.g. "ce.expert-lowest.rg-mpc"
    claim: str
    metric: str
    value: str
    verdict: str
    seeds: int = 0


@dataclass(frozen=True)
class Experiment:
    """One figure of MODEL.md §7: its tables, its plot and its claims."""

    name: str
    setting: str  # one line for the settings table of REPRODUCTION.md
    sweeps: Callable[[bool], dict[str, dict]] = lambda quick: {}  # table name -> sweep spec
    builders: dict[str, Callable[[Path, bool], list[dict]]] = field(default_factory=dict)  # non-sweep tables
    plot: Callable[[dict[str, list[dict]], Path], None] | None = None
    claims: Callable[[dict[str, list[dict]]], list[Claim]] = lambda tables: []

    def table_names(self, quick: bool = False) -> list[str]:
        return list(self.sweeps(quick)) + list(self.builders)


def _spec(name, grid, policies, seeds, preset="default", set_=None):
    return {"name": name, "env": "lawn/Joint-v0", "preset": preset, "set": dict(set_ or {}), "grid": grid,
            "policies": list(policies), "seeds": seeds}


def _pick(quick: bool, full, short):
    return short if quick else full


# ---------------------------------------------------------------------- reading tables
def _f(row, key) -> float:
    return float(row[key])


def slot_cost(row: Mapping[str, Any], slot: int = REPORT_SLOT) -> float:
    """The realized stage cost of ``slot`` in an episode row (``stage_costs``, a JSON list)."""
    costs = json.loads(row["stage_costs"]) if isinstance(row["stage_costs"], str) else row["stage_costs"]
    return float(costs[min(slot, len(costs) - 1)])


def _by_seed(rows, metric: str | Callable, **where) -> dict[int, float]:
    """{seed: value} of the rows matching ``where`` (values compared as strings)."""
    get = metric if callable(metric) else (lambda r: _f(r, metric))
    out = {}
    for r in rows:
        if all(str(r[k]) == str(v) for k, v in where.items()):
            out[int(r["seed"])] = get(r)
    return out


def _values(rows, key) -> list:
    return sorted({float(r[key]) for r in rows})


def _pct(mean, half) -> str:
    return f"{mean * 100:+.1f} % ± {half * 100:.1f} %"


def _claim(figure, key, claim, metric, a, b, expect, relative=True, fmt=None) -> Claim:
    mean, half, n = paired_difference(a, b, relative=relative)
    value = (fmt or _pct)(mean, half)
    return Claim(figure, key, claim, metric, value, verdict(mean, half, expect), n)


def _combine(verdicts: Sequence[str]) -> str:
    if any(v == "differs" for v in verdicts):
        return "differs"
    if all(v == "holds" for v in verdicts):
        return "holds"
    return "not significant"


def _multi(figure, key, claim, metric, parts: list[tuple[str, dict, dict]], expect, relative=True) -> Claim:
    """One claim over several paired comparisons (label, a, b): every interval must hold."""
    cells, verdicts, n = [], [], 0
    for label, a, b in parts:
        mean, half, n = paired_difference(a, b, relative=relative)
        cells.append(f"{label}: {_pct(mean, half) if relative else f'{mean:+.3g} ± {half:.2g}'}")
        verdicts.append(verdict(mean, half, expect))
    return Claim(figure, key, claim, metric, "; ".join(cells), _combine(verdicts), n)


# ---------------------------------------------------------------------- plotting helpers
def _figure(ncols=1, width=5.0, height=3.6):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width * ncols, height), dpi=110)
    FigureCanvasAgg(fig)
    return fig


def _save(fig, path: Path) -> None:
    fig.tight_layout()
    fig.savefig(path.with_suffix(".png"))
    fig.savefig(path.with_suffix(".pdf"))


def _curve(ax, rows, x_key, y_key, policy, label=None, **kw):
    sel = [r for r in rows if r["policy"] == policy]
    xs = _values(sel, x_key)
    if not xs:
        return
    get = y_key if callable(y_key) else (lambda r: _f(r, y_key))
    stats_ = [mean_ci([get(r) for r in sel if float(r[x_key]) == x]) for x in xs]
    color, marker, ls = STYLE.get(policy, ("k", ".", "-"))
    ax.errorbar(xs, [m for m, _ in stats_], yerr=[0.0 if not math.isfinite(h) else h for _, h in stats_],
                color=kw.pop("color", color), marker=marker, ls=kw.pop("ls", ls), ms=4, capsize=3,
                label=label or policy, **kw)


def _label(ax, title, xlabel, ylabel, legend_size=7):
    ax.set_title(title, fontsize=9)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.legend(fontsize=legend_size)


# ---------------------------------------------------------------------- convergence
def _convergence_table(out: Path, quick: bool) -> list[dict]:
    from lawn_env import ScenarioConfig

    from .gap import CONVERGENCE_SLOTS, convergence

    cfg = ScenarioConfig(num_slots=30) if quick else ScenarioConfig()
    slots = CONVERGENCE_SLOTS[:2] if quick else CONVERGENCE_SLOTS
    glob = {"psi_points": 41, "drone_spacing_m": 2.5, "power_levels": 40} if quick else {}
    return convergence(cfg, slots, seed=0, driver="ao-mpc", iterations=20, global_settings=glob)


def _convergence_plot(tables, path: Path) -> None:
    from .gap import plot_convergence

    rows = [{**r, "slot": int(r["slot"]), "iteration": int(r["iteration"]),
             **{k: float(r[k]) for k in ("objective", "global_objective", "rg_mpc_objective")}}
            for r in tables["convergence"]]
    plot_convergence(rows, path.with_suffix(".png"))
    plot_convergence(rows, path.with_suffix(".pdf"))


def _convergence_claims(tables) -> list[Claim]:
    from agents import AOSettings

    tol = AOSettings().tolerance
    out = []
    rows = tables["convergence"]
    for slot in dict.fromkeys(r["slot"] for r in rows):
        sel = [r for r in rows if r["slot"] == slot]
        trace = [float(r["objective"]) for r in sel]
        ends = [float(r["objective"]) for r in sel if r["block"] == "drone"]  # J^ after each iteration
        glob = float(sel[0]["global_objective"])
        monotone = all(b <= a * (1 + 1e-12) for a, b in zip(trace, trace[1:]))
        stop = next((i + 1 for i in range(1, len(ends)) if ends[i - 1] - ends[i] <= tol * abs(ends[i - 1])), len(ends))
        gap_stop, gap_end = ends[stop - 1] / glob - 1, ends[-1] / glob - 1
        out.append(Claim("convergence", f"convergence.monotone.{slot}", f"slot {slot}: the objective is non-increasing "
                         "over the AO's iterations", "J^ after every block", "non-increasing" if monotone else
                         "increases", "holds" if monotone else "differs"))
        out.append(Claim("convergence", f"convergence.few-iterations.{slot}",
                         f"slot {slot}: the AO converges within a few iterations (≤ 10)",
                         f"Algorithm 2's stopping rule (relative decrease <= {tol:g})",
                         f"stops after {stop} iterations, {gap_stop:.2%} above the global reference",
                         "holds" if stop <= 10 else "differs"))
        out.append(Claim("convergence", f"convergence.optimum.{slot}",
                         f"slot {slot} (project's check, not the paper's): within 0.1 % of a global optimum "
                         "after 20 iterations", "J^ vs global-mpc", f"{gap_end:.2%} above (rg-mpc "
                         f"{float(sel[0]['rg_mpc_objective']) / glob - 1:.3%})", "holds" if gap_end < 1e-3 else "differs"))
    return out


# ---------------------------------------------------------------------- CE robustness
CE_BUDGET_DBW = -30.0


def _ce_sweeps(quick):
    q = QUICK_SET if quick else {}
    policies = EXPERTS + BASELINES
    return {
        "ce": _spec("ce", {"channel.ce_error_var": _pick(quick, [0.0, 0.01, 0.05, 0.1], [0.0, 0.1])}, policies,
                    _pick(quick, 20, 2), preset="paper-nominal", set_={**q, "power_budget_dbw": CE_BUDGET_DBW}),
        "ce-floor": _spec("ce-floor", {"channel.ce_error_var": [0.0, 0.1]}, policies, _pick(quick, 10, 2),
                          preset="paper-nominal", set_=q),
    }


def _ce_plot(tables, path: Path) -> None:
    fig = _figure(ncols=2, width=4.6)
    for j, (name, budget) in enumerate((("ce", CE_BUDGET_DBW), ("ce-floor", 0.0))):
        ax = fig.add_subplot(1, 2, j + 1)
        rows = tables[name]
        for policy in dict.fromkeys(r["policy"] for r in rows):
            _curve(ax, rows, "channel.ce_error_var", "rmse_m", policy)
        _label(ax, f"R_th = 1, P_max = {budget:g} dBW" + (" (the floor: power cannot matter)" if j else ""),
               "normalized CE error variance ρ", "tracking RMSE (m)")
    _save(fig, path)


def _ce_claims(tables) -> list[Claim]:
    rows = tables["ce"]
    rhos = _values(rows, "channel.ce_error_var")
    lo, hi = rhos[0], rhos[-1]
    policies = list(dict.fromkeys(r["policy"] for r in rows))
    out = [_multi("ce", "ce.rmse-grows", f"RMSE grows with the CE error variance, every policy (ρ = {lo:g} → {hi:g}, "
                  f"{CE_BUDGET_DBW:g} dBW)", "RMSE, paired per seed",
                  [(p, _by_seed(rows, "rmse_m", policy=p, **{"channel.ce_error_var": hi}),
                    _by_seed(rows, "rmse_m", policy=p, **{"channel.ce_error_var": lo})) for p in policies], "positive")]
    for e in EXPERTS:
        at = {"channel.ce_error_var": hi}
        out.append(_multi("ce", f"ce.expert-lowest.{e}", f"{e} has the lowest RMSE (ρ = {hi:g})", "RMSE, paired per seed",
                          [(b, _by_seed(rows, "rmse_m", policy=e, **at), _by_seed(rows, "rmse_m", policy=b, **at))
                           for b in BASELINES], "negative"))
        growth = {p: {s: v - _by_seed(rows, "rmse_m", policy=p, **{"channel.ce_error_var": lo})[s]
                      for s, v in _by_seed(rows, "rmse_m", policy=p, **at).items()} for p in policies}
        out.append(_multi("ce", f"ce.slowest-growth.{e}", f"{e} has the slowest RMSE growth (ρ = {lo:g} → {hi:g})",
                          "RMSE growth (m), paired per seed", [(b, growth[e], growth[b]) for b in BASELINES],
                          "negative", relative=False))
        out.append(_multi("ce", f"ce.expert-lowest-slot.{e}", f"{e} has the lowest cost at slot {REPORT_SLOT} (ρ = {hi:g})",
                          f"stage cost at slot {REPORT_SLOT}, paired per seed",
                          [(b, _by_seed(rows, slot_cost, policy=e, **at), _by_seed(rows, slot_cost, policy=b, **at))
                           for b in BASELINES], "negative"))
    floor = tables["ce-floor"]
    out.append(_multi("ce", "ce.floor", "at 0 dBW (project's check): power and position cannot lower the outage floor, "
                      "so the experts tie with EPA (within ±1 %)", "RMSE vs EPA at ρ = 0.1, paired per seed",
                      [(e, _by_seed(floor, "rmse_m", policy=e, **{"channel.ce_error_var": 0.1}),
                        _by_seed(floor, "rmse_m", policy="epa", **{"channel.ce_error_var": 0.1})) for e in EXPERTS],
                      "tie"))
    return out


# ---------------------------------------------------------------------- CDF under power budgets
def _cdf_sweeps(quick):
    return {"cdf": _spec("cdf", {"power_budget_dbw": _pick(quick, [-30.0, -25.0, -20.0, -15.0], [-30.0, -15.0])},
                         EXPERTS, _pick(quick, 20, 2), preset="paper-nominal", set_=QUICK_SET if quick else {})}


def _cdf_plot(tables, path: Path) -> None:
    rows = tables["cdf"]
    fig = _figure()
    ax = fig.add_subplot(111)
    for i, p in enumerate(_values(rows, "power_budget_dbw")):
        for policy in EXPERTS:
            vals = np.sort([_f(r, "rmse_m") for r in rows if r["policy"] == policy and float(r["power_budget_dbw"]) == p])
            if vals.size:
                ax.step(vals, np.arange(1, vals.size + 1) / vals.size, where="post", color=f"C{i}",
                        ls="-" if policy == "rg-mpc" else "--", label=f"{policy}, {p:g} dBW")
    _label(ax, "CDF of RMSE under power budgets (R_th = 1)", "tracking RMSE (m)", "CDF over seeds")
    _save(fig, path)


def _cdf_claims(tables) -> list[Claim]:
    rows = tables["cdf"]
    budgets = _values(rows, "power_budget_dbw")
    out = []
    for e in EXPERTS:
        parts = [(f"{b:g} vs {a:g} dBW", _by_seed(rows, "rmse_m", policy=e, power_budget_dbw=b),
                  _by_seed(rows, "rmse_m", policy=e, power_budget_dbw=a)) for a, b in zip(budgets, budgets[1:])]
        overall = _claim("cdf", "", "", "", parts[-1][1], parts[0][2], "negative")
        steps = [verdict(*paired_difference(a, b)[:2], "negative") for _, a, b in parts]
        cells = "; ".join(f"{label}: {_pct(*paired_difference(a, b)[:2])}" for label, a, b in parts)
        v = overall.verdict if overall.verdict != "holds" else ("holds" if "differs" not in steps else "differs")
        out.append(Claim("cdf", f"cdf.power.{e}", f"{e}: a higher power budget gives a lower RMSE",
                         "RMSE, paired per seed", f"{budgets[-1]:g} vs {budgets[0]:g} dBW: {overall.value} ({cells})",
                         v, overall.seeds))
    return out


# ---------------------------------------------------------------------- rate threshold
def _rate_sweeps(quick):
    return {"rate": _spec("rate", {"channel.rate_threshold_bps_hz": _pick(quick, [6.0, 8.0, 10.0], [6.0, 10.0]),
                                   "power_budget_dbw": _pick(quick, [-3.0, 0.0, 3.0], [0.0, 3.0])},
                          EXPERTS, _pick(quick, 20, 2), set_=QUICK_SET if quick else {})}


def _rate_plot(tables, path: Path) -> None:
    rows = tables["rate"]
    fig = _figure(ncols=2, width=4.6)
    for j, (metric, label) in enumerate((("control_cost", "episode control cost"),
                                         (slot_cost, f"stage cost at slot {REPORT_SLOT}"))):
        ax = fig.add_subplot(1, 2, j + 1)
        for i, p in enumerate(_values(rows, "power_budget_dbw")):
            sub = [r for r in rows if float(r["power_budget_dbw"]) == p]
            for policy in EXPERTS:
                _curve(ax, sub, "channel.rate_threshold_bps_hz", metric, policy, label=f"{policy}, {p:g} dBW",
                       color=f"C{i}", ls="-" if policy == "rg-mpc" else "--")
        ax.set_yscale("log")
        _label(ax, f"{label} vs rate threshold", "rate threshold R_th (bit/s/Hz)", label)
    _save(fig, path)


def _rate_claims(tables) -> list[Claim]:
    rows = tables["rate"]
    rates, budgets = _values(rows, "channel.rate_threshold_bps_hz"), _values(rows, "power_budget_dbw")
    r0, r1 = rates[0], rates[-1]
    out = []
    for e in EXPERTS:
        for metric, mlabel, tag in (("control_cost", "episode control cost", ""),
                                    (slot_cost, f"stage cost at slot {REPORT_SLOT}", "-slot")):
            def at(rate, budget, metric=metric):
                return _by_seed(rows, metric, policy=e, **{"channel.rate_threshold_bps_hz": rate,
                                                           "power_budget_dbw": budget})

            out.append(_multi("rate", f"rate.rises{tag}.{e}", f"{e}: cost rises with R_th ({r0:g} → {r1:g}), "
                              "at every P_max", f"{mlabel}, paired per seed",
                              [(f"{b:g} dBW", at(r1, b), at(r0, b)) for b in budgets], "positive"))
            log_rise = {b: {s: math.log(max(v, 1e-12) / max(at(r0, b)[s], 1e-12)) for s, v in at(r1, b).items()}
                        for b in budgets}
            out.append(_multi("rate", f"rate.steeper{tag}.{e}", f"{e}: the rise is steeper at lower P_max",
                              f"log(cost at R_th {r1:g} / at {r0:g}), {mlabel}, paired per seed",
                              [(f"{budgets[0]:g} vs {budgets[-1]:g} dBW", log_rise[budgets[0]], log_rise[budgets[-1]])],
                              "positive", relative=False))
    return out


# ---------------------------------------------------------------------- blocklength
BLOCK_POLICIES = EXPERTS + ("epa", "sf")


def _blocklength_sweeps(quick):
    q = QUICK_SET if quick else {}
    seeds = _pick(quick, 20, 2)
    return {
        "blocklength": _spec("blocklength", {"channel.blocklength": _pick(quick, [128, 256, 1024, 4096], [256, 2048])},
                             BLOCK_POLICIES, seeds, set_=q),
        "blocklength-ibl": _spec("blocklength-ibl", {"channel.infinite_blocklength": [True]}, BLOCK_POLICIES, seeds,
                                 set_=q),
    }


def _blocklength_plot(tables, path: Path) -> None:
    rows, ibl = tables["blocklength"], tables["blocklength-ibl"]
    fig = _figure()
    ax = fig.add_subplot(111)
    for policy in dict.fromkeys(r["policy"] for r in rows):
        _curve(ax, rows, "channel.blocklength", "control_cost", policy)
        limit = [_f(r, "control_cost") for r in ibl if r["policy"] == policy]
        if limit:
            ax.axhline(np.mean(limit), color=STYLE.get(policy, ("k",))[0], ls=":", lw=1)
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    _label(ax, "control cost vs blocklength (R_th = 10, P_max = 0 dBW)",
           "blocklength l (channel uses); dotted: IBL limit of each policy", "realized control cost")
    _save(fig, path)


def _blocklength_claims(tables) -> list[Claim]:
    rows, ibl = tables["blocklength"], tables["blocklength-ibl"]
    lengths = [int(x) for x in _values(rows, "channel.blocklength")]
    l0, l1 = lengths[0], lengths[-1]
    out = []
    for p in dict.fromkeys(r["policy"] for r in rows):
        at = lambda length, metric="control_cost": _by_seed(rows, metric, policy=p, **{"channel.blocklength": length})
        out.append(_claim("blocklength", f"blocklength.falls.{p}", f"{p}: cost falls as the blocklength grows "
                          f"(l = {l0} → {l1})", "episode control cost, paired per seed", at(l1), at(l0), "negative"))
        limit = _by_seed(ibl, "control_cost", policy=p)
        m1, h1, n = paired_difference(at(l1), limit)
        m0, _, _ = paired_difference(at(l0), limit)
        ok = (m1 - h1 <= 0 <= m1 + h1) or (0 < m1 < m0)
        out.append(Claim("blocklength", f"blocklength.ibl.{p}", f"{p}: cost converges toward the IBL limit",
                         "episode control cost vs IBL, paired per seed",
                         f"l = {l1}: {_pct(m1, h1)} above IBL (l = {l0}: {m0 * 100:+.1f} %)",
                         "holds" if ok else "differs", n))
    for base in ("epa", "sf"):
        for e in EXPERTS:
            out.append(_multi("blocklength", f"blocklength.beats-{base}.{e}", f"{e} beats {base.upper()} at every "
                              "blocklength", "episode control cost, paired per seed",
                              [(f"l={length}", _by_seed(rows, "control_cost", policy=e, **{"channel.blocklength": length}),
                                _by_seed(rows, "control_cost", policy=base, **{"channel.blocklength": length}))
                               for length in lengths], "negative"))
            if 1024 in lengths:
                out.append(_claim("blocklength", f"blocklength.beats-{base}-slot.{e}",
                                  f"{e} beats {base.upper()} at l = 1024", f"stage cost at slot {REPORT_SLOT}, paired "
                                  "per seed", _by_seed(rows, slot_cost, policy=e, **{"channel.blocklength": 1024}),
                                  _by_seed(rows, slot_cost, policy=base, **{"channel.blocklength": 1024}), "negative"))
    return out


# ---------------------------------------------------------------------- tracking paths
PATH_CASES = [("K=3", "k3", "rg-mpc"), ("K=3", "k3", "ao-mpc"), ("K=4", "default", "rg-mpc"),
              ("K=4", "default", "ao-mpc"), ("K=4", "default", "epa")]


def _path_rows(cases, quick: bool) -> list[dict]:
    """Drone, AGV and reference positions of one episode (seed 0) per (label, preset, policy)."""
    import gymnasium as gym

    from agents import make_policy, rollout
    from lawn_env import presets

    rows = []
    for label, preset, policy in cases:
        cfg = presets.get(preset).override(num_slots=30 if quick else 120)
        env = gym.make("lawn/Joint-v0", config=cfg).unwrapped
        cost = rollout(env, make_policy(policy, cfg), 0).metrics["control_cost"]
        traj = env.trajectories()
        for n in range(traj["drone_position"].shape[0]):
            base = {"case": label, "preset": preset, "policy": policy, "slot": n, "control_cost": cost}
            rows.append({**base, "who": "drone", "x": traj["drone_position"][n, 0], "y": traj["drone_position"][n, 1]})
            for i in range(cfg.num_agvs):
                for who, arr in (("agv", traj["agv_position"]), ("reference", traj["reference_position"])):
                    rows.append({**base, "who": f"{who}_{i}", "x": arr[n, i, 0], "y": arr[n, i, 1]})
    return rows


def _paths_plot_cases(rows, path: Path, cases) -> None:
    from lawn_env import presets

    fig = _figure(ncols=len(cases), width=3.3, height=3.6)
    for j, (label, preset, policy) in enumerate(cases):
        ax = fig.add_subplot(1, len(cases), j + 1)
        sel = [r for r in rows if r["case"] == label and r["policy"] == policy]
        k = len({r["who"] for r in sel if r["who"].startswith("agv_")})
        for i in range(k):
            for who, ls in (("reference", "--"), ("agv", "-")):
                pts = [(float(r["x"]), float(r["y"])) for r in sel if r["who"] == f"{who}_{i}"]
                ax.plot(*zip(*pts), ls, color=f"C{i}", lw=0.9 if who == "reference" else 1.3)
        drone = [(float(r["x"]), float(r["y"])) for r in sel if r["who"] == "drone"]
        ax.plot(*zip(*drone), "-", color="k", lw=1.2)
        ax.plot(*drone[-1], "k^", ms=6)
        x0, x1, y0, y1 = presets.get(preset).area_m
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        ax.set_aspect("equal")
        ax.set_title(f"{label}, {policy}: cost {float(sel[0]['control_cost']):,.0f}", fontsize=8)
    _save(fig, path)


def _paths_sweeps(quick):
    seeds, q = _pick(quick, 20, 2), QUICK_SET if quick else {}
    return {"paths-k3": _spec("paths-k3", {}, EXPERTS, seeds, preset="k3", set_=q),
            "paths-k4": _spec("paths-k4", {}, EXPERTS + ("epa",), seeds, set_=q)}


def _paths_plot(tables, path: Path) -> None:
    _paths_plot_cases(tables["paths"], path, PATH_CASES)


def _paths_claims(tables) -> list[Claim]:
    k3, k4 = tables["paths-k3"], tables["paths-k4"]
    out = []
    for e in EXPERTS:
        out.append(_claim("paths", f"paths.k3-shorter.{e}", f"{e}: with K = 3 the drone flies a shorter path than "
                          "with K = 4", "drone path length, paired per seed", _by_seed(k3, "drone_path_length_m", policy=e),
                          _by_seed(k4, "drone_path_length_m", policy=e), "negative"))
        out.append(_claim("paths", f"paths.epa-longer.{e}", f"EPA's drone flies a longer path than {e}'s (K = 4)",
                          "drone path length, paired per seed", _by_seed(k4, "drone_path_length_m", policy="epa"),
                          _by_seed(k4, "drone_path_length_m", policy=e), "positive"))
        out.append(_claim("paths", f"paths.epa-worse.{e}", f"EPA tracks worse than {e} (K = 4)", "RMSE, paired per seed",
                          _by_seed(k4, "rmse_m", policy="epa"), _by_seed(k4, "rmse_m", policy=e), "positive"))
    return out


# ---------------------------------------------------------------------- disturbance mode
DIST_CASES = [("nominal", "default", "rg-mpc"), ("nominal", "default", "epa"),
              ("disturbed", "disturbed", "rg-mpc"), ("disturbed", "disturbed", "epa")]


def _disturbance_sweeps(quick):
    q = QUICK_SET if quick else {}
    return {
        "disturbance-costs": _spec("disturbance-costs", {"preset": ["default", "disturbed"]}, EXPERTS + ("epa",),
                                   _pick(quick, 20, 2), set_=q),
        "disturbance-period": _spec("disturbance-period", {"disturbance.control_period_slots": _pick(quick, [1, 2, 3], [2]),
                                                           "disturbance.period_aware_planning": [True, False]},
                                    ("rg-mpc", "epa"), _pick(quick, 10, 2), preset="disturbed", set_=q),
    }


def _disturbance_plot(tables, path: Path) -> None:
    fig = _figure(ncols=3, width=4.0)
    rows = tables["disturbance-costs"]
    variants = list(dict.fromkeys(r["preset"] for r in rows))
    policies = list(dict.fromkeys(r["policy"] for r in rows))
    width = 0.8 / len(policies)
    for j, metric in enumerate(("control_cost", "rmse_m")):
        ax = fig.add_subplot(1, 3, j + 1)
        for i, policy in enumerate(policies):
            st = [mean_ci([_f(r, metric) for r in rows if r["policy"] == policy and r["preset"] == v]) for v in variants]
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
        sub = [r for r in per if parse_bool(r["disturbance.period_aware_planning"]) == aware]
        for policy in dict.fromkeys(r["policy"] for r in sub):
            _curve(ax, sub, "disturbance.control_period_slots", "control_cost", policy,
                   label=f"{policy}, {'plans with' if aware else 'ignores'} the period", ls=ls)
    ax.set_yscale("log")
    _label(ax, "disturbed: control period (ablation)", "commands every P slots", "control cost")
    _save(fig, path)
    _paths_plot_cases(tables["disturbance"], path.with_name(path.name + "-paths"), DIST_CASES)


def _disturbance_claims(tables) -> list[Claim]:
    rows = tables["disturbance-costs"]
    out = []
    for variant in ("default", "disturbed"):
        for e in EXPERTS:
            out.append(_claim("disturbance", f"disturbance.beats-epa.{variant}.{e}",
                              f"{variant}: {e} beats EPA" + (" (the same trend under disturbances)" if variant != "default"
                                                            else ""), "episode control cost, paired per seed",
                              _by_seed(rows, "control_cost", policy=e, preset=variant),
                              _by_seed(rows, "control_cost", policy="epa", preset=variant), "negative"))
    per = tables["disturbance-period"]
    periods = [int(p) for p in _values(per, "disturbance.control_period_slots") if p > 1]
    for policy in dict.fromkeys(r["policy"] for r in per):
        parts = []
        for p in periods:
            def get(aware, p=p):
                return {int(r["seed"]): _f(r, "control_cost") for r in per
                        if r["policy"] == policy and int(float(r["disturbance.control_period_slots"])) == p
                        and parse_bool(r["disturbance.period_aware_planning"]) == aware}
            parts.append((f"P={p}", get(True), get(False)))
        if parts:
            out.append(_multi("disturbance", f"disturbance.period-aware.{policy}", f"{policy} (project's check): "
                              "planning with the control period beats ignoring it", "episode control cost, paired per "
                              "seed", parts, "negative"))
    return out


# ---------------------------------------------------------------------- the registry
EXPERIMENTS: dict[str, Experiment] = {e.name: e for e in [
    Experiment("convergence", "default (K = 4, R_th = 10, 0 dBW, l = 1024), episode seed 0 driven by `ao-mpc`; slots "
               "11, 19, 28, 41; 20 AO iterations without early stop; `global-mpc` as the reference",
               builders={"convergence": _convergence_table}, plot=_convergence_plot, claims=_convergence_claims),
    Experiment("ce", f"`paper-nominal` (R_th = 1) at P_max = {CE_BUDGET_DBW:g} dBW, ρ ∈ {{0, 0.01, 0.05, 0.1}}, "
               "rg-mpc, ao-mpc, epa, pid, lqr, 20 seeds; the 0 dBW floor panel at ρ ∈ {0, 0.1}, 10 seeds",
               sweeps=_ce_sweeps, plot=_ce_plot, claims=_ce_claims),
    Experiment("cdf", "`paper-nominal`, P_max ∈ {−30, −25, −20, −15} dBW, rg-mpc and ao-mpc, 20 seeds",
               sweeps=_cdf_sweeps, plot=_cdf_plot, claims=_cdf_claims),
    Experiment("rate", "default, R_th ∈ {6, 8, 10}, P_max ∈ {−3, 0, 3} dBW, rg-mpc and ao-mpc, 20 seeds",
               sweeps=_rate_sweeps, plot=_rate_plot, claims=_rate_claims),
    Experiment("blocklength", "default, l ∈ {128, 256, 1024, 4096} and IBL, rg-mpc, ao-mpc, epa, sf, 20 seeds",
               sweeps=_blocklength_sweeps, plot=_blocklength_plot, claims=_blocklength_claims),
    Experiment("paths", "`k3` (rg-mpc, ao-mpc) and default (rg-mpc, ao-mpc, epa): paths of seed 0, path lengths and "
               "RMSE over 20 seeds", sweeps=_paths_sweeps,
               builders={"paths": lambda out, quick: _path_rows(PATH_CASES, quick)}, plot=_paths_plot,
               claims=_paths_claims),
    Experiment("disturbance", "default vs `disturbed` (wind, gusts, actuator lag, noise, commands every 2 slots), "
               "rg-mpc, ao-mpc, epa, 20 seeds; control period 1–3 with and without period-aware planning, 10 seeds",
               sweeps=_disturbance_sweeps, builders={"disturbance": lambda out, quick: _path_rows(DIST_CASES, quick)},
               plot=_disturbance_plot, claims=_disturbance_claims),
]}


# ---------------------------------------------------------------------- running
def _tables(exp: Experiment, out: Path, quick: bool, workers: int, progress: bool, run: bool = True) -> dict:
    from .evaluate import write_rows
    from .sweep import SweepTableError, read_rows, read_table, run_sweep

    tables = {}
    for name, spec in exp.sweeps(quick).items():
        path = out / "data" / f"{name}.csv"
        if run:
            try:
                run_sweep(spec, path, workers=workers, progress=progress)
            except SweepTableError as exc:
                raise SweepTableError(f"{exc}. For `lawn figures`: delete {path} or choose another --out "
                                      "(the figure's table was written by another spec or version)") from None
        tables[name] = read_rows(path)[0]
    for name, build in exp.builders.items():
        path = out / "data" / f"{name}.csv"
        if run and not path.exists():
            write_rows(build(out, quick), path)
        tables[name] = read_table(path)
    return tables


def make_figures(names: Sequence[str], out: Path, quick: bool = False, workers: int = 1,
                 progress: bool = True) -> dict[str, float]:
    """Build the named figures (all when ``names`` is empty): run the missing table rows, plot;
    returns seconds per figure."""
    names = list(names) or list(EXPERIMENTS)
    unknown = [n for n in names if n not in EXPERIMENTS]
    if unknown:
        raise ValueError(f"unknown figures {unknown}; valid: {', '.join(EXPERIMENTS)}")
    out = Path(out)
    (out / "data").mkdir(parents=True, exist_ok=True)
    timings = {}
    record = out / "timings.json"
    computed = json.loads(record.read_text()) if record.exists() else {}
    for name in names:
        start = time.perf_counter()
        exp = EXPERIMENTS[name]
        paths = [out / "data" / f"{t}.csv" for t in exp.table_names(quick)]
        before = [p.stat().st_mtime_ns if p.exists() else None for p in paths]
        exp.plot(_tables(exp, out, quick, workers, progress), out / name)
        timings[name] = time.perf_counter() - start
        if [p.stat().st_mtime_ns if p.exists() else None for p in paths] != before:
            computed[name] = timings[name]  # rows were run: the time it takes to build this figure
    record.write_text(json.dumps(computed, indent=2) + "\n")
    return timings


def check_claims(out: Path, names: Sequence[str] = ()) -> list[Claim]:
    """The claims of the named experiments (all whose tables exist when ``names`` is empty),
    checked on the tables in ``out/data``."""
    out = Path(out)
    claims = []
    for name, exp in EXPERIMENTS.items():
        if names and name not in names:
            continue
        paths = [out / "data" / f"{t}.csv" for t in list(exp.sweeps(False)) + list(exp.builders)]
        if not all(p.exists() for p in paths):
            continue
        claims += exp.claims(_tables(exp, out, False, 1, False, run=False))
    return claims


def _tally(claims: Sequence[Claim]) -> str:
    paper = [c for c in claims if "project's check" not in c.claim]
    own = [c for c in claims if "project's check" in c.claim]

    def count(cs):
        return ", ".join(f"{sum(c.verdict == v for c in cs)} {v}" for v in ("holds", "not significant", "differs"))

    return (f"Of the paper's {len(paper)} claims checked here: {count(paper)}. Of the project's own {len(own)} "
            f"checks: {count(own)}.")


def format_claims(claims: Sequence[Claim]) -> str:
    lines = ["| figure | claim | checked on | project's number (paired mean ± 95 % interval) | seeds | verdict |",
             "|---|---|---|---|---|---|"]
    for c in claims:
        v = {"holds": "holds", "differs": "**differs**", "not significant": "*not significant*"}.get(c.verdict, c.verdict)
        lines.append(f"| {c.figure} | {c.claim} | {c.metric} | {c.value} | {c.seeds or '–'} | {v} |")
    return "\n".join(lines)


# ---------------------------------------------------------------------- docs/REPRODUCTION.md
def write_reproduction(out: Path, docs: Path, explanations: Mapping[str, str] | None = None) -> Path:
    """Write ``docs/REPRODUCTION.md`` from the tables in ``out`` and copy the figures to
    ``docs/figures/reproduction/``. Every claim that does not hold gets the explanation keyed by
    its claim key's prefix in ``explanations`` (default :data:`training.reproduction.EXPLANATIONS`);
    the build times are those :func:`make_figures` recorded in ``out/timings.json`` when it ran the
    tables' rows."""
    from .provenance import provenance
    from .reproduction import EXPLANATIONS, INTRO

    out, docs = Path(out), Path(docs)
    explanations = EXPLANATIONS if explanations is None else explanations
    claims = check_claims(out)
    fig_dir = docs / "figures" / "reproduction"
    fig_dir.mkdir(parents=True, exist_ok=True)
    for png in sorted(out.glob("*.png")):
        shutil.copy2(png, fig_dir / png.name)
    lines = [INTRO.strip(), "", f"Generated by `lawn figures --out {out} --docs {docs}` at {provenance()}."]
    record = out / "timings.json"
    timings = json.loads(record.read_text()) if record.exists() else {}
    if timings:
        total = sum(timings.values())
        lines.append(f"Time to build the tables and figures from scratch (`--workers 2`, 2 cores): {total / 60:.1f} min ("
                     + ", ".join(f"{k} {v:.0f} s" for k, v in timings.items()) + ").")
    lines += ["", "## Settings", "", "| figure | setting |", "|---|---|"]
    lines += [f"| {e.name} | {e.setting} |" for e in EXPERIMENTS.values()]
    lines += ["", "## The paper's claims, checked", "",
              "Each comparison is paired: the same seeds (references, initial offsets, fading draws) for both "
              "sides; relative differences are per seed, then averaged, with a 95 % t-interval. *holds*: the "
              "interval lies on the claimed side of zero; *not significant*: it contains zero; *differs*: it lies "
              "on the other side. Rows marked \"project's check\" are this project's own findings, not the paper's "
              "claims.", "", _tally(claims), "", format_claims(claims), "",
              "## Where the results differ from the paper, and why", ""]
    missing, groups = [], {}  # explanation text -> the claims it explains, in table order
    for c in claims:
        if c.verdict == "holds":
            continue
        prefix = next((k for k in sorted(explanations, key=len, reverse=True) if c.key.startswith(k)), None)
        if prefix is None:
            missing.append(c.key)
        else:
            groups.setdefault(explanations[prefix].strip(), []).append(c)
    for text, members in groups.items():
        names = "; ".join(f"{c.figure}: {c.claim} [{c.metric}] ({c.verdict})" for c in members)
        lines += [f"* *{names}.*", "", "  " + text.replace("\n", "\n  "), ""]
    if missing:
        lines += ["* **Not yet explained:** " + ", ".join(missing), ""]
    lines += ["## Figures", ""]
    lines += [f"![{p.stem}](figures/reproduction/{p.name})" for p in sorted(out.glob("*.png"))]
    path = docs / "REPRODUCTION.md"
    path.write_text("\n".join(lines) + "\n")
    return path
