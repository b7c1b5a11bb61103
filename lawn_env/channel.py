"""Short-packet drone-to-AGV link with Nakagami-m fading (MODEL.md §2).

Functions vectorized over any leading shape; the link's two scalar equations (the squared
distance, the outage argument) are compiled once (:func:`link_distance_sq`, :func:`link_argument`)
and used both by the simulation's slot kernel and, as ufuncs, by every array function here. All
functions take *linear*
quantities (power in W, gain as a ratio); the config's dB values are converted by
:class:`LinkParams`. Distances are 3-D drone–AGV distances in m.

Equations
---------
* FBL rate (Polyanskiy–Poor–Verdú normal approximation), bit/s/Hz:
  ``R(G) = log2(1+G) - sqrt(V/l) Q^{-1}(eps) log2(e)``, ``V = 1 - (1+G)^{-2}``.
  ``paper_form=True`` drops ``log2(e)`` as the paper prints it (a units slip, MODEL.md §2).
* SNR threshold: the root of ``R(G) = R_th`` on the increasing branch, found by bracketed root
  finding above the closed-form turning point, cached per ``(R_th, l, eps, paper_form)``.
  ``blocklength=inf`` gives the IBL threshold ``2^R_th - 1``.
* Outage (Prop. 1): ``P = gammainc(m, x)`` (regularized lower incomplete gamma) with
  ``x = m G_th (rho + d^2 sigma^2 / (alpha0 p)) / (1 - rho)``; for perfect CSI (rho = 0) this is
  ``x = m g``, ``g = d^2 G_th sigma^2 / (alpha0 p)``. ``p = 0`` gives ``P = 1``.
  The MMSE CE error is treated as noise: ``G_eff = (1-rho) beta |h|^2 p / (rho beta p + sigma^2)``.
* Success ``psi = 1 - P = gammaincc(m, x)``, with derivatives in log form.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numba
import numpy as np
import numpy.typing as npt
from scipy import special

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
    "outage_probability",
    "success_probability",
    "success_and_gradients",
    "gamma_density",
    "outage_argument",
    "outage_argument_sq",
    "delivered_from_fading",
    "sample_normalized_fading",
    "realized_snr",
    "sample_fading",
    "sample_delivery",
    "distance_sq",
    "POWER_FLOOR_W",
    "link_distance_sq",
    "link_argument",
]

@dataclass(frozen=True)
class LinkParams:
    """Linear link parameters shared by the simulator and the planners.

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
        """(c_d, c_ce) with the outage argument x = c_d d^2 / p + c_ce (see :func:`outage_argument_sq`)."""
        return _outage_coefficients(self.snr_threshold, self.alpha0, self.noise_power_w, self.m, self.ce_error_var)

    # ------------------------------------------------------------------ the one home of psi
    # Every view of the link (the simulator, the vector envs, the planners, the RL interface's
    # anchor) computes distances, outage and success probabilities and their slopes here.
    @functools.cached_property
    def altitude_sq(self) -> float:
        return self.altitude_m * self.altitude_m

    def distance_sq(self, drone_xy: npt.ArrayLike, agv_xy: npt.ArrayLike) -> np.ndarray:
        """Squared 3-D distances d^2 = ||c - q||^2 + H^2 (m^2) from the drone at ``drone_xy`` to the
        AGVs at ``agv_xy`` (both (..., 2), broadcasting; :func:`distance_sq` for this altitude)."""
        return _distance_sq(drone_xy, agv_xy, self.altitude_sq)

    def outage_argument_sq(self, power_w: npt.ArrayLike, distance_sq_m2: npt.ArrayLike) -> np.ndarray:
        """x of Prop. 1 for this link (fast path of :func:`outage_argument_sq`)."""
        c_d, c_ce = self.coefficients
        return _outage_argument(power_w, distance_sq_m2, c_d, c_ce)

    def outage_at(self, x: npt.ArrayLike) -> np.ndarray:
        """Outage probability gammainc(m, x) at outage arguments ``x``."""
        return special.gammainc(self.m, x)

    def success_at(self, x: npt.ArrayLike) -> np.ndarray:
        """Success probability psi = gammaincc(m, x) at outage arguments ``x`` (accurate when tiny)."""
        return special.gammaincc(self.m, x)

    def outage_sq(self, power_w: npt.ArrayLike, distance_sq_m2: npt.ArrayLike) -> np.ndarray:
        """Outage probability at powers (W) and squared distances (m^2)."""
        return self.outage_at(self.outage_argument_sq(power_w, distance_sq_m2))

    def success_sq(self, power_w: npt.ArrayLike, distance_sq_m2: npt.ArrayLike) -> np.ndarray:
        """Success probability psi at powers (W) and squared distances (m^2): what every planner plans
        with (``LinkParams.from_config(config, planning=True)``)."""
        return self.success_at(self.outage_argument_sq(power_w, distance_sq_m2))

    def success_slope_term(self, x: npt.ArrayLike) -> np.ndarray:
        """g = x^(m-1) e^(-x) / Gamma(m) (x - x_ce) >= 0 at outage arguments ``x``: d psi/dp = g / p and
        d psi/d(d^2) = -g / d^2 (x falls with p and grows with d^2; x_ce is the part power cannot remove)."""
        return gamma_density(self.m, x) * (x - self.coefficients[1])

    def success_power_slope(self, x: npt.ArrayLike, power_w: npt.ArrayLike) -> np.ndarray:
        """d psi / d p (1/W) at outage arguments ``x`` of powers ``power_w`` (floored at
        ``POWER_FLOOR_W`` as the arguments were)."""
        return self.success_slope_term(x) / power_w

    @functools.cached_property
    def kwargs(self) -> dict:
        """The link as keyword arguments of the module-level functions (:func:`outage_probability`, ...)."""
        return dict(
            snr_threshold=self.snr_threshold,
            alpha0=self.alpha0,
            noise_power_w=self.noise_power_w,
            m=self.m,
            ce_error_var=self.ce_error_var,
        )


