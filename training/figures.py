"""``lawn figures``: the paper's experiments (MODEL.md §7) from tidy tables.

Each experiment is a sweep spec (full and ``--quick``) and a plot function that reads only the
table. ``lawn figures [NAME...] --out DIR`` runs the missing sweeps into ``DIR/data/NAME.csv``
(resuming any partial table) and writes ``DIR/NAME.png`` and ``.pdf``. The paper's expert
(``ao-mpc``) and the reduced-problem expert (``rg-mpc``) appear side by side in every figure.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Callable

import numpy as np

__all__ = ["EXPERIMENTS", "make_figures"]

EXPERTS = ["rg-mpc", "ao-mpc"]
STYLE = {"rg-mpc": ("C3", "o", "-"), "ao-mpc": ("C0", "s", "-"), "epa": ("C1", "^", "--"), "sf": ("C2", "v", "--"),
         "pid": ("C4", "D", ":"), "lqr": ("C5", "x", ":")}


def _spec(name, grid, policies, seeds, preset="default", set_=None):
    return {"name": name, "env": "lawn/Joint-v0", "preset": preset, "set": dict(set_ or {}), "grid": grid,
            "policies": policies, "seeds": seeds}


QUICK_SET = {"num_slots": 30}


def _specs(quick: bool) -> dict[str, dict]:
    s = (lambda full, short: short if quick else full)
    q = QUICK_SET if quick else {}
    return {
        "ce": _spec("ce", {"channel.ce_error_var": s([0.0, 0.005, 0.01, 0.02, 0.05, 0.1], [0.0, 0.05])},
                    EXPERTS + ["epa", "pid", "lqr"], s(10, 2), preset="paper-nominal", set_=q),
        "cdf": _spec("cdf", {"power_budget_dbw": s([-30.0, -25.0, -20.0, -15.0], [-30.0, -15.0])}, EXPERTS,
                     s(20, 3), preset="paper-nominal", set_=q),
        "rate": _spec("rate", {"channel.rate_threshold_bps_hz": s([6.0, 7.0, 8.0, 9.0, 10.0, 11.0], [6.0, 10.0]),
                               "power_budget_dbw": s([-3.0, 0.0, 3.0], [0.0])}, EXPERTS, s(10, 2), set_=q),
        "disturbance-costs": _spec("disturbance-costs", {"preset": ["default", "disturbed"]}, EXPERTS + ["epa"],
                                   s(10, 2), set_=q),
        "blocklength": _spec("blocklength", {"channel.blocklength": s([128, 256, 512, 1024, 2048, 4096], [256, 2048]),
                                             "channel.infinite_blocklength": [False, True]},
                             EXPERTS + ["epa", "sf"], s(10, 2), set_=q),
    }


# ---------------------------------------------------------------------- plots (tables only)
def _figure(ncols=1, width=5.0, height=3.6):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width * ncols, height), dpi=110)
    FigureCanvasAgg(fig)
    return fig


class _single_axes:
    """``with _single_axes(path, title, xlabel, ylabel) as ax:`` draws one axes and saves PNG+PDF."""

    def __init__(self, path: Path, title: str, xlabel: str, ylabel: str, legend_size: int = 8):
        self.path, self.labels, self.legend_size = path, (title, xlabel, ylabel), legend_size

    def __enter__(self):
        self.fig = _figure()
        self.ax = self.fig.add_subplot(111)
        return self.ax

    def __exit__(self, *exc):
        if exc[0] is None:
            title, xlabel, ylabel = self.labels
            self.ax.set_title(title, fontsize=9)
            self.ax.set_xlabel(xlabel)
            self.ax.set_ylabel(ylabel)
            self.ax.legend(fontsize=self.legend_size)
            self.fig.tight_layout()
            _save(self.fig, self.path)
        return False


def _mean_ci(values):
    from scipy import stats

    v = np.asarray(values, dtype=float)
    if v.size < 2:
        return float(v.mean()), 0.0
    return float(v.mean()), float(stats.t.ppf(0.975, v.size - 1) * v.std(ddof=1) / np.sqrt(v.size))


def _curve(ax, rows, x_key, y_key, policy, label=None, **kw):
    sel = [r for r in rows if r["policy"] == policy]
    xs = sorted({float(r[x_key]) for r in sel})
    means, cis = zip(*[_mean_ci([float(r[y_key]) for r in sel if float(r[x_key]) == x]) for x in xs])
    color, marker, ls = STYLE.get(policy, ("k", ".", "-"))
    ax.errorbar(xs, means, yerr=cis, color=kw.pop("color", color), marker=marker, ls=kw.pop("ls", ls), ms=4,
                capsize=3, label=label or policy, **kw)
    return xs, means


def plot_ce(rows, path: Path) -> None:
    with _single_axes(path, "RMSE vs channel-estimation error (R_th = 1, P_max = 0 dBW)",
                      "normalized CE error variance ρ", "tracking RMSE (m)") as ax:
        for policy in dict.fromkeys(r["policy"] for r in rows):
            _curve(ax, rows, "channel.ce_error_var", "rmse_m", policy)


def plot_cdf(rows, path: Path) -> None:
    with _single_axes(path, "CDF of RMSE under power budgets (R_th = 1)", "tracking RMSE (m)", "CDF over seeds",
                      legend_size=7) as ax:
        for i, p in enumerate(sorted({float(r["power_budget_dbw"]) for r in rows})):
            for policy in EXPERTS:
                vals = np.sort([float(r["rmse_m"]) for r in rows
                                if r["policy"] == policy and float(r["power_budget_dbw"]) == p])
                if vals.size:
                    ax.step(vals, np.arange(1, vals.size + 1) / vals.size, where="post", color=f"C{i}",
                            ls="-" if policy == "rg-mpc" else "--", label=f"{policy}, {p:g} dBW")


def plot_rate(rows, path: Path) -> None:
    with _single_axes(path, "control cost vs rate threshold under power budgets", "rate threshold R_th (bit/s/Hz)",
                      "realized control cost", legend_size=7) as ax:
        for i, p in enumerate(sorted({float(r["power_budget_dbw"]) for r in rows})):
            sub = [r for r in rows if float(r["power_budget_dbw"]) == p]
            for policy in EXPERTS:
                _curve(ax, sub, "channel.rate_threshold_bps_hz", "control_cost", policy,
                       label=f"{policy}, {p:g} dBW", color=f"C{i}", ls="-" if policy == "rg-mpc" else "--")
        ax.set_yscale("log")


def plot_blocklength(rows, path: Path) -> None:
    fbl = [r for r in rows if str(r["channel.infinite_blocklength"]) in ("False", "false", "0")]
    ibl = [r for r in rows if str(r["channel.infinite_blocklength"]) in ("True", "true", "1")]
    with _single_axes(path, "control cost vs blocklength (R_th = 10, P_max = 0 dBW)",
                      "blocklength l (channel uses); dotted: IBL limit of each policy", "realized control cost") as ax:
        for policy in dict.fromkeys(r["policy"] for r in fbl):
            _curve(ax, fbl, "channel.blocklength", "control_cost", policy)
            limit = [float(r["control_cost"]) for r in ibl if r["policy"] == policy]
            if limit:
                ax.axhline(np.mean(limit), color=STYLE.get(policy, ("k",))[0], ls=":", lw=1)
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")


def plot_bars(rows, path: Path) -> None:
    fig = _figure(ncols=2, width=4.0)
    for j, metric in enumerate(("control_cost", "rmse_m")):
        ax = fig.add_subplot(1, 2, j + 1)
        variants = list(dict.fromkeys(r["preset"] for r in rows))
        policies = list(dict.fromkeys(r["policy"] for r in rows))
        width = 0.8 / len(policies)
        for i, policy in enumerate(policies):
            stats_ = [_mean_ci([float(r[metric]) for r in rows if r["policy"] == policy and r["preset"] == v])
                      for v in variants]
            ax.bar(np.arange(len(variants)) + i * width, [m for m, _ in stats_], width, yerr=[c for _, c in stats_],
                   color=STYLE.get(policy, ("k",))[0], capsize=3, label=policy)
        ax.set_xticks(np.arange(len(variants)) + 0.4 - width / 2, variants)
        ax.set_yscale("log")
        ax.set_title(metric.replace("_", " "), fontsize=9)
        if j == 0:
            ax.legend(fontsize=8)
    fig.tight_layout()
    _save(fig, path)


def _save(fig, path: Path) -> None:
    fig.savefig(path.with_suffix(".png"))
    fig.savefig(path.with_suffix(".pdf"))


# ---------------------------------------------------------------------- episodes-based figures
def _convergence(out: Path, quick: bool, workers: int, progress: bool) -> Path:
    from lawn_env import ScenarioConfig

    from .evaluate import write_rows
    from .gap import convergence, plot_convergence
    from .sweep import read_table

    table = out / "data" / "convergence.csv"
    if not table.exists():
        cfg = ScenarioConfig(num_slots=30) if quick else ScenarioConfig()
        slots = [11, 19] if quick else [11, 19, 28, 41]
        glob = {"psi_points": 41, "drone_spacing_m": 2.5, "power_levels": 40} if quick else {}
        write_rows(convergence(cfg, slots, seed=0, driver="ao-mpc", iterations=20, global_settings=glob), table)
    rows = [{**r, "slot": int(r["slot"]), "iteration": int(r["iteration"]),
             **{k: float(r[k]) for k in ("objective", "global_objective", "rg_mpc_objective")}} for r in read_table(table)]
    plot_convergence(rows, out / "convergence.png")
    plot_convergence(rows, out / "convergence.pdf")
    return table


def _paths(out: Path, quick: bool, workers: int, progress: bool, name: str = "paths", cases=None) -> Path:
    """Tracking paths: K = 3 expert, K = 4 expert, K = 4 EPA (seed 0), for both experts."""
    import gymnasium as gym

    from agents import make_policy
    from lawn_env import presets

    from .evaluate import write_rows
    from .sweep import read_table

    table = out / "data" / f"{name}.csv"
    cases = cases or [("K=3", "k3", "rg-mpc"), ("K=3", "k3", "ao-mpc"), ("K=4", "default", "rg-mpc"),
                      ("K=4", "default", "ao-mpc"), ("K=4", "default", "epa")]
    if not table.exists():
        rows = []
        for label, preset, policy in cases:
            cfg = presets.get(preset).override(num_slots=30 if quick else 120)
            k = cfg.num_agvs
            env = gym.make("lawn/Joint-v0", config=cfg).unwrapped
            agent = make_policy(policy, cfg)
            obs, _ = env.reset(seed=0)
            agent.reset(0)
            done = False
            while not done:
                obs, _, _, done, info = env.step(agent.act(obs))
            traj = env.sim.trajectories()
            cost = info["episode_metrics"]["control_cost"]
            for n in range(traj["drone_position"].shape[0]):
                rows.append({"case": label, "policy": policy, "slot": n, "who": "drone", "x": traj["drone_position"][n, 0],
                             "y": traj["drone_position"][n, 1], "control_cost": cost})
                for i in range(k):
                    for who, arr in (("agv", traj["agv_position"]), ("reference", traj["reference_position"])):
                        rows.append({"case": label, "policy": policy, "slot": n, "who": f"{who}_{i}", "x": arr[n, i, 0],
                                     "y": arr[n, i, 1], "control_cost": cost})
        write_rows(rows, table)
    rows = read_table(table)
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
        ax.set_xlim(0, 200)
        ax.set_ylim(0, 200)
        ax.set_aspect("equal")
        ax.set_title(f"{label}, {policy}: cost {float(sel[0]['control_cost']):,.0f}", fontsize=8)
    fig.tight_layout()
    _save(fig, out / name)
    return table


def _disturbance(out: Path, quick: bool, workers: int, progress: bool) -> Path:
    """Expert and EPA paths with and without the disturbance mode (MODEL.md §7), seed 0."""
    cases = [("nominal", "default", "rg-mpc"), ("nominal", "default", "epa"),
             ("disturbed", "disturbed", "rg-mpc"), ("disturbed", "disturbed", "epa")]
    return _paths(out, quick, workers, progress, name="disturbance", cases=cases)


def _sweep_figure(name: str, plot: Callable):
    def run(out: Path, quick: bool, workers: int, progress: bool) -> Path:
        from .sweep import read_table, run_sweep

        table = out / "data" / f"{name}.csv"
        run_sweep(_specs(quick)[name], table, workers=workers, progress=progress)
        plot(read_table(table), out / name)
        return table

    return run


#: name -> builder(out_dir, quick, workers, progress) returning its table's path
EXPERIMENTS: dict[str, Callable] = {
    "convergence": _convergence,
    "ce": _sweep_figure("ce", plot_ce),
    "cdf": _sweep_figure("cdf", plot_cdf),
    "rate": _sweep_figure("rate", plot_rate),
    "blocklength": _sweep_figure("blocklength", plot_blocklength),
    "paths": _paths,
    "disturbance": _disturbance,
    "disturbance-costs": _sweep_figure("disturbance-costs", lambda rows, path: plot_bars(rows, path)),
}


def make_figures(names, out: Path, quick: bool = False, workers: int = 1, progress: bool = True) -> dict[str, float]:
    """Build the named figures (all when ``names`` is empty); returns seconds per figure."""
    names = list(names) or list(EXPERIMENTS)
    unknown = [n for n in names if n not in EXPERIMENTS]
    if unknown:
        raise ValueError(f"unknown figures {unknown}; valid: {', '.join(EXPERIMENTS)}")
    out = Path(out)
    (out / "data").mkdir(parents=True, exist_ok=True)
    timings = {}
    for name in names:
        start = time.perf_counter()
        EXPERIMENTS[name](out, quick, workers, progress)
        timings[name] = time.perf_counter() - start
    return timings


# ---------------------------------------------------------------------- the paper's claims, checked
def _means(rows, key, metric, policy=None, where=None):
    out = {}
    for r in rows:
        if policy is not None and r["policy"] != policy:
            continue
        if where and any(str(r[k]) != str(v) for k, v in where.items()):
            continue
        out.setdefault(float(r[key]) if key not in ("channel.infinite_blocklength", "preset") else r[key], []).append(
            float(r[metric]))
    return {k: float(np.mean(v)) for k, v in sorted(out.items())}


def trend_checks(out: Path) -> list[dict]:
    """Each figure's claim from the paper's text, checked on its table; returns rows of
    (figure, claim, holds, evidence)."""
    from .sweep import read_table

    out = Path(out)
    data = out / "data"
    checks = []

    def add(fig, claim, holds, evidence):
        checks.append({"figure": fig, "claim": claim, "holds": bool(holds), "evidence": evidence})

    if (data / "convergence.csv").exists():
        rows = read_table(data / "convergence.csv")
        for slot in dict.fromkeys(r["slot"] for r in rows):
            sel = [float(r["objective"]) for r in rows if r["slot"] == slot]
            glob = float(next(r["global_objective"] for r in rows if r["slot"] == slot))
            fast = float(next(r["rg_mpc_objective"] for r in rows if r["slot"] == slot))
            monotone = all(b <= a * (1 + 1e-12) for a, b in zip(sel, sel[1:]))
            excess = sel[-1] / glob - 1
            add("convergence", f"slot {slot}: the AO converges to the optimum within a few iterations",
                monotone and excess < 1e-3,
                f"trace non-increasing: {monotone}; after 20 iterations {excess:.2%} above the global reference "
                f"(rg-mpc {fast / glob - 1:.3%})")
    if (data / "ce.csv").exists():
        rows = read_table(data / "ce.csv")
        policies = list(dict.fromkeys(r["policy"] for r in rows))
        grow = {p: _means(rows, "channel.ce_error_var", "rmse_m", p) for p in policies}
        add("ce", "RMSE grows with the CE error variance (every policy)",
            all(list(g.values())[-1] > list(g.values())[0] for g in grow.values()),
            "; ".join(f"{p}: {list(g.values())[0]:.3f} -> {list(g.values())[-1]:.3f} m" for p, g in grow.items()))
        best = min(policies, key=lambda p: np.mean(list(grow[p].values())))
        add("ce", "the expert has the lowest RMSE and the slowest growth", best in EXPERTS,
            f"lowest mean RMSE over rho: {best}; EPA {np.mean(list(grow['epa'].values())):.3f}, "
            f"rg-mpc {np.mean(list(grow['rg-mpc'].values())):.3f}, ao-mpc {np.mean(list(grow['ao-mpc'].values())):.3f} m")
    if (data / "cdf.csv").exists():
        rows = read_table(data / "cdf.csv")
        for p in EXPERTS:
            med = {}
            for r in rows:
                if r["policy"] == p:
                    med.setdefault(float(r["power_budget_dbw"]), []).append(float(r["rmse_m"]))
            med = {k: float(np.median(v)) for k, v in sorted(med.items())}
            vals = list(med.values())
            add("cdf", f"{p}: a higher power budget gives lower RMSE", all(b <= a + 1e-9 for a, b in zip(vals, vals[1:])),
                "median RMSE " + ", ".join(f"{k:g} dBW: {v:.3f} m" for k, v in med.items()))
    if (data / "rate.csv").exists():
        rows = read_table(data / "rate.csv")
        for p in EXPERTS:
            rises = {}
            for budget in sorted({float(r["power_budget_dbw"]) for r in rows}):
                m = _means(rows, "channel.rate_threshold_bps_hz", "control_cost", p, {"power_budget_dbw": budget})
                rises[budget] = list(m.values())[-1] / list(m.values())[0]
            ordered = list(rises.values())
            add("rate", f"{p}: cost rises with R_th, more steeply at lower P_max",
                all(v > 1 for v in ordered) and all(a >= b for a, b in zip(ordered, ordered[1:])),
                "cost(R_max)/cost(R_min): " + ", ".join(f"{k:g} dBW x{v:.2f}" for k, v in rises.items()))
    if (data / "blocklength.csv").exists():
        rows = read_table(data / "blocklength.csv")
        fbl = [r for r in rows if r["channel.infinite_blocklength"] in ("False", "false")]
        ibl = [r for r in rows if r["channel.infinite_blocklength"] in ("True", "true")]
        for p in dict.fromkeys(r["policy"] for r in rows):
            m = _means(fbl, "channel.blocklength", "control_cost", p)
            limit = float(np.mean([float(r["control_cost"]) for r in ibl if r["policy"] == p]))
            vals = list(m.values())
            add("blocklength", f"{p}: cost falls as the blocklength grows, toward the IBL limit",
                vals[-1] < vals[0] and vals[-1] >= limit * 0.9,
                f"l={int(list(m)[0])}: {vals[0]:,.0f}, l={int(list(m)[-1])}: {vals[-1]:,.0f}, IBL: {limit:,.0f}")
        for base in ("epa", "sf"):
            worse = [l for l in {float(r['channel.blocklength']) for r in fbl}
                     if min(_means(fbl, "channel.blocklength", "control_cost", e)[l] for e in EXPERTS)
                     >= _means(fbl, "channel.blocklength", "control_cost", base)[l]]
            add("blocklength", f"the experts beat {base.upper()} at every blocklength", not worse,
                "expert not better at l = " + (", ".join(f"{int(l)}" for l in sorted(worse)) if worse else "none"))
    if (data / "disturbance-costs.csv").exists():
        rows = read_table(data / "disturbance-costs.csv")
        for variant in ("default", "disturbed"):
            m = {p: np.mean([float(r["control_cost"]) for r in rows if r["policy"] == p and r["preset"] == variant])
                 for p in dict.fromkeys(r["policy"] for r in rows)}
            add("disturbance", f"{variant}: the experts beat EPA", min(m[e] for e in EXPERTS) < m["epa"],
                ", ".join(f"{p} {v:,.0f}" for p, v in m.items()))
    return checks


def format_checks(checks: list[dict]) -> str:
    lines = ["| figure | claim (paper) | holds here | evidence (from the figure's table) |", "|---|---|---|---|"]
    for c in checks:
        lines.append(f"| {c['figure']} | {c['claim']} | {'yes' if c['holds'] else '**no**'} | {c['evidence']} |")
    return "\n".join(lines)
