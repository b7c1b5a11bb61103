"""The paper's experiments (MODEL.md §7), one module each: its sweep specs (full and ``--quick``),
the builders of its other tables, its plot (reading only those tables) and its claims, checked with
paired per-seed differences and 95 % t-intervals (:func:`evaluation.stats.paired_difference`), in
one :class:`Experiment` record (``EXPERIMENT``). :mod:`.runner` runs any of them:
``lawn figures [NAME...] --out DIR`` runs the missing rows into ``DIR/data/<table>.csv`` (resuming
partial tables), writes ``DIR/<name>.png`` and ``.pdf`` and the claims' results
(``DIR/claims.json``, ``DIR/claims.md``); with ``--docs DOCS`` it writes ``DOCS/REPRODUCTION.md``
from those results (:func:`paper.experiments.reproduction.write_reproduction`).

Where the paper evaluates one slot (its rate, blocklength and CE figures use "a selected time slot",
n = 11), the claims are checked on the episode's realized control cost *and* on the realized stage
cost of slot 11 (the transition driven by the decision at slot 11, counted from 0 as everywhere in
this package), each labelled.
"""

from __future__ import annotations

from .base import REPORT_SLOT, SEEDS, Experiment
from .claims import Claim, format_claims, read_claims, tally, write_claims
from .registry import EXPERIMENTS
from .runner import check_claims, make_figures, tables_of

__all__ = ["EXPERIMENTS", "Experiment", "Claim", "REPORT_SLOT", "SEEDS", "make_figures", "check_claims", "write_claims",
           "read_claims", "tables_of", "format_claims", "tally"]