def distance_sq(drone_xy: np.ndarray, agv_xy: np.ndarray, altitude_m: float) -> np.ndarray:
    """Squared 3-D distance d^2 = ||q - c||^2 + H^2, m^2 (broadcasts over leading axes)."""
    return _distance_sq(drone_xy, agv_xy, altitude_m * altitude_m)


def _distance_sq(drone_xy: npt.ArrayLike, agv_xy: npt.ArrayLike, altitude_sq: float) -> np.ndarray:
    return _offsets_distance_sq(np.asarray(agv_xy, dtype=float) - drone_xy, altitude_sq)


def _offsets_distance_sq(diff: np.ndarray, altitude_sq: float) -> np.ndarray:
    """:func:`link_distance_sq` of every horizontal offset of ``diff`` (..., 2) (a new array, so
    contiguous), in one compiled loop; a float for one offset."""
    out = np.empty(diff.shape[:-1])
    _distance_rows(diff.reshape(-1, 2), altitude_sq, out.reshape(-1))
    return out if out.ndim else out[()]


#: Powers are floored here before dividing; gammainc(m, x) is exactly 1.0 in double precision
#: at that floor for any geometry, so p = 0 means outage probability 1 without inf/NaN.
POWER_FLOOR_W = 1e-300


@numba.njit(cache=True)
def link_distance_sq(dx: float, dy: float, altitude_sq: float) -> float:  # pragma: no cover - compiled
    """d^2 = (dx^2 + dy^2) + H^2 for the horizontal offset (dx, dy) m between drone and AGV: the
    one place of this equation (the slot kernel calls it; :func:`distance_sq` runs it over arrays)."""
    return (dx * dx + dy * dy) + altitude_sq


@numba.njit(cache=True)
def link_argument(distance_sq_m2: float, power_w: float, c_d: float, c_ce: float) -> float:  # pragma: no cover
    """The outage argument x = c_d d^2 / (p + POWER_FLOOR_W) + c_ce of one link: the one place of this
    equation (the slot kernel calls it; :func:`outage_argument_sq` is its ufunc). The floor keeps
    p = 0 finite: x ~ 1e295, gammainc(m, x) == 1.0 exactly."""
    x = distance_sq_m2 * c_d / (power_w + POWER_FLOOR_W)
    return x + c_ce if c_ce != 0.0 else x


