"""The benchmark's cost structure, its statistics and its reference rows (docs/benchmark.md): the
transient/sustained split, the geometric paired comparison, the IQM aggregate, the headroom and
noise-floor rows, the tasks of suite v2."""

import math

import gymnasium as gym
import numpy as np
import pytest
from scipy import stats

import lawn_env
from evaluation.episode import TRANSIENT_SLOTS, EpisodeSpec
from evaluation.run import (
    LIMIT_SETTINGS,
    LIMITS,
    NOISE,
    REFERENCE_ROWS,
    build_policy,
    evaluate,
    limit_config,
    resolve,
    split_cost,
)
from evaluation.stats import aggregate_score, normalized_score, paired_difference, paired_geometric
from lawn_env import ScenarioConfig, presets


def _flat(tree: dict, prefix: str = "") -> dict:
    out = {}
    for key, value in tree.items():
        if isinstance(value, dict):
            out.update(_flat(value, f"{prefix}{key}."))
        else:
            out[prefix + key] = value
    return out


# ---------------------------------------------------------------------- the cost's structure
@pytest.mark.parametrize("env_id", list(lawn_env.ENV_IDS))
def test_transient_and_sustained_costs_add_up_to_the_episode_cost(env_id):
    rows = evaluate([EpisodeSpec("epa", env_id, ScenarioConfig(), 3, {}),
                     EpisodeSpec("rg-mpc", env_id, ScenarioConfig(), 3, {})], progress=False)
    for row in rows:
        stage = row.stage_costs
        assert len(stage) == 120 and row.transient_slots == TRANSIENT_SLOTS
        assert row.transient_cost == pytest.approx(sum(stage[:TRANSIENT_SLOTS]), rel=1e-12)
        assert row.transient_cost + row.sustained_cost == pytest.approx(row.control_cost, rel=1e-9)
        assert 0 < row.sustained_cost < row.control_cost
    other = evaluate([EpisodeSpec("epa", env_id, ScenarioConfig(), 3, {})], progress=False, transient_slots=5)[0]
    assert other.control_cost == rows[0].control_cost  # the split only reads the episode
    assert other.transient_cost < rows[0].transient_cost and other.transient_slots == 5


def test_split_cost_edges_and_errors():
    assert split_cost([1.0, 2.0, 3.0], 0) == (0.0, 6.0)
    assert split_cost([1.0, 2.0, 3.0], 2) == (3.0, 3.0)
    assert split_cost([1.0, 2.0, 3.0], 10) == (6.0, 0.0)
    for bad in (-1, 2.5, True, "3"):
        with pytest.raises(ValueError, match="transient_slots"):
            split_cost([1.0], bad)
    with pytest.raises(ValueError, match="transient_slots=-2"):
        evaluate([EpisodeSpec("epa", "lawn/Joint-v1", ScenarioConfig(), 0, {})], progress=False, transient_slots=-2)


# ---------------------------------------------------------------------- the geometric comparison
def test_geometric_comparison_equals_the_direct_computation():
    rng = np.random.default_rng(5)
    b = rng.lognormal(3.0, 1.0, 400)
    a = b * rng.lognormal(-0.1, 0.3, 400)
    g = paired_geometric(dict(enumerate(a)), dict(enumerate(b)))
    logs = np.log(a / b)
    assert g.ratio == pytest.approx(math.exp(logs.mean()), rel=1e-12) and g.seeds == 400
    assert g.won == pytest.approx(np.mean(a < b))
    half = stats.norm.ppf(0.975) * logs.std(ddof=1) / math.sqrt(logs.size)  # the bootstrap's normal limit
    assert math.log(g.low) == pytest.approx(logs.mean() - half, abs=0.006)
    assert math.log(g.high) == pytest.approx(logs.mean() + half, abs=0.006)
    assert g.excludes_zero and g.change < 0


