import warnings

import numpy as np
import pytest

import lawn_env  # noqa: F401  (registers the environment ids)
from lawn_env.dynamics import PredictionModel


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def pytest_configure(config):
    # Gymnasium's checker warns about the unbounded (normalized, but not clipped) observation box.
    warnings.filterwarnings("ignore", message=".*Box observation space (minimum|maximum) value is.*")
    # Hypothesis draws its examples from a fixed seed and keeps no example database: every run (CI's
    # clean checkout included) tests the same examples, so a pass or a failure is reproducible
    from hypothesis import settings

    settings.register_profile("lawn", derandomize=True, database=None)
    settings.load_profile("lawn")


def _independent_qp(config, x, ref, psi, blocked=None):
    """The QP P3 of one AGV written independently of ``lawn_env.mpc``, straight from the paper's
    cost and MODEL.md's control set, solved by cvxpy/Clarabel at tight tolerances: (value, z).
    ``blocked`` (N_p,) bool fixes those increments to zero (move blocking, MODEL.md §7)."""
    cp = pytest.importorskip("cvxpy")
    model = PredictionModel.from_config(config)
    ctl = config.control
    n = ctl.horizon
    q1, q2 = np.diag(ctl.q1_diag), np.diag(ctl.q2_diag)
    z = cp.Variable((n, 2))
    cost = 0
    state = x
    cons = [cp.abs(z) <= ctl.accel_increment_max_mps2]
    cons += [z[i] == 0 for i in range(n) if blocked is not None and blocked[i]]
    u = x[4:6]
    for i in range(n):
        e = state - ref[i]
        cost += cp.quad_form(e, q1) + cp.quad_form(z[i], q2)
        state = model.a_aug @ state + psi * (model.b_aug @ z[i])
        u = u + z[i]
        cons.append(cp.abs(u) <= ctl.accel_max_mps2)
    e = state - ref[n]
    cost += cp.quad_form(e, model.q3)
    prob = cp.Problem(cp.Minimize(cost), cons)
    prob.solve(solver=cp.CLARABEL, tol_gap_abs=1e-12, tol_gap_rel=1e-12, tol_feas=1e-12)
    return prob.value, z.value


@pytest.fixture
def independent_qp():
    """``independent_qp(config, x_aug_k, reference_k, psi_k, blocked=None) -> (value, z)`` (see above)."""
    return _independent_qp


#: The suite's longest tests (tens of seconds each): started first, so that on two xdist workers
#: they run beside the many short ones instead of after them (the suite's wall time is its tail).
LONG_FIRST = ("test_quick_figures_are_built_from_their_tables", "test_the_site_builds_in_strict_mode")


def pytest_collection_modifyitems(config, items):
    items.sort(key=lambda item: item.originalname not in LONG_FIRST)  # stable: the rest keep their order