@numba.njit(cache=True)
def _distance_rows(diff, altitude_sq, out):  # pragma: no cover - compiled
    for i in range(diff.shape[0]):
        out[i] = link_distance_sq(diff[i, 0], diff[i, 1], altitude_sq)


@numba.vectorize(["float64(float64, float64, float64, float64)"], cache=True)
def _argument_dufunc(distance_sq_m2, power_w, c_d, c_ce):  # pragma: no cover - compiled
    return link_argument(distance_sq_m2, power_w, c_d, c_ce)


_argument_ufunc = _argument_dufunc.ufunc  # numpy's ufunc of the compiled loop (numba's wrapper dispatches slower)


def _outage_coefficients(snr_threshold, alpha0, noise_power_w, m, ce_error_var):
    """(c_d, c_ce) with x = c_d d^2 / p + c_ce: c_d = m G_th sigma^2 / (alpha0 (1 - rho)), c_ce = m G_th rho / (1 - rho)."""
    scale = m * snr_threshold / (1.0 - ce_error_var)
    return scale * noise_power_w / alpha0, scale * ce_error_var


def outage_argument_sq(power_w: npt.ArrayLike, distance_sq_m2: npt.ArrayLike, *, snr_threshold: float, alpha0: float,
                       noise_power_w: float, m: float, ce_error_var: float = 0.0) -> np.ndarray:
    """x of Prop. 1 from the squared distance: x = m G_th (rho + d^2 sigma^2 / (alpha0 p)) / (1 - rho).

    ``Pr(outage) = Pr(|h|^2 < x / m) = gammainc(m, x)`` since ``m |h|^2 ~ Gamma(m, 1)``.
    """
    c_d, c_ce = _outage_coefficients(snr_threshold, alpha0, noise_power_w, m, ce_error_var)
    return _outage_argument(power_w, distance_sq_m2, c_d, c_ce)


def _outage_argument(power_w, distance_sq_m2, c_d: float, c_ce: float):
    return _argument_ufunc(distance_sq_m2, power_w, c_d, c_ce)


def outage_argument(power_w: npt.ArrayLike, distance_m: npt.ArrayLike, *, snr_threshold: float, alpha0: float,
                    noise_power_w: float, m: float, ce_error_var: float = 0.0) -> np.ndarray:
    """The incomplete-gamma argument x of Prop. 1 (``x = m g`` for perfect CSI)."""
    return outage_argument_sq(power_w, np.square(distance_m), snr_threshold=snr_threshold, alpha0=alpha0,
                              noise_power_w=noise_power_w, m=m, ce_error_var=ce_error_var)


def outage_probability(power_w: npt.ArrayLike, distance_m: npt.ArrayLike, *, snr_threshold: float, alpha0: float,
                       noise_power_w: float, m: float, ce_error_var: float = 0.0) -> np.ndarray:
    """Outage probability Pr(G < G_th) = gammainc(m, x) (Prop. 1, MODEL.md §2).

    Evaluated with the regularized incomplete gamma function, accurate for tiny outage (the
    paper's ``1 - e^{-mg} sum ...`` form loses all digits there). ``p = 0`` gives 1.
    """
    x = outage_argument(
        power_w, distance_m, snr_threshold=snr_threshold, alpha0=alpha0,
        noise_power_w=noise_power_w, m=m, ce_error_var=ce_error_var,
    )
    return special.gammainc(m, x)


def success_probability(power_w: npt.ArrayLike, distance_m: npt.ArrayLike, *, snr_threshold: float, alpha0: float,
                        noise_power_w: float, m: float, ce_error_var: float = 0.0) -> np.ndarray:
    """psi = 1 - P = gammaincc(m, x), accurate also when psi is tiny."""
    x = outage_argument(
        power_w, distance_m, snr_threshold=snr_threshold, alpha0=alpha0,
        noise_power_w=noise_power_w, m=m, ce_error_var=ce_error_var,
    )
    return special.gammaincc(m, x)