def test_geometric_and_mean_of_ratios_disagree_on_heavy_tails():
    base = dict.fromkeys(range(10), 100.0)
    policy = {s: 50.0 if s < 8 else 1000.0 for s in range(10)}  # halves 8 seeds, 10x on 2
    mean, _, _ = paired_difference(policy, base)
    g = paired_geometric(policy, base)
    assert mean == pytest.approx((8 * -0.5 + 2 * 9.0) / 10)  # +140 %: the mean of ratios says worse
    assert g.ratio == pytest.approx(math.exp((8 * math.log(0.5) + 2 * math.log(10.0)) / 10))  # -9 %: better
    assert mean > 0 > g.change and g.won == 0.8


def test_geometric_ties_small_samples_and_errors():
    same = {s: 10.0 + s for s in range(5)}
    g = paired_geometric(same, same)
    assert (g.ratio, g.low, g.high, g.won) == (1.0, 1.0, 1.0, 0.5) and not g.excludes_zero
    two = paired_geometric({0: 2.0, 1: 4.0}, {0: 1.0, 1: 1.0})
    assert two.ratio == pytest.approx(math.sqrt(8.0)) and math.isnan(two.low) and two.seeds == 2
    with pytest.raises(ValueError, match="must be > 0"):
        paired_geometric({0: 0.0}, {0: 1.0})
    with pytest.raises(ValueError, match="share no seed"):
        paired_geometric({0: 1.0}, {1: 1.0})


# ---------------------------------------------------------------------- the aggregate
def test_aggregate_is_rliables_interquartile_mean_of_the_task_scores():
    rng = np.random.default_rng(2)
    per_task = {}
    for i, target in enumerate([10.0, 40.0, 70.0, 95.0, 300.0]):  # one outlying task
        e = 200.0 + rng.normal(0, 5, 30)
        r = 100.0 + rng.normal(0, 5, 30)
        x = e - (target / 100.0) * (e - r).mean() + rng.normal(0, 1, 30)
        per_task[f"t{i}"] = (e, r, x)
    scores = [normalized_score(dict(enumerate(x)), dict(enumerate(e)), dict(enumerate(r)), version=2)[0]
              for e, r, x in per_task.values()]
    iqm, lo, hi, n = aggregate_score(per_task, version=2)  # on cost: the outlying task's costs go below zero
    middle = sorted(scores)[1:-1]  # trim_mean(0.25) of five drops int(1.25) = 1 at each end
    assert n == 5 and iqm == pytest.approx(np.mean(middle), rel=1e-12)
    assert iqm == pytest.approx(stats.trim_mean(scores, 0.25), rel=1e-12)  # rliable's metrics.aggregate_iqm
    assert lo < iqm < hi and hi - lo < 20  # the outlier moves neither the point nor the interval much
    # a task whose costs do not vary contributes its one score to every resample
    fixed = {t: (np.full(10, 200.0), np.full(10, 100.0), np.full(10, 150.0)) for t in ("a", "b", "c", "d")}
    assert aggregate_score(fixed, version=2) == (50.0, 50.0, 50.0, 4)
    geometric = {t: (np.full(10, 200.0), np.full(10, 50.0), np.full(10, 100.0)) for t in ("a", "b", "c", "d")}
    assert aggregate_score(geometric)[:3] == pytest.approx((50.0, 50.0, 50.0))  # v3: on log cost
    assert aggregate_score({})[3] == 0


# ---------------------------------------------------------------------- reference rows
@pytest.mark.parametrize("task", presets.SUITE)
def test_limit_rows_lift_one_field_of_their_task(task):
    config = presets.get(task)
    base = _flat(config.to_dict())
    for name, (key, value) in LIMITS.items():
        lifted = _flat(limit_config(name, config).to_dict())
        changed = {k for k in base if base[k] != lifted[k]}
        assert changed == ({key} if base[key] != value else set()), name
        policy, played, kwargs = resolve(name, config)
        assert policy == "dv-mpc" and played == limit_config(name, config) and kwargs == LIMIT_SETTINGS.get(name, {})
    for name, (expert, settings) in NOISE.items():
        assert name == f"noise:{expert}" and resolve(name, config) == (expert, config, settings)
    assert LIMITS["limit:fast-drone"][1] == 300.0  # the validated maximum of drone.max_speed_mps
    with pytest.raises(ValueError, match="unknown limit row 'limit:nope'"):
        limit_config("limit:nope", config)


