import math

import numpy as np
import pytest
from scipy import special, stats

from lawn_env import ScenarioConfig, channel, presets
from lawn_env.channel import LinkParams


@pytest.mark.parametrize("paper_form", [False, True])
@pytest.mark.parametrize("blocklength", [64, 256, 1024, 8192])
@pytest.mark.parametrize("rate", [0.1, 1.0, 4.0, 10.0])
def test_rate_at_threshold_equals_rate(rate, blocklength, paper_form):
    g = channel.snr_threshold(rate, blocklength, 1e-6, paper_form)
    assert float(channel.fbl_rate(g, blocklength, 1e-6, paper_form)) == pytest.approx(rate, rel=1e-12, abs=1e-12)
    # increasing branch: above the turning point
    assert g > channel.rate_turning_point(blocklength, 1e-6, paper_form)


@pytest.mark.parametrize("paper_form", [False, True])
def test_turning_point_is_the_minimum(paper_form):
    g0 = channel.rate_turning_point(1024, 1e-6, paper_form)
    grid = g0 * np.array([0.9, 0.99, 1.0, 1.01, 1.1])
    r = channel.fbl_rate(grid, 1024, 1e-6, paper_form)
    assert np.argmin(r) == 2 and r[2] < 0


def test_log2e_factor():
    # the dispersion term of the correct form is log2(e) times the paper's printed one
    g, l, eps = 5.0, 1024, 1e-6
    gap_ok = math.log2(1 + g) - float(channel.fbl_rate(g, l, eps))
    gap_paper = math.log2(1 + g) - float(channel.fbl_rate(g, l, eps, paper_form=True))
    assert gap_ok / gap_paper == pytest.approx(1 / math.log(2))
    assert gap_paper == pytest.approx(math.sqrt((1 - (1 + g) ** -2) / l) * stats.norm.isf(eps))


def test_infinite_blocklength_limit():
    rate = 6.0
    ibl = channel.snr_threshold(rate, math.inf, 1e-6)
    assert ibl == pytest.approx(2**rate - 1)
    thresholds = [channel.snr_threshold(rate, l, 1e-6) for l in (256, 1024, 2**14, 2**20, 2**30)]
    assert all(a > b for a, b in zip(thresholds, thresholds[1:]))  # longer blocks need less SNR
    assert thresholds[-1] == pytest.approx(ibl, rel=1e-3)
    snr = np.logspace(-1, 3, 9)
    assert np.allclose(channel.fbl_rate(snr, 2**40, 1e-6), channel.ibl_rate(snr), atol=1e-4)
    assert np.allclose(channel.fbl_rate(snr, math.inf, 1e-6), np.log2(1 + snr))


def test_bad_threshold_arguments():
    with pytest.raises(ValueError, match="rate"):
        channel.snr_threshold(-1.0, 1024, 1e-6)
    with pytest.raises(ValueError, match="bler"):
        channel.snr_threshold(1.0, 1024, 2.0)
    with pytest.raises(ValueError, match="blocklength"):
        channel.snr_threshold(1.0, 0, 1e-6)


def _link(m=2, rho=0.0, rate=None):
    # CE error caps the SINR at (1 - rho) / rho |h|^2: at R_th = 10 (G_th ~ 1187) rho = 1e-3 already
    # floors outage at 0.69 whatever the power, so CE cases use the paper's R_th = 1 (MODEL.md §8)
    rate = rate if rate is not None else (1.0 if rho > 0 else 10.0)
    cfg = ScenarioConfig(channel=dict(nakagami_m=m, ce_error_var=rho, rate_threshold_bps_hz=rate))
    return LinkParams.from_config(cfg)


def _outage(link, power_w, distance_m):
    return link.outage_sq(power_w, np.square(np.asarray(distance_m, dtype=float)))


@pytest.mark.parametrize(
    "m, rho, target",
    [(1, 0.0, 0.002), (2, 0.0, 0.01), (2, 0.0, 0.3), (2, 0.0, 0.9), (3, 0.0, 0.05), (2, 0.05, 0.2)],
)
def test_outage_closed_form_matches_monte_carlo(m, rho, target):
    """Closed form (Prop. 1) against the frequency of the simulator's own fading sampler."""
    link = _link(m, rho)
    dist = 80.0
    # find the power giving the target outage, then sample deliveries at that power
    from scipy.optimize import brentq

    power = brentq(lambda p: _outage(link, p, dist) - target, 1e-12, 1e6)
    p_closed = float(_outage(link, power, dist))
    n = 400_000
    x = float(link.outage_argument_sq(power, dist**2))
    fading = channel.sample_normalized_fading(np.random.default_rng(7), link.m, n)
    delivered = np.vectorize(channel.command_delivered, otypes=[bool])(fading, x)  # the kernel's rule
    p_mc = 1.0 - delivered.mean()
    sigma = math.sqrt(p_closed * (1 - p_closed) / n)
    assert abs(p_mc - p_closed) < 5 * sigma, (p_mc, p_closed, sigma)


