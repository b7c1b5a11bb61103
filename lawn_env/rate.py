"""The short-packet rate (MODEL.md §2): the finite-blocklength (Polyanskiy-Poor-Verdu normal
approximation) rate of a link at a given SNR and the SNR threshold at which it reaches a rate.
Depends on nothing else in the package (the config validates its rate, blocklength and BLER with
:func:`snr_threshold`; :mod:`lawn_env.channel` builds the links on it and re-exports these names).

* FBL rate, bit/s/Hz: ``R(G) = log2(1+G) - sqrt(V/l) Q^{-1}(eps) log2(e)``, ``V = 1 - (1+G)^{-2}``.
  ``paper_form=True`` drops ``log2(e)`` as the paper prints it (a units slip, MODEL.md §2).
* SNR threshold: the root of ``R(G) = R_th`` on the increasing branch, found by bracketed root
  finding above the closed-form turning point, cached per ``(R_th, l, eps, paper_form)``.
  ``blocklength=inf`` gives the IBL threshold ``2^R_th - 1``.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from scipy import optimize, special

__all__ = ["LOG2E", "ibl_rate", "fbl_rate", "rate_turning_point", "snr_threshold"]

LOG2E = 1.0 / math.log(2.0)


def _dispersion_factor(blocklength: float, bler: float, paper_form: bool) -> float:
    """sqrt(1/l) Q^{-1}(eps) [log2 e]: the coefficient of sqrt(V) in the FBL rate."""
    qinv = -float(special.ndtri(bler))  # Q^{-1}(eps) = -Phi^{-1}(eps), exact for small eps
    factor = qinv / math.sqrt(blocklength)
    return factor if paper_form else factor * LOG2E


def ibl_rate(snr: np.ndarray | float) -> np.ndarray:
    """Shannon rate log2(1 + SNR), bit/s/Hz (the IBL limit of :func:`fbl_rate`)."""
    return np.log2(1.0 + np.asarray(snr, dtype=float))


def fbl_rate(snr: np.ndarray | float, blocklength: float, bler: float, paper_form: bool = False) -> np.ndarray:
    """Achievable FBL rate in bit/s/Hz at linear SNR ``snr`` (MODEL.md §2).

    ``blocklength=math.inf`` returns the IBL rate.
    """
    snr = np.asarray(snr, dtype=float)
    if math.isinf(blocklength):
        return ibl_rate(snr)
    dispersion = 1.0 - (1.0 + snr) ** -2
    return np.log2(1.0 + snr) - np.sqrt(dispersion) * _dispersion_factor(blocklength, bler, paper_form)


def rate_turning_point(blocklength: float, bler: float, paper_form: bool = False) -> float:
    """SNR at which the FBL rate is minimal (R' = 0), in closed form.

    R'(G) = 0 reduces to ``(1+G) sqrt((1+G)^2 - 1) = c`` with ``c = Q^{-1}(eps)/sqrt(l)`` for the
    log2(e) form (the paper's equation) and ``c ln 2`` for the paper's printed form; so
    ``(1+G)^2 = 1/2 + sqrt(1/4 + c^2)``.
    """
    c = -float(special.ndtri(bler)) / math.sqrt(blocklength)
    if paper_form:
        c *= math.log(2.0)
    return math.sqrt(0.5 + math.sqrt(0.25 + c * c)) - 1.0


@functools.lru_cache(maxsize=256)
def _snr_threshold_cached(rate: float, blocklength: float, bler: float, paper_form: bool) -> float:
    if math.isinf(blocklength):
        return float(2.0**rate) - 1.0
    lo = rate_turning_point(blocklength, bler, paper_form)
    # R(G) >= log2(1+G) - factor, so G_hi = 2^(rate + factor) - 1 has R(G_hi) >= rate.
    hi = 2.0 ** (rate + _dispersion_factor(blocklength, bler, paper_form) + 1.0)

    def f(g: float) -> float:
        return float(fbl_rate(g, blocklength, bler, paper_form)) - rate

    return float(optimize.brentq(f, lo, hi, xtol=1e-300, rtol=4 * np.finfo(float).eps, maxiter=500))


def snr_threshold(rate: float, blocklength: float, bler: float, paper_form: bool = False) -> float:
    """Linear SNR at which the FBL rate equals ``rate`` bit/s/Hz (increasing branch).

    ``blocklength=math.inf`` gives the IBL threshold ``2^rate - 1``. Cached.
    """
    rate = float(rate)
    if not rate > 0 or not math.isfinite(rate):
        raise ValueError(f"rate={rate!r}: the rate threshold must be a finite positive number (bit/s/Hz)")
    if not 0.0 < bler < 1.0:
        raise ValueError(f"bler={bler!r}: must lie in (0, 1)")
    if not blocklength > 0:
        raise ValueError(f"blocklength={blocklength!r}: must be positive (or math.inf for IBL)")
    return _snr_threshold_cached(rate, float(blocklength), float(bler), bool(paper_form))