def test_perfect_links_deliver_every_command_and_planners_see_it():
    config = ScenarioConfig().override({"channel.perfect_links": True})
    env = gym.make("lawn/Joint-v1", config=config)
    policy, _ = build_policy("limit:perfect-links", ScenarioConfig(), "lawn/Joint-v1")
    obs, info = env.reset(seed=1)
    policy.reset(seed=1)
    for _ in range(10):
        obs, reward, terminated, truncated, info = env.step(policy.act(obs))
        assert info["delivered"].all() and np.all(info["outage_probability"] == 0.0)
    assert policy.last_plan.info["success_probability"] == pytest.approx(1.0)


def test_reference_rows_run_under_their_names_and_beat_or_tie_the_expert():
    names = ("dv-mpc", "rg-mpc", *REFERENCE_ROWS, "noise:rg-mpc")
    rows = evaluate([EpisodeSpec(p, "lawn/Joint-v1", ScenarioConfig(), 0, {}) for p in names], progress=False)
    cost = {r.policy: r.control_cost for r in rows}
    assert set(cost) == {"dv-mpc", "rg-mpc", "noise:rg-mpc", *REFERENCE_ROWS}
    assert cost["limit:perfect-links"] < cost["dv-mpc"] and cost["limit:fast-drone"] < cost["dv-mpc"]
    assert cost["noise:dv-mpc"] == pytest.approx(cost["dv-mpc"], rel=0.05)
    assert cost["noise:rg-mpc"] == pytest.approx(cost["rg-mpc"], rel=0.05)


# ---------------------------------------------------------------------- the suite
@pytest.mark.parametrize("task", presets.SUITE)
def test_suite_tasks_resolve_validate_and_run_an_episode(task):
    config = presets.get(task)
    assert ScenarioConfig.from_dict(config.to_dict()) == config
    env = gym.make("lawn/Joint-v1", config=task)
    policy, _ = build_policy("epa", config, "lawn/Joint-v1")
    obs, _ = env.reset(seed=0)
    policy.reset(seed=0)
    done, slots = False, 0
    while not done:
        obs, _, terminated, truncated, info = env.step(policy.act(obs))
        done, slots = terminated or truncated, slots + 1
    assert slots == config.num_slots and info["episode_metrics"]["control_cost"] > 0


def test_steady_tasks_start_without_the_transient():
    for task in ("steady", "steady-low-power", "steady-gusty", "wide-k8"):
        config = presets.get(task)
        x0, x1, y0, y1 = config.area_m
        assert config.reference.initial_offset_std_m == 0.0
        assert config.drone.start_m == ((x0 + x1) / 2, (y0 + y1) / 2)
    assert presets.SUITE_VERSION == 3 and presets.SUITE[0] == "default" and "disturbed" in presets.SUITE
    assert set(presets.SUITE_V1) <= set(presets.names()) and set(presets.SUITE_V2) < set(presets.SUITE)


def test_suite_v3_adds_tasks_where_links_are_poor():
    """k16 and k32: the default scenario with 16 and 32 AGVs on one budget, where most commands are lost."""
    extra = [t for t in presets.SUITE if t not in presets.SUITE_V2]
    assert extra == ["k16", "k32"]
    for task, k in zip(extra, (16, 32), strict=True):
        config = presets.get(task)
        assert config == ScenarioConfig(num_agvs=k)


