"""The compiled search and refinement of the reduced planners (:mod:`agents.search`) against the Python
code they replaced (``tests/oracle_search.py``), and a batch against its scenarios one by one."""

import math

import gymnasium as gym
import numpy as np
import oracle_search as oracle
import pytest

import lawn_env  # noqa: F401
from agents import make_policy, rollout, search
from lawn_env import ScenarioConfig, presets

AREA = (0.0, 100.0, 0.0, 100.0)


def test_vector_sum_is_numpys_sum_bit_for_bit(rng):
    for n in [*range(0, 300), 1000, 4097]:
        a = rng.standard_normal(n) * 10.0 ** rng.uniform(-6, 6, n)
        assert search.vector_sum(a) == a.sum(), n


def test_the_projections_and_the_grid_are_the_python_ones(rng):
    area = np.array(AREA)
    for _ in range(3000):
        center, radius = rng.uniform(0, 100, 2), rng.uniform(0, 30)
        point = center + rng.normal(0, 40, 2)
        assert np.array_equal(search.project_disc_box(point, center, radius, area),
                              oracle.project_disc_box(point, center, radius, AREA))
        v, total = rng.normal(0, 1, rng.integers(1, 40)), rng.uniform(0.1, 3)
        assert np.array_equal(search.project_budget(v, total), oracle.project_budget(v, total))
        spacing, cap = rng.uniform(0.3, 3), int(rng.integers(5, 500))
        assert np.array_equal(search.disc_box_grid(center, radius, area, spacing, cap),
                              oracle.disc_box_grid(center, radius, AREA, spacing, cap))


def _recorded(config, slots, seed=0, settings=None):
    """(problem, the planner's previous slot) at every decision of a dv-mpc episode on ``config``."""
    policy = make_policy("dv-mpc", config, **(settings or {}))
    planner = policy.solver
    env = gym.make("lawn/Joint-v1", config=config).unwrapped
    recorded = []
    make = planner._problems

    def problems(snapshots):
        made = make(snapshots)
        recorded.append((made[0], planner.last))
        return made

    planner._problems = problems
    rollout(env, policy, seed, max_steps=slots)
    return planner, recorded


CASES = {
    "default": (ScenarioConfig(), None),
    "disturbed (lag, period 2, measurement noise)": (presets.get("disturbed"), None),
    "buffered actuator": (ScenarioConfig(control={"actuator": "buffer"}), None),
    "certainty-equivalent tail": (ScenarioConfig(), {"tail": "certainty-equivalent"}),
    "k1": (ScenarioConfig(num_agvs=1), None),
    "k32": (presets.get("k32"), None),
}


@pytest.mark.parametrize("case", list(CASES))
def test_compiled_decisions_are_the_python_planners(case):
    """On recorded slots of each task: the compiled decision (search, starts, refinement) is the Python
    planner's to the last bit; a batch of them is each one alone."""
    config, settings = CASES[case]
    planner, recorded = _recorded(config, 6 if config.num_agvs > 8 else 12, settings=settings)
    problems = [problem for problem, _ in recorded]
    lasts = [last for _, last in recorded]
    batch = search.decide(problems, lasts, planner.settings)
    for i, (problem, last) in enumerate(recorded):
        phi, power, q, origin = oracle.decide(problem, last, planner.settings)
        alone = search.decide([problem], [last], planner.settings)
        assert search.STARTS[int(alone.origin[0])] == origin
        assert alone.phi[0] == phi and np.array_equal(alone.power[0], power) and np.array_equal(alone.position[0], q)
        for field in search.Decisions._fields:
            assert np.array_equal(getattr(batch, field)[i], getattr(alone, field)[0], equal_nan=True), field


def test_a_search_only_decision_is_the_searchs_point():
    config = ScenarioConfig()
    planner, recorded = _recorded(config, 3)
    s = planner.settings
    for problem, last in recorded:
        decided = search.decide([problem], [last], s, search_only=True)
        positions = oracle.disc_box_grid(problem.q_prev, problem.reach, problem.area, s.drone_spacing_m,
                                         s.max_drone_points)
        power, q = oracle.grid_search(problem, positions, s.power_levels, s.coarse_power_levels, s.keep_positions)
        phi, psi = oracle.phi_at(problem, power, q)
        assert decided.phi[0] == phi and np.array_equal(decided.psi[0], psi)
        assert decided.evaluations[0] == 1 and math.isnan(decided.start_values[0, search.EQUAL])


@pytest.mark.parametrize("case", ["default", "disturbed (lag, period 2, measurement noise)", "buffered actuator",
                                  "certainty-equivalent tail", "k1"])
