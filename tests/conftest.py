import warnings

import numpy as np
import pytest

import lawn_env  # noqa: F401  (registers the environment ids)


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def pytest_configure(config):
    # Gymnasium's checker warns about the unbounded (normalized, but not clipped) observation box.
    warnings.filterwarnings("ignore", message=".*Box observation space (minimum|maximum) value is.*")