def test_two_ranges_are_compared_apart_with_the_tail_and_the_worst_seed():
    from evaluation.cells import fmt_ranges, fmt_worst
    from evaluation.seeds import TEST_RANGES, range_of, test_seeds
    from evaluation.stats import TAIL_RATIO, compare_ranges

    seeds = test_seeds(5)
    assert seeds[:5] == list(range(5)) and seeds[5:] == [TEST_RANGES[1] + i for i in range(5)]
    assert [range_of(s) for s in (0, 4, TEST_RANGES[1], TEST_RANGES[1] + 4)] == [0, 0, 1, 1]
    reference = {s: 10.0 + (s % 3) for s in seeds}
    # the first range 2 % above the reference on every seed, the second 10 % below but for one seed at 4x
    costs = {s: reference[s] * (1.02 if range_of(s) == 0 else 0.9) for s in seeds}
    costs[TEST_RANGES[1] + 2] = 4.0 * reference[TEST_RANGES[1] + 2]
    c = compare_ranges(costs, reference)
    assert len(c.ranges) == 2 and c.ranges[0].ratio == pytest.approx(1.02) and c.ranges[0].seeds == 5
    assert c.ranges[1].ratio == pytest.approx((0.9 ** 4 * 4.0) ** 0.2)
    assert c.tail == pytest.approx(0.1) and TAIL_RATIO < 4.0
    assert c.worst == pytest.approx(4.0) and c.worst_seed == TEST_RANGES[1] + 2
    assert c.below(1.03) is False  # the second range's interval reaches past +3 %
    assert compare_ranges({s: costs[s] for s in seeds[:5]}, reference).below(1.021)  # one range: its bound
    assert fmt_ranges(c).count(" / ") == 1 and "4.00× (seed" in fmt_worst(c)
    with pytest.raises(ValueError, match="share no seed"):
        compare_ranges({1: 1.0}, {2: 1.0})


def test_compare_is_the_python_front_door_of_evaluate(tmp_path):
    """``evaluation.api.compare`` plays the same episodes as ``evaluate``, with each policy's
    geometric comparison against the reference computed on the same seeds; a result survives its CSV
    row; bad requests are named."""
    from evaluation.api import EpisodeResult, compare
    from evaluation.episode import read_csv, read_results, write_results

    result = compare(["epa", "rg-mpc"], config="steady", seeds=[3, 4], settings={"rg-mpc": {"power_levels": 20}})
    rows = evaluate([EpisodeSpec(p, "lawn/Joint-v1", presets.get("steady"), s,
                                 {"power_levels": 20} if p == "rg-mpc" else {})
                     for p in ("epa", "rg-mpc") for s in (3, 4)], progress=False)
    def played(r):  # the row less this machine's clock
        return {k: v for k, v in r.as_row().items() if not k.startswith("decision_time")}

    assert [played(r) for r in result.results] == [played(r) for r in rows]
    first = result.of("epa")[0]
    assert isinstance(first, EpisodeResult) and first.stage_costs.shape == (presets.get("steady").num_slots,)
    assert first.stage_costs.sum() == pytest.approx(first.control_cost, rel=1e-9)
    assert result.reference == "epa" and set(result.geometric) == {"rg-mpc"}
    np.testing.assert_equal(vars(result.geometric["rg-mpc"]),  # two seeds: no interval (NaN) on either side
                            vars(paired_geometric(result.costs("rg-mpc"), result.costs("epa"))))
    back = read_results(write_results(rows, tmp_path / "rows.csv"))  # strings back
    for fresh, read in zip(rows, back, strict=True):
        assert read.as_row() == fresh.as_row() and isinstance(read.diverged, bool) and isinstance(read.seed, int)
        np.testing.assert_array_equal(read.stage_costs, fresh.stage_costs)
    old = [{k: v for k, v in r.items() if k not in ("diverged", "max_tracking_error_m")}
           for r in read_csv(tmp_path / "rows.csv")]  # an older table: two columns fewer
    assert all(r.diverged is None and r.max_tracking_error_m is None for r in map(EpisodeResult.from_row, old))
    assert EpisodeResult.from_row({**old[0], "diverged": "1", "stage_costs": ""}).diverged is True
    with pytest.raises(ValueError, match=r"columns \['nope'\] are not fields of an episode result"):
        EpisodeResult.from_row({**old[0], "nope": "1"})
    with pytest.raises(ValueError, match="metric 'nope' is not a scalar field"):
        back[0].value("nope")
    with pytest.raises(ValueError, match="policies is empty"):
        compare([])
    with pytest.raises(ValueError, match=r"settings for \['pid'\], which are not among the policies"):
        compare(["epa"], settings={"pid": {}})


