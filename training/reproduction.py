"""The fixed text of ``docs/REPRODUCTION.md``; every number in it comes from the tables
(:func:`training.figures.write_reproduction`).

``EXPLANATIONS`` maps a claim-key prefix to why that claim does not hold here; each names the test
or command that demonstrates the mechanism. A claim that does not hold and has no explanation is
listed as "not yet explained" in the document.
"""

INTRO = """
# Reproducing the paper's experiments

One command regenerates every experiment of MODEL.md §7, this page and its figures:

```bash
lawn figures --out runs/figures --docs docs   # the full set (≥ 20 seeds where a claim is tested)
lawn figures rate blocklength --out runs/figures    # some of them
lawn figures --quick --out runs/quick               # reduced seeds, grids and episodes (the tests run it)
```

(`bash scripts/refresh_docs.sh` runs it together with every other generated table of the README.)
Each experiment (`training/figures.py`, one `Experiment` record per figure) is a set of tidy tables
(`runs/figures/data/<table>.csv`: one row per episode with its config, the metrics of MODEL.md §6,
the realized stage cost of every slot and the software version), a plot that reads only those
tables, and the paper's claims about it, checked on the same tables. Rerunning skips finished rows,
so an interrupted run resumes.

The regime (MODEL.md §8): at the paper's nominal point (R_th = 1 bit/s/Hz at 0 dBW) every link's
outage is 1e-8 to 1e-5 and the policies tie, so the figures sit where outage matters: rate and
blocklength at the project's decided R_th = 10 (varied around it), CDF at R_th = 1 with power budgets
of −30 to −15 dBW, and CE at R_th = 1 and −30 dBW, where the noise term σ²d²/(α0 p) is comparable
to the CE error ρ (at 0 dBW it is below 3e-3 everywhere, so the CE error sets a power-independent
outage floor: the second CE panel shows it). Reference paths respect the AGVs' envelope (MODEL.md §1)
and planners plan with the control period (MODEL.md §7).
"""

_SLOT_NOISE = """One slot's realized cost is dominated by that slot's fading draw and by where each
AGV happens to be on its path; its seed-to-seed spread is far larger than the episode cost's, so 20
seeds rarely resolve a difference on it. The episode-cost rows of the same comparison are the
meaningful ones."""

_AO = """The paper's AO is no better than equal power per slot on this scenario: on the states of an
EPA-driven episode its returned J^ is above EPA's on some slots, while the reduced-problem expert's
never is (`tests/test_reduced.py::test_paper_ao_is_no_better_than_epa_per_slot_where_rg_mpc_is`).
Its power block starts from equal power and stalls, and Algorithm 2's stopping rule ends the descent
far above the optimum (the convergence rows above). With references the AGVs can follow, the
tracking part of the cost is small and these per-slot losses decide the comparison; `rg-mpc`, which
solves the same per-slot problem to the optimum, wins the same comparison (the `rg-mpc` row)."""

EXPLANATIONS = {
    "convergence.optimum": """The AO's objective never increases (the paper's argument holds with
MODEL.md §4's safeguard), but it stops on a slow descent far above the optimum: block-coordinate
descent on strongly coupled blocks, where each power or drone step can raise ψ only a little before
the next QP. The reduced-problem expert reaches the global reference at the same slots (the value
in brackets). Tested by `tests/test_reduced.py::test_rg_mpc_is_never_worse_than_the_paper_ao_on_sampled_slots`;
measured over 200 slots by `lawn gap` (README).""",
    "convergence.few-iterations": """At this slot the descent is slow enough that Algorithm 2's rule
(relative decrease per iteration below 1e-2) needs more than ten iterations; see the row above for
how far from the optimum it still is.""",
    "ce.rmse-grows": """Every policy's mean RMSE grows with ρ, and the paired interval excludes zero for
every policy but EPA. EPA loses an AGV on one seed at ρ = 0.1 (its RMSE there is an order of
magnitude above the others, `runs/figures/data/ce.csv`), and that one relative difference widens
the t-interval across zero.""",
    "ce.slowest-growth": """The differences in growth are a few centimetres against the MPC-based
baselines and are dominated by the one lost AGV against EPA; 20 seeds do not resolve them. The level
comparison ("lowest RMSE") is resolved.""",
    "ce.expert-lowest-slot": _SLOT_NOISE,
    "rate.rises-slot": _SLOT_NOISE,
    "rate.steeper-slot": _SLOT_NOISE,
    "ce.expert-lowest": _AO + """ Here the predictive PID and LQR, whose power and drone are optimized by
the same blocks but whose increments need no coupled descent, track better than the AO.""",
    "blocklength.beats-epa-slot": _SLOT_NOISE,
    "blocklength.beats-sf-slot": _SLOT_NOISE,
    "blocklength.beats-epa": _AO,
    "blocklength.beats-sf": _AO,
    "disturbance.beats-epa": _AO,
    "paths.epa-worse": _AO,
    "paths.k3-shorter": """The claim holds for the paper's AO, whose drone takes small SCA steps. `rg-mpc`
moves the drone wherever the one-slot objective is lower, however little, and nothing in the
paper's objective charges for flying (MODEL.md §4), so its path length is set by that repositioning,
several times EPA's and the AO's (`runs/figures/data/paths-k4.csv`), not by how many AGVs it
serves.""",
    "paths.epa-longer": """The claim holds for the paper's AO. `rg-mpc` moves the drone wherever the
one-slot objective is lower, however little, and nothing in the paper's objective charges for flying
(MODEL.md §4), so its drone flies several times further than EPA's while its cost is lower (the
disturbance rows).""",
    "disturbance.period-aware": """Planning with the period is better on every seed at P = 2 and on all
but one at P = 3, where EPA's period-aware plan still loses an AGV on one seed (commands every 1.5 s
with actuator lag and noise), and that seed's relative difference widens the interval across zero
(`runs/figures/data/disturbance-period.csv`).""",
}