def test_a_batch_of_scenarios_plans_as_each_one_alone(case):
    """dv-mpc's plan_scenarios over B scenarios (their own seeds, one restarting mid-way) gives each scenario
    the plans it gets when planned alone, bit for bit (each keeps its own warm starts, tracker and
    psi-bar)."""
    config, settings = CASES[case]
    seeds, slots = (3, 4, 5), 14
    alone = {}
    for seed in seeds:
        policy = make_policy("dv-mpc", config, **(settings or {}))
        env = gym.make("lawn/Joint-v1", config=config).unwrapped
        alone[seed] = list(_planned(policy, env, seed, slots))
    batch = make_policy("dv-mpc", config, **(settings or {}))
    envs = [gym.make("lawn/Joint-v1", config=config).unwrapped for _ in seeds]
    for env, seed in zip(envs, seeds):
        env.reset(seed=seed)
    planner = batch.solver
    for t in range(slots):
        snapshots = [env.snapshot() for env in envs]
        plans = planner.plan_scenarios(snapshots)
        for env, seed, plan, snap in zip(envs, seeds, plans, snapshots):
            expected = alone[seed][t]
            assert np.array_equal(plan.increments, expected.increments) and plan.objective == expected.objective
            assert np.array_equal(plan.power_w, expected.power_w)
            assert np.array_equal(plan.drone_position, expected.drone_position), (seed, t)
            env.step(batch.action(plan, snap))


def _planned(policy, env, seed, slots):
    env.reset(seed=seed)
    policy.reset(seed)
    for _ in range(slots):
        snap = env.snapshot()
        plan = policy.plan(snap)
        yield plan
        env.step(policy.action(plan, snap))


def test_a_batch_restarts_one_scenario_and_refuses_another_size():
    config = ScenarioConfig()
    planner = make_policy("dv-mpc", config).solver
    env = gym.make("lawn/Joint-v1", config=config).unwrapped
    env.reset(seed=1)
    fresh = make_policy("dv-mpc", config).solver.plan(env.snapshot())
    planner.plan_scenarios([env.snapshot(), env.snapshot()])
    planner.plan_scenarios([env.snapshot(), env.snapshot()])
    planner.reset(np.array([False, True]))  # the second scenario starts a new episode
    plans = planner.plan_scenarios([env.snapshot(), env.snapshot()])
    assert plans[1].objective == fresh.objective and np.array_equal(plans[1].drone_position, fresh.drone_position)
    assert "previous" in plans[0].info["start_values"] and "previous" not in plans[1].info["start_values"]
    with pytest.raises(ValueError, match="3 snapshots for a planner playing 2 scenarios"):
        planner.plan_scenarios([env.snapshot()] * 3)
    with pytest.raises(ValueError, match="which has shape"):
        planner.reset(np.array([True]))


def test_the_tabulated_planners_grid_search_is_the_python_one():
    """rg-mpc's and global-mpc's grid search (:data:`agents.search.HERMITE`: V_k tabulated with exact QPs,
    cubic Hermite between points, psi by scipy's law) against the pre-change Python search, bit for bit."""
    from agents.reduced import ReducedProblem
    from agents.rg_mpc import ReducedGradientPlanner

    config = ScenarioConfig()
    planner = ReducedGradientPlanner(config)
    env = gym.make("lawn/Joint-v1", config=config).unwrapped
    env.reset(seed=2)
    s = planner.settings
    for _ in range(4):
        snapshot = env.snapshot()
        problem = ReducedProblem(planner.mpc, planner.link, snapshot, config)
        table = problem.table(planner.psi_grid)
        positions = search.disc_box_grid(problem.q_prev, problem.reach, np.asarray(problem.area), s.drone_spacing_m,
                                         s.max_drone_points)
        value, power, q = problem.grid_search(table, positions, s.power_levels, s.coarse_power_levels,
                                              s.keep_positions)
        expected = oracle.hermite_grid_search(table.grid, table.values, table.slopes, problem.agv_xy, positions,
                                              s.power_levels, s.coarse_power_levels, s.keep_positions,
                                              problem.budget, problem.link)
        assert value == expected[0] and np.array_equal(power, expected[1]) and np.array_equal(q, expected[2])
        env.step(env.action_space.sample() * 0.3)


def test_a_reference_qp_backend_plans_one_scenario_at_a_time():
    policy = make_policy("dv-mpc", ScenarioConfig(), qp_backend="daqp")
    assert not policy.batched and make_policy("dv-mpc", ScenarioConfig()).batched
    env = gym.make("lawn/Joint-v1").unwrapped
    env.reset(seed=0)
    with pytest.raises(ValueError, match="qp_backend='daqp' plans one scenario at a time"):
        policy.solver.plan_scenarios([env.snapshot(), env.snapshot()])