def test_statistics_reduce_results_once_per_row_and_compare_any_two_rows():
    """``rows.reduce``: per (task, env, policy) the seeds, each cost's mean and interval and sum, the
    decision time and the score; a comparison of two rows computes what is read, from the same costs
    the functions on results take; a missing row compares to nothing."""
    from evaluation.episode import EpisodeResult
    from evaluation.rows import reduce
    from evaluation.stats import costs_of, mean_ci, paired, paired_geometric

    rng = np.random.default_rng(3)
    rows = [EpisodeResult(p, "lawn/Joint-v1", s, control_cost=c, transient_cost=c / 2, sustained_cost=c / 2,
                          decision_time_median_s=1e-3 * (1 + s), task=t)
            for t in ("a", "b") for p, scale in (("epa", 3.0), ("dv-mpc", 1.0), ("x", 1.5)) for s in range(6)
            for c in [scale * float(rng.uniform(1, 2))]]
    stats = reduce(rows)
    row = stats.row("a", "lawn/Joint-v1", "x")
    assert row.seeds == 6 and row.means["control_cost"] == mean_ci(costs_of(rows, "x", task="a").values())
    assert row.totals["sustained_cost"] == pytest.approx(sum(costs_of(rows, "x", task="a").values()) / 2)
    assert row.decision_ms == pytest.approx(3.5) and row.score is not None
    vs = stats.versus(("a", "lawn/Joint-v1", "x"), ("a", "lawn/Joint-v1", "dv-mpc"))
    assert vs.geometric == paired_geometric(costs_of(rows, "x", task="a"), costs_of(rows, "dv-mpc", task="a"))
    assert vs.paired == paired(rows, "x", "dv-mpc", "lawn/Joint-v1", "a") and len(vs.relative) == 6
    assert stats.aggregate("lawn/Joint-v1", "x", ["a", "b"])[3] == 2 and stats.envs("b") == ["lawn/Joint-v1"]
    assert stats.versus(("a", "lawn/Joint-v1", "x"), ("a", "lawn/Joint-v1", "nope")) is None


def _benchmark_summary(diverged: float) -> list:
    """A summary of the main job's eleven rows (their long names), ``diverged`` on ``epa`` only."""
    from evaluation.rows import SummaryRow
    from evaluation.stats import SUMMARY_METRICS, Interval

    names = ["dv-mpc", "rg-mpc", "ao-mpc", "epa", "sf", "pid", "lqr", "noise:dv-mpc", "limit:fast-drone",
             "limit:perfect-links", "actuator:buffer"]
    summary = []
    for i, name in enumerate(names):
        means = {key: Interval(100.0 + 10 * i, 5.0) for key, _ in SUMMARY_METRICS}
        means["diverged"] = Interval(diverged if name == "epa" else 0.0, 0.0)
        summary.append(SummaryRow(name, 20, means))
    return summary