def gamma_density(m: float, x: npt.ArrayLike) -> np.ndarray:
    """x^(m-1) e^(-x) / Gamma(m) = -d psi / dx, in log form (accurate for large x)."""
    return np.exp(special.xlogy(m - 1, x) - x - special.gammaln(m))


def success_and_gradients(power_w: npt.ArrayLike, drone_xy: npt.ArrayLike, agv_xy: npt.ArrayLike,
                          link: LinkParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """psi, d psi / d p (1/W) and d psi / d q (1/m, shape (..., 2)) for each link.

    ``drone_xy`` broadcasts against ``agv_xy`` (..., 2). The derivatives use the log form of the
    Gamma density, d psi/dx = -x^(m-1) e^(-x) / Gamma(m), with dx/dp = -(x - x_ce)/p and
    dx/d(d^2) = (x - x_ce)/d^2. At p = 0 (floored at ``POWER_FLOOR_W``) psi and both derivatives are 0.
    """
    diff = np.asarray(drone_xy, dtype=float) - np.asarray(agv_xy, dtype=float)
    d2 = _offsets_distance_sq(diff, link.altitude_sq)
    p = np.maximum(power_w, POWER_FLOOR_W)
    x = link.outage_argument_sq(p, d2)
    g = link.success_slope_term(x)
    return link.success_at(x), g / p, (-2.0 * g / d2)[..., None] * diff


def realized_snr(power_w: npt.ArrayLike, distance_m: npt.ArrayLike, fading: npt.ArrayLike, *, alpha0: float,
                 noise_power_w: float, ce_error_var: float = 0.0) -> np.ndarray:
    """Effective SNR for fading power gains ``fading`` = ``|h|^2`` (MMSE CE error as noise)."""
    beta_p = alpha0 / np.square(distance_m) * np.asarray(power_w, dtype=float)
    return (1.0 - ce_error_var) * beta_p * fading / (ce_error_var * beta_p + noise_power_w)


def sample_fading(rng: np.random.Generator, m: float, size: int | tuple[int, ...]) -> np.ndarray:
    """Nakagami-m power gains ``|h|^2 ~ Gamma(shape m, scale 1/m)`` (unit mean)."""
    return rng.standard_gamma(m, size) / m


def sample_normalized_fading(rng: np.random.Generator, m: float, size: int | tuple[int, ...]) -> np.ndarray:
    """``m |h|^2 ~ Gamma(m, 1)``: the fading on the scale of the outage argument x.

    The same draws as :func:`sample_fading` times m (one generator call, one fewer operation)."""
    return rng.standard_gamma(m, size)


def delivered_from_fading(normalized_fading: npt.ArrayLike, outage_arg: npt.ArrayLike) -> np.ndarray:
    """True where the command arrives: realized SNR >= G_th, i.e. ``m |h|^2 >= x``.

    ``G_eff >= G_th`` rearranges to ``|h|^2 >= G_th (rho + sigma^2 d^2/(alpha0 p)) / (1 - rho) = x / m``
    (:func:`realized_snr` computes the SNR itself; a test checks that the two forms agree).
    Comparing the SNR with G_th is equivalent to comparing R(SNR) with R_th on the increasing
    branch; below the turning point R < 0 < R_th, also an outage.
    """
    return normalized_fading >= outage_arg


def sample_delivery(rng: np.random.Generator, power_w: npt.ArrayLike, distance_m: npt.ArrayLike,
                    link: LinkParams) -> np.ndarray:
    """Draw Nakagami-m fading and return True where the command arrives (MODEL.md §2)."""
    distance_m = np.asarray(distance_m, dtype=float)
    x = link.outage_argument_sq(power_w, np.square(distance_m))
    return delivered_from_fading(sample_normalized_fading(rng, link.m, x.shape), x)
