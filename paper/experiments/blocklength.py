"""Cost against the blocklength, with the infinite-blocklength limit (the paper's blocklength figure)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from evaluation.cells import fmt_paired
from evaluation.stats import paired_difference
from evaluation.sweep import SweepSpec

from .base import EXPERTS, REPORT_SLOT, SEEDS, Experiment, Metric, Tables, by_seed, slot_cost, spec, values
from .claims import Claim, multi_claim, paired_claim
from .plots import STYLE, curve, label_axes, new_figure, save

BLOCK_POLICIES = (*EXPERTS, "epa", "sf")


def _blocklength_sweeps(quick: bool) -> dict[str, SweepSpec]:
    lengths = [256, 2048] if quick else [128, 256, 1024, 4096]
    return {"blocklength": spec("blocklength", {"channel.blocklength": lengths}, BLOCK_POLICIES, quick),
            "blocklength-ibl": spec("blocklength-ibl", {"channel.infinite_blocklength": [True]}, BLOCK_POLICIES, quick)}


def _blocklength_plot(tables: Tables, path: Path) -> None:
    rows, ibl = tables["blocklength"], tables["blocklength-ibl"]
    fig = new_figure()
    ax = fig.add_subplot(111)
    for policy in dict.fromkeys(r.policy for r in rows):
        curve(ax, rows, "channel.blocklength", "control_cost", policy)
        limit = [r.result.control_cost for r in ibl if r.policy == policy]
        if limit:
            ax.axhline(np.mean(limit), color=STYLE.get(policy, ("k",))[0], ls=":", lw=1)
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    label_axes(ax, "control cost vs blocklength (R_th = 10, P_max = 0 dBW)",
               "blocklength l (channel uses); dotted: IBL limit of each policy", "realized control cost")
    save(fig, path)


def _blocklength_claims(tables: Tables) -> list[Claim]:
    rows, ibl = tables["blocklength"], tables["blocklength-ibl"]
    lengths = [int(x) for x in values(rows, "channel.blocklength")]
    l0, l1 = lengths[0], lengths[-1]

    def at(policy: str, length: int, metric: Metric = "control_cost") -> dict[int, float]:
        return by_seed(rows, metric, policy, {"channel.blocklength": length})

    out = []
    for p in dict.fromkeys(r.policy for r in rows):
        out.append(paired_claim("blocklength", f"blocklength.falls.{p}", f"{p}: cost falls as the blocklength grows "
                                f"(l = {l0} → {l1})", "episode control cost, paired per seed", at(p, l1), at(p, l0),
                                "negative"))
        limit = by_seed(ibl, "control_cost", p)
        m1, h1, n = paired_difference(at(p, l1), limit)
        m0, _, _ = paired_difference(at(p, l0), limit)
        ok = (m1 - h1 <= 0 <= m1 + h1) or (0 < m1 < m0)
        out.append(Claim("blocklength", f"blocklength.ibl.{p}", f"{p}: cost converges toward the IBL limit",
                         "episode control cost vs IBL, paired per seed",
                         f"l = {l1}: {fmt_paired(m1, h1)} above IBL (l = {l0}: {m0 * 100:+.1f} %)",
                         "holds" if ok else "differs", n))
    for base in ("epa", "sf"):
        for e in EXPERTS:
            out.append(multi_claim("blocklength", f"blocklength.beats-{base}.{e}", f"{e} beats {base.upper()} at every "
                                   "blocklength", "episode control cost, paired per seed",
                                   [(f"l={n}", at(e, n), at(base, n)) for n in lengths], "negative"))
            if 1024 in lengths:
                out.append(paired_claim("blocklength", f"blocklength.beats-{base}-slot.{e}", f"{e} beats "
                                        f"{base.upper()} at l = 1024", f"stage cost at slot {REPORT_SLOT}, paired per "
                                        "seed", at(e, 1024, slot_cost), at(base, 1024, slot_cost), "negative"))
    return out


EXPERIMENT = Experiment("blocklength",
                        f"default, l ∈ {{128, 256, 1024, 4096}} and IBL, rg-mpc, ao-mpc, epa, sf, {SEEDS} seeds",
                        sweeps=_blocklength_sweeps, plot=_blocklength_plot, claims=_blocklength_claims)
