"""Short-packet drone-to-AGV link with Nakagami-m fading (MODEL.md §2).

Each equation of the link is one compiled scalar function here, called by the simulation's slot
kernel and, as a numpy ufunc, by every array method of :class:`LinkParams` (the planners, the RL
interface's anchors, the stake prior and the tests call those):

* :func:`link_distance_sq`: ``d^2 = ||c - q||^2 + H^2`` (m^2);
* :func:`link_argument`: the outage argument of Prop. 1,
  ``x = m G_th (rho + d^2 sigma^2 / (alpha0 p)) / (1 - rho) = c_d d^2 / p + c_ce``;
* :func:`outage_law`: the outage probability ``P = gammainc(m, x)`` (regularized lower incomplete
  gamma: ``m |h|^2 ~ Gamma(m, 1)``), its complement ``psi = gammaincc(m, x)`` (accurate when tiny),
  its density ``-d psi / dx`` and its high-SNR order;
* :func:`command_delivered`: a command arrives when ``m |h|^2 >= x`` (realized SNR >= G_th).

All functions take *linear* quantities (power in W, gain as a ratio); the config's dB values are
converted by :class:`LinkParams`. The FBL rate and the SNR threshold are in :mod:`lawn_env.rate`:
``R(G) = log2(1+G) - sqrt(V/l) Q^{-1}(eps) log2(e)``, ``V = 1 - (1+G)^{-2}`` (``paper_form=True``
drops ``log2(e)`` as the paper prints it, MODEL.md §2); the threshold G_th is the root of
``R(G) = R_th`` on the increasing branch (``blocklength=inf``: ``2^R_th - 1``). The MMSE CE error
is treated as noise: ``G_eff = (1-rho) beta |h|^2 p / (rho beta p + sigma^2)``.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import llvmlite.binding
import numba
import numpy as np
import numpy.typing as npt
from numba.extending import get_cython_function_address

from .rate import LOG2E, fbl_rate, ibl_rate, rate_turning_point, snr_threshold

if TYPE_CHECKING:
    from .config import ScenarioConfig

__all__ = [
    "LOG2E",
    "LinkParams",
    "fbl_rate",
    "ibl_rate",
    "rate_turning_point",
    "snr_threshold",
    "success_and_gradients",
    "sample_normalized_fading",
    "distance_sq",
    "POWER_FLOOR_W",
    "link_distance_sq",
    "link_argument",
    "outage_law",
    "command_delivered",
    "OUTAGE",
    "SUCCESS",
    "DENSITY",
    "ORDER",
    "SERIES",
]


def _scipy_special(name: str) -> numba.types.ExternalFunction:
    """scipy's own compiled ``name(a, x)`` (the function its ufunc calls, so the same values) as a
    function the compiled code here can call. It is linked under a symbol name, not an address, so
    that a cached kernel still finds it in a new process."""
    symbol = f"lawn_scipy_{name}"
    llvmlite.binding.add_symbol(symbol, get_cython_function_address("scipy.special.cython_special", name))
    f8 = numba.types.float64
    return numba.types.ExternalFunction(symbol, f8(f8, f8))


_GAMMAINC = _scipy_special("gammainc")
_GAMMAINCC = _scipy_special("gammaincc")
_GAMMALN = numba.types.ExternalFunction("lawn_scipy_gammaln", numba.types.float64(numba.types.float64))
llvmlite.binding.add_symbol("lawn_scipy_gammaln", get_cython_function_address("scipy.special.cython_special",
                                                                              "gammaln"))

#: What :func:`outage_law` returns: the outage probability, the success probability, the density,
#: the high-SNR order; and SERIES, the success probability in Erlang's closed form for integer m.
OUTAGE, SUCCESS, DENSITY, ORDER, SERIES = 0, 1, 2, 3, 4
#: SERIES is Erlang's closed form for integer m up to this and x below :data:`SERIES_MAX_X` (where e^-x
#: is a normal number), SUCCESS's value elsewhere.
SERIES_MAX_M = 64.0
SERIES_MAX_X = 700.0

#: Powers are floored here before dividing; gammainc(m, x) is exactly 1.0 in double precision
#: at that floor for any geometry, so p = 0 means outage probability 1 without inf/NaN.
POWER_FLOOR_W = 1e-300


@numba.njit(cache=True)
def link_distance_sq(dx: float, dy: float, altitude_sq: float) -> float:  # pragma: no cover - compiled
    """d^2 = (dx^2 + dy^2) + H^2 for the horizontal offset (dx, dy) m between drone and AGV."""
    return (dx * dx + dy * dy) + altitude_sq


@numba.njit(cache=True)
def link_argument(distance_sq_m2: float, power_w: float, c_d: float, c_ce: float) -> float:  # pragma: no cover
    """The outage argument x = c_d d^2 / (p + POWER_FLOOR_W) + c_ce of one link (Prop. 1, with the
    coefficients of :attr:`LinkParams.coefficients`). The floor keeps p = 0 finite: x ~ 1e295,
    gammainc(m, x) == 1.0 exactly."""
    x = distance_sq_m2 * c_d / (power_w + POWER_FLOOR_W)
    return x + c_ce if c_ce != 0.0 else x


@numba.njit(cache=True)
def outage_law(m: float, x: float, part: int) -> float:  # pragma: no cover - compiled
    """The outage law of one link at the outage argument x (Prop. 1): ``part`` OUTAGE gives
    ``P = Pr(m |h|^2 < x) = gammainc(m, x)``, SUCCESS psi = 1 - P = gammaincc(m, x) (accurate when
    psi is tiny, where 1 - P has no digits left), DENSITY -d psi / dx = x^(m-1) e^(-x) / Gamma(m)
    (in log form, accurate for large x), ORDER the exponent a of its high-SNR form P ∝ x^a
    (P ~ x^m / Gamma(m+1) as x -> 0: the diversity order m, which the stake prior's closed form
    uses), and SERIES the success probability again, in Erlang's closed form ``e^-x sum_{j<m} x^j / j!``
    for integer m (all terms positive, summed in ascending j): within 2e-13 of SUCCESS (a test checks)
    and about 13 times faster (``python benchmarks/expert_decisions.py --link-law``), what ``dv-mpc``'s
    compiled search evaluates its thousands of links with (:mod:`agents.search`; every other caller reads
    SUCCESS, so their decisions keep scipy's last bit). The five are one law: they change together."""
    scipy: float  # what scipy's compiled functions return (numba's external functions, untyped to mypy)
    if part == OUTAGE:
        scipy = _GAMMAINC(m, x)
        return scipy
    if part == SUCCESS:
        scipy = _GAMMAINCC(m, x)
        return scipy
    if part == SERIES:
        if m > SERIES_MAX_M or x >= SERIES_MAX_X or m != math.floor(m):
            scipy = _GAMMAINCC(m, x)
            return scipy
        term = 1.0
        total = 1.0
        for j in range(1, int(m)):
            term *= x / j
            total += term
        return math.exp(-x) * total
    if part == ORDER:
        return m
    if m == 1.0:
        log_x = 0.0
    elif x == 0.0:  # x^(m-1) at 0 without log(0)'s floating-point flag (numpy would warn of it)
        log_x = -math.inf if m > 1.0 else math.inf
    else:
        log_x = (m - 1.0) * math.log(x)
    return math.exp(log_x - x - _GAMMALN(m))


@numba.njit(cache=True)
def command_delivered(normalized_fading: float, x: float) -> bool:  # pragma: no cover - compiled
    """True where the command arrives: realized SNR >= G_th, i.e. ``m |h|^2 >= x``.

    ``G_eff >= G_th`` rearranges to ``|h|^2 >= G_th (rho + sigma^2 d^2/(alpha0 p)) / (1 - rho) = x / m``
    (a test computes the SNR itself and checks that the two forms agree). Comparing the SNR with
    G_th is comparing R(SNR) with R_th on the increasing branch; below the turning point
    R < 0 < R_th, also an outage."""
    return normalized_fading >= x


@numba.vectorize(["float64(float64, float64, int64)"], cache=True)
def _law_dufunc(m: float, x: float, part: int) -> float:  # pragma: no cover - compiled
    value: float = outage_law(m, x, part)
    return value


@numba.vectorize(["float64(float64, float64, float64, float64)"], cache=True)
def _argument_dufunc(  # pragma: no cover - compiled
    distance_sq_m2: float, power_w: float, c_d: float, c_ce: float,
) -> float:
    value: float = link_argument(distance_sq_m2, power_w, c_d, c_ce)
    return value


@numba.njit(cache=True)
def _distance_rows(diff: np.ndarray, altitude_sq: float, out: np.ndarray) -> None:  # pragma: no cover - compiled
    for i in range(diff.shape[0]):
        out[i] = link_distance_sq(diff[i, 0], diff[i, 1], altitude_sq)


# numpy's ufuncs of the compiled loops (numba's wrappers dispatch several times slower), as their callers call them
_law: Callable[[float, npt.ArrayLike, int], np.ndarray] = _law_dufunc.ufunc
_argument: Callable[[npt.ArrayLike, npt.ArrayLike, float, float], np.ndarray] = _argument_dufunc.ufunc


@dataclass(frozen=True)
class LinkParams:
    """Linear link parameters shared by the simulator and the planners, and every array form of
    the link's equations (the compiled functions above over any leading shape).

    ``snr_threshold`` is G_th; ``ce_error_var`` is rho (0 for perfect CSI).
    """

    snr_threshold: float
    alpha0: float
    noise_power_w: float
    m: int
    altitude_m: float
    ce_error_var: float = 0.0

    @classmethod
    def from_config(cls, config: ScenarioConfig, *, planning: bool = False) -> LinkParams:
        """Link of a :class:`~lawn_env.config.ScenarioConfig`.

        With ``planning=True`` and ``channel.ce_aware_planning=False`` the CE error is ignored
        (a CSI-unaware planner's model of the link).
        """
        ch = config.channel
        blocklength = math.inf if ch.infinite_blocklength else ch.blocklength
        rho = ch.ce_error_var if (ch.ce_aware_planning or not planning) else 0.0
        threshold = 0.0 if ch.perfect_links else snr_threshold(ch.rate_threshold_bps_hz, blocklength, ch.bler,
                                                                ch.paper_rate_form)
        return cls(
            snr_threshold=threshold,
            alpha0=ch.alpha0,
            noise_power_w=ch.noise_power_w,
            m=ch.nakagami_m,
            altitude_m=config.drone.altitude_m,
            ce_error_var=rho,
        )

    @functools.cached_property
    def coefficients(self) -> tuple[float, float]:
        """(c_d, c_ce) of :func:`link_argument`: c_d = m G_th sigma^2 / (alpha0 (1 - rho)),
        c_ce = m G_th rho / (1 - rho), the part of x that power cannot remove."""
        scale = self.m * self.snr_threshold / (1.0 - self.ce_error_var)
        return scale * self.noise_power_w / self.alpha0, scale * self.ce_error_var

    @functools.cached_property
    def constants(self) -> np.ndarray:
        """(m, c_d, c_ce, H^2): the link as the planners' compiled searches read it (``agents.search``)."""
        c_d, c_ce = self.coefficients
        return np.array([float(self.m), c_d, c_ce, self.altitude_sq])

    @functools.cached_property
    def altitude_sq(self) -> float:
        return self.altitude_m * self.altitude_m

    def distance_sq(self, drone_xy: npt.ArrayLike, agv_xy: npt.ArrayLike) -> np.ndarray:
        """Squared 3-D distances d^2 (m^2) from the drone at ``drone_xy`` to the AGVs at ``agv_xy``
        (both (..., 2), broadcasting): :func:`link_distance_sq` over arrays."""
        return _offsets_distance_sq(np.asarray(agv_xy, dtype=float) - drone_xy, self.altitude_sq)

    def outage_argument_sq(self, power_w: npt.ArrayLike, distance_sq_m2: npt.ArrayLike) -> np.ndarray:
        """x of Prop. 1 at powers (W) and squared distances (m^2): :func:`link_argument` over arrays."""
        c_d, c_ce = self.coefficients
        return _argument(distance_sq_m2, power_w, c_d, c_ce)

    def outage_at(self, x: npt.ArrayLike) -> np.ndarray:
        """Outage probability at outage arguments ``x`` (:func:`outage_law`)."""
        return _law(float(self.m), x, OUTAGE)

    def success_at(self, x: npt.ArrayLike) -> np.ndarray:
        """Success probability psi at outage arguments ``x`` (:func:`outage_law`; accurate when tiny)."""
        return _law(float(self.m), x, SUCCESS)

    def outage_sq(self, power_w: npt.ArrayLike, distance_sq_m2: npt.ArrayLike) -> np.ndarray:
        """Outage probability at powers (W) and squared distances (m^2)."""
        return self.outage_at(self.outage_argument_sq(power_w, distance_sq_m2))

    def success_sq(self, power_w: npt.ArrayLike, distance_sq_m2: npt.ArrayLike) -> np.ndarray:
        """Success probability psi at powers (W) and squared distances (m^2): what every planner plans
        with (``LinkParams.from_config(config, planning=True)``)."""
        return self.success_at(self.outage_argument_sq(power_w, distance_sq_m2))

    def success_slope_term(self, x: np.ndarray | float) -> np.ndarray:
        """g = (-d psi / dx) (x - x_ce) >= 0 at outage arguments ``x``: d psi/dp = g / p and
        d psi/d(d^2) = -g / d^2 (x falls with p and grows with d^2; x_ce is the part power cannot remove)."""
        return _law(float(self.m), x, DENSITY) * (x - self.coefficients[1])

    def success_power_slope(self, x: np.ndarray | float, power_w: npt.ArrayLike) -> np.ndarray:
        """d psi / d p (1/W) at outage arguments ``x`` of powers ``power_w`` (floored at
        ``POWER_FLOOR_W`` as the arguments were)."""
        return self.success_slope_term(x) / power_w

    def stake_power_weights(self, stake: np.ndarray, distance_sq_m2: np.ndarray) -> np.ndarray:
        """The power split that minimizes the expected loss ``sum_k w_k P_k`` over a fixed budget in
        the high-SNR regime of :func:`outage_law`, ``P ∝ x^a ∝ (d^2 / p)^a`` (a its ORDER, m for
        Nakagami-m): the Lagrange condition gives ``p_k ∝ (w_k d_k^(2a))^(1/(a+1))``. Weights
        (..., K) for stakes ``w`` > 0 and squared distances (..., K), computed in logs (``d^(2a)``
        overflows for large a) and scaled so that the largest is 1."""
        m: float = outage_law(float(self.m), 0.0, ORDER)
        log_w: np.ndarray = (np.log(stake) + m * np.log(distance_sq_m2)) / (m + 1.0)
        weights: np.ndarray = np.exp(log_w - log_w.max(axis=-1, keepdims=True))
        return weights


def distance_sq(drone_xy: np.ndarray, agv_xy: np.ndarray, altitude_m: float) -> np.ndarray:
    """Squared 3-D distance d^2 = ||q - c||^2 + H^2, m^2 (broadcasts over leading axes)."""
    return _offsets_distance_sq(np.asarray(agv_xy, dtype=float) - drone_xy, altitude_m * altitude_m)


def _offsets_distance_sq(diff: np.ndarray, altitude_sq: float) -> np.ndarray:
    """:func:`link_distance_sq` of every horizontal offset of ``diff`` (..., 2) (a new array, so
    contiguous), in one compiled loop; a float for one offset."""
    out = np.empty(diff.shape[:-1])
    _distance_rows(diff.reshape(-1, 2), altitude_sq, out.reshape(-1))
    return out if out.ndim else out[()]


def success_and_gradients(power_w: npt.ArrayLike, drone_xy: npt.ArrayLike, agv_xy: npt.ArrayLike,
                          link: LinkParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """psi, d psi / d p (1/W) and d psi / d q (1/m, shape (..., 2)) for each link.

    ``drone_xy`` broadcasts against ``agv_xy`` (..., 2). With dx/dp = -(x - x_ce)/p and
    dx/d(d^2) = (x - x_ce)/d^2 (:meth:`LinkParams.success_slope_term`). At p = 0 (floored at
    ``POWER_FLOOR_W``) psi and both derivatives are 0.
    """
    diff = np.asarray(drone_xy, dtype=float) - np.asarray(agv_xy, dtype=float)
    d2 = _offsets_distance_sq(diff, link.altitude_sq)
    p = np.maximum(power_w, POWER_FLOOR_W)
    x = link.outage_argument_sq(p, d2)
    g = link.success_slope_term(x)
    return link.success_at(x), g / p, (-2.0 * g / d2)[..., None] * diff


def sample_normalized_fading(rng: np.random.Generator, m: float, size: int | tuple[int, ...]) -> np.ndarray:
    """``m |h|^2 ~ Gamma(m, 1)``: the Nakagami-m fading power gain on the scale of the outage
    argument x (unit-mean ``|h|^2`` times m)."""
    return rng.standard_gamma(m, size)