def test_plot_summary_names_never_overlap_and_shows_no_empty_diverged_panel(tmp_path):
    """``benchmark.png``: the eleven names stand upright and apart under every panel; with no
    episode diverged there is no (empty) diverged panel and the title says so; with one there is."""
    import itertools

    from matplotlib.backends.backend_agg import RendererAgg

    from evaluation.report import plot_summary
    from evaluation.stats import SUMMARY_METRICS

    fig = plot_summary(_benchmark_summary(0.0), tmp_path / "none.png", title="t")
    assert (tmp_path / "none.png").stat().st_size > 0
    titles = [ax.get_title() for ax in fig.axes]
    assert "diverged" not in titles and len(titles) == len(SUMMARY_METRICS) - 1
    assert fig.get_suptitle() == "t; no episode diverged"
    renderer = fig.canvas.get_renderer()
    assert isinstance(renderer, RendererAgg)
    for ax in fig.axes:
        labels = [t for t in ax.get_xticklabels() if t.get_text()]
        assert len(labels) == 11 and all(t.get_rotation() == 90 for t in labels)
        boxes = [t.get_window_extent(renderer) for t in labels]
        for left, right in itertools.pairwise(boxes):
            assert left.x1 < right.x0, (ax.get_title(), left, right)  # apart, in order
        assert min(b.y0 for b in boxes) >= 0  # inside the figure
    panels = [ax.get_window_extent(renderer) for ax in fig.axes]
    for left, right in itertools.pairwise(panels):
        assert left.x1 < right.x0  # the panels themselves apart

    fig = plot_summary(_benchmark_summary(0.1), tmp_path / "some.png", title="t")
    assert [ax.get_title() for ax in fig.axes][5] == "diverged" and fig.get_suptitle() == "t"
    plot_summary(_benchmark_summary(0.0), tmp_path / "again.png", title="t")
    assert (tmp_path / "again.png").read_bytes() == (tmp_path / "none.png").read_bytes()  # deterministic


def test_results_json_holds_arrays_of_numbers_and_reads_back(tmp_path):
    """``write_results`` to ``.json``: every per-AGV and per-slot field a JSON array of numbers, the
    file valid JSON (NaN as null, infinities as strings); ``read_results`` gives the same results."""
    import json

    from evaluation.episode import EpisodeResult, read_results, write_results

    rows = evaluate([EpisodeSpec("epa", "lawn/Joint-v1", presets.get("steady"), s, {}) for s in (3, 4)], progress=False)
    odd = rows[1].with_(rmse_m=math.nan, tracking_cost=math.inf, stage_costs=np.array([1.5, math.nan, -math.inf]),
                        mean_power_w=None)  # a NaN, infinities and a field not recorded
    rows = [rows[0], odd]
    path = write_results(rows, tmp_path / "rows.json")
    text = path.read_text()
    data = json.loads(text, parse_constant=lambda c: pytest.fail(f"{c} is not JSON"))
    arrays = ("rmse_per_agv_m", "outage_rate_per_agv", "mean_power_w", "stage_costs")
    for name in arrays:
        assert isinstance(data[0][name], list) and all(type(x) is float for x in data[0][name]), name
    assert len(data[0]["stage_costs"]) == rows[0].slots and data[0]["stage_costs"] == rows[0].stage_costs.tolist()
    assert data[1]["stage_costs"] == [1.5, None, "-Infinity"] and "mean_power_w" not in data[1]
    assert data[1]["rmse_m"] is None and data[1]["tracking_cost"] == "Infinity"
    back = read_results(path)
    assert all(isinstance(r, EpisodeResult) for r in back) and len(back) == 2
    for fresh, read in zip(rows, back, strict=True):
        np.testing.assert_equal(read.as_row(), fresh.as_row())  # NaN equals NaN here
        for name in arrays:
            got, want = getattr(read, name), getattr(fresh, name)
            assert (got is None) == (want is None)
            if want is not None:
                assert got.dtype == float
                np.testing.assert_array_equal(got, want)
        assert isinstance(read.diverged, bool) and isinstance(read.seed, int)
    assert math.isnan(back[1].rmse_m) and back[1].tracking_cost == math.inf and back[1].mean_power_w is None
    assert read_results(tmp_path / "missing.json") == []
    csv_back = read_results(write_results(rows, tmp_path / "rows.csv"))  # the CSV as it was: strings in cells
    assert csv_back[1].as_row()["stage_costs"] == "[1.5, NaN, -Infinity]"