def test_realized_snr_agrees_with_fading_threshold(rng):
    """The delivery rule m|h|^2 >= x against the realized SNR itself (MODEL.md §2, the MMSE CE error
    as noise: G_eff = (1-rho) beta |h|^2 p / (rho beta p + sigma^2), beta = alpha0 / d^2) and the rate."""
    link = _link(2, 0.03)
    power = rng.uniform(0.01, 1.0, 10_000)
    dist = rng.uniform(50, 250, 10_000)
    g = channel.sample_normalized_fading(rng, link.m, power.shape)
    x = link.outage_argument_sq(power, dist**2)
    via_threshold = np.array([channel.command_delivered(gi, xi) for gi, xi in zip(g, x)])
    beta_p = link.alpha0 / dist**2 * power
    rho = link.ce_error_var
    snr = (1.0 - rho) * beta_p * (g / link.m) / (rho * beta_p + link.noise_power_w)
    rate = channel.fbl_rate(snr, 1024, 1e-6)
    via_rate = rate >= 1.0  # _link's R_th when rho > 0
    mismatch = via_threshold != via_rate
    # the two forms can differ only at the threshold itself (rounding), never in bulk
    assert mismatch.sum() <= 2
    assert via_threshold.mean() == pytest.approx(1 - _outage(link, power, dist).mean(), abs=0.02)


def test_outage_accurate_for_tiny_values():
    link = presets.get("paper-nominal")
    params = LinkParams.from_config(link)
    p = float(_outage(params, 0.25, 60.0))
    x = float(params.outage_argument_sq(0.25, 60.0**2))
    # series for m = 2: P = 1 - e^-x (1 + x) = x^2/2 - x^3/3 + ...
    assert p == pytest.approx(x**2 / 2 - x**3 / 3 + x**4 / 8, rel=1e-9)
    # the paper's sum form 1 - e^-x (1 + x) cancels ~8 digits at these outages: a relative error
    # around 1e-9 (5.7e-10 here at P = 6.9e-8; 5e-9 at P = 1e-8), small but far above gammainc's
    naive = 1 - math.exp(-x) * (1 + x)
    assert 1e-10 < abs(naive - p) / p < 1e-8
    assert p == pytest.approx(x**2 / 2 - x**3 / 3 + x**4 / 8 - x**5 / 30, rel=1e-11)


def test_zero_power_means_outage_and_no_nan():
    link = _link()
    p = _outage(link, np.array([0.0, 0.5]), np.array([60.0, 60.0]))
    assert p[0] == 1.0 and 0 < p[1] < 1
    psi, dp, dq = channel.success_and_gradients(np.array([0.0, 0.5]), np.zeros(2), np.array([[30.0, 40.0]] * 2), link)
    assert psi[0] == 0.0 and dp[0] == 0.0 and np.all(dq[0] == 0.0)
    assert np.all(np.isfinite(dp)) and np.all(np.isfinite(dq))


@pytest.mark.parametrize("m, rho", [(1, 0.0), (2, 0.0), (4, 0.0), (2, 0.02)])
def test_gradients_match_finite_differences(m, rho, rng):
    link = _link(m, rho)
    power = rng.uniform(0.05, 0.6, 6)
    drone = rng.uniform(0, 200, (6, 2))
    agv = rng.uniform(0, 200, (6, 2))
    psi, dpsi_dp, dpsi_dq = channel.success_and_gradients(power, drone, agv, link)
    dist = np.sqrt(channel.distance_sq(drone, agv, link.altitude_m))
    x = ((dist**2) * link.m * link.snr_threshold * link.noise_power_w / link.alpha0 / power
         + link.m * link.snr_threshold * link.ce_error_var) / (1 - link.ce_error_var)  # Prop. 1 written out
    np.testing.assert_allclose(psi, special.gammaincc(m, x), rtol=1e-12)  # scipy, the oracle
    np.testing.assert_allclose(psi, 1 - _outage(link, power, dist), rtol=1e-9)
    h = 1e-6
    fd_p = (channel.success_and_gradients(power + h, drone, agv, link)[0]
            - channel.success_and_gradients(power - h, drone, agv, link)[0]) / (2 * h)
    assert np.allclose(dpsi_dp, fd_p, rtol=1e-5, atol=1e-9)
    for axis in range(2):
        e = np.zeros(2)
        e[axis] = 1e-4
        fd_q = (channel.success_and_gradients(power, drone + e, agv, link)[0]
                - channel.success_and_gradients(power, drone - e, agv, link)[0]) / 2e-4
        assert np.allclose(dpsi_dq[:, axis], fd_q, rtol=1e-5, atol=1e-9)


def test_gammainc_form_equals_paper_sum_where_both_are_accurate():
    x = np.linspace(0.5, 8, 20)
    for m in (1, 2, 3, 5):
        paper = 1 - np.exp(-x) * sum(x**i / math.factorial(i) for i in range(m))
        assert np.allclose(special.gammainc(m, x), paper, rtol=1e-10)


def test_regimes_of_model_md_section_8():
    """Nominal point: outage 1e-8 .. 1e-6 everywhere; default: a visible range (MODEL.md §8)."""
    grid = np.stack(np.meshgrid(np.linspace(0, 200, 21), np.linspace(0, 200, 21)), -1).reshape(-1, 2)
    drone = np.array([100.0, 100.0])
    corners = np.array([[0.0, 0.0], [200.0, 200.0]])
    dmax = float(np.sqrt(channel.distance_sq(corners[0], corners[1], 50.0)))
    nominal = LinkParams.from_config(presets.get("paper-nominal"))
    equal = 1.0 / 4
    worst = _outage(nominal, equal, dmax)  # corner to corner: 3.6e-5
    best = _outage(nominal, equal, 50.0)  # straight above: 3.3e-8
    from_center = _outage(nominal, equal, np.sqrt(channel.distance_sq(drone, grid, 50.0)))
    assert 1e-8 < best < worst < 1e-4
    assert from_center.max() < 3e-6  # a drone anywhere central keeps every link at ~1e-6 or better
    default = LinkParams.from_config(presets.get("default"))
    d = np.sqrt(channel.distance_sq(drone, grid, 50.0))
    p = _outage(default, equal, d)
    assert p.min() < 0.05 and p.max() > 0.5  # outage matters at the default point: 0.024 .. 0.63


def test_ce_floor_makes_outage_power_independent_at_0_dbw():
    """MODEL.md §8: at R_th = 1 and 0 dBW the CE error's floor dominates (rho = 0.1: outage 3.4-4.2 %
    whatever the power from P/16 to P and the distance from 50 to 287 m), while at -30 dBW power
    and distance move the outage by more than a factor of 2 (the CE figure's regime)."""
    d = np.linspace(50.0, 287.0, 12)
    for budget, spread in ((0.0, "floor"), (-30.0, "visible")):
        cfg = presets.get("paper-nominal").override(power_budget_dbw=budget, **{"channel.ce_error_var": 0.1})
        link = LinkParams.from_config(cfg)
        p_max = cfg.power_budget_w
        out = np.array([_outage(link, p, d) for p in (p_max / 16, p_max / 4, p_max)])
        if spread == "floor":
            assert out.min() > 0.033 and out.max() < 0.043
        else:
            assert out.max() > 2 * out.min()


def test_ce_error_floor_at_the_default_rate_threshold():
    """At R_th = 10 the CE error floors the outage at gammainc(m, m G_th rho / (1 - rho)): 0.69 at
    rho = 1e-3 even at full power straight above the AGV, practically 1 at rho = 1e-2."""
    for rho, low, high in ((1e-3, 0.68, 0.70), (1e-2, 1 - 1e-8, 1.0)):
        link = LinkParams.from_config(presets.get("default").override(**{"channel.ce_error_var": rho}))
        assert low <= _outage(link, 1.0, 50.0) <= high


def test_the_outage_law_is_scipys_gammainc_gammaincc_and_density():
    """:func:`lawn_env.channel.outage_law` (the kernel's and every array method's) against scipy, the
    oracle: gammainc and gammaincc bit for bit for integer m = 1..100 (and non-integer m), x = 0 and
    1e-300..1e3; the density x^(m-1) e^(-x) / Gamma(m) to rounding; the array methods equal the scalar."""
    xs = np.concatenate([[0.0], np.logspace(-300, 3, 400), [5e-324, 1e295]])
    law = channel.outage_law
    for m in [*range(1, 101), 0.5, 1.5, 2.75, 37.3]:
        np.testing.assert_array_equal([law(float(m), float(x), channel.OUTAGE) for x in xs], special.gammainc(m, xs),
                                      err_msg=f"m={m}")
        np.testing.assert_array_equal([law(float(m), float(x), channel.SUCCESS) for x in xs],
                                      special.gammaincc(m, xs), err_msg=f"m={m}")
        inner = xs[1:-1]
        np.testing.assert_allclose([law(float(m), float(x), channel.DENSITY) for x in inner],
                                   np.exp(special.xlogy(m - 1, inner) - inner - special.gammaln(m)), rtol=1e-12,
                                   atol=1e-300)
    assert law(2.0, 1e295, channel.OUTAGE) == 1.0 and law(2.0, 0.0, channel.OUTAGE) == 0.0
    link = _link(3)
    x = np.logspace(-5, 2, 50)
    np.testing.assert_array_equal(link.outage_at(x), [law(3.0, v, channel.OUTAGE) for v in x])
    np.testing.assert_array_equal(link.success_at(x), [law(3.0, v, channel.SUCCESS) for v in x])
    np.testing.assert_array_equal(link.success_slope_term(x), [law(3.0, v, channel.DENSITY) * v for v in x])


def test_erlangs_closed_form_is_scipys_gammaincc_to_rounding():
    """:func:`lawn_env.channel.outage_law`'s SERIES (dv-mpc's search's psi) against scipy: within 2e-13
    relative for integer m <= 64 and x < 700 (the conditioning of e^-x: 700 eps), scipy's value itself
    elsewhere (non-integer m, m > 64, x >= 700)."""
    xs = np.concatenate([[0.0], np.logspace(-300, np.log10(699.9), 300), np.linspace(0, 60, 200),
                         [700.0, 1e3, 1e295, np.inf]])
    for m in [*range(1, 70), 0.5, 2.75, 37.3]:
        series = np.array([channel.outage_law(float(m), float(x), channel.SERIES) for x in xs])
        exact = special.gammaincc(m, xs)
        inside = (float(m) == int(m)) & (m <= 64) & (xs < 700)
        np.testing.assert_allclose(series[inside], exact[inside], rtol=2e-13, atol=0, err_msg=f"m={m}")
        np.testing.assert_array_equal(series[~inside], exact[~inside], err_msg=f"m={m}")


def test_the_density_at_zero_is_exact_and_quiet():
    """At x = 0 (perfect links: G_th = 0) the density is scipy's value, 0 for m > 1 and 1 for m = 1,
    with no floating-point warning from log(0)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for m in (1.0, 2.0, 3.5):
            assert channel.outage_law(m, 0.0, channel.DENSITY) == np.exp(special.xlogy(m - 1, 0.0) - special.gammaln(m))
            assert np.all(_link(int(m)).success_slope_term(np.zeros(3)) == 0.0)


def test_compiled_link_equations_equal_the_array_forms():
    """The link's scalar equations (one source, compiled: the kernel's and the ufuncs') give the
    array formulas' values bit for bit: d^2 = (dx^2 + dy^2) + H^2 and x = d^2 c_d / (p + floor) + c_ce."""
    rng = np.random.default_rng(0)
    drone, agv = rng.uniform(-300, 300, (50, 2)), rng.uniform(-300, 300, (50, 4, 2))
    d2 = channel.distance_sq(drone[:, None], agv, 50.0)
    diff = agv - drone[:, None]
    np.testing.assert_array_equal(d2, (diff[..., 0] ** 2 + diff[..., 1] ** 2) + 2500.0)
    np.testing.assert_array_equal(d2[3, 1], channel.link_distance_sq(diff[3, 1, 0], diff[3, 1, 1], 2500.0))
    power = np.concatenate([rng.uniform(0, 1, 199), [0.0]])
    for rho in (0.0, 0.02):
        link = _link(2, rho)
        c_d, c_ce = link.coefficients
        x = link.outage_argument_sq(power, d2.ravel()[:200])
        reference = d2.ravel()[:200] * c_d / (power + channel.POWER_FLOOR_W) + c_ce
        np.testing.assert_array_equal(x, reference)
        assert channel.link_argument(d2.ravel()[7], power[7], c_d, c_ce) == x[7]
    assert np.isfinite(x[-1]) and special.gammainc(2.0, x[-1]) == 1.0  # p = 0: outage 1, no inf/NaN


def test_the_stake_split_minimizes_the_high_snr_expected_loss():
    """:meth:`LinkParams.stake_power_weights` solves min sum_k w_k (d_k^2 / p_k)^m over sum p = P
    (the outage law's high-SNR form): no feasible perturbation of the split lowers the loss."""
    link = _link(3)
    rng = np.random.default_rng(2)
    stake, d2 = rng.uniform(0.1, 5.0, 5), rng.uniform(2500.0, 40000.0, 5)
    w = link.stake_power_weights(stake, d2)
    p = w / w.sum()
    loss = lambda q: float(np.sum(stake * (d2 / q) ** link.m))  # noqa: E731
    assert w.max() == 1.0
    for _ in range(50):
        step = rng.normal(0, 1e-3, 5)
        q = p + step - step.mean()
        assert loss(q) >= loss(p) * (1 - 1e-12)
