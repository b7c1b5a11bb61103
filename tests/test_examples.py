"""The examples in examples/ run as their docstrings say (tiny budgets)."""

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def test_cleanrl_style_ppo_trains_and_logs_full_episodes():
    """examples/ppo_lawn.py on gymnasium >= 1.0: every finished episode is logged (the statistics that
    CleanRL's own script never sees under gymnasium 1.x), and the run ends with the control cost of
    full unmodified episodes beside the zero action."""
    pytest.importorskip("torch")
    out = subprocess.run([sys.executable, str(ROOT / "examples" / "ppo_lawn.py"), "--total-timesteps", "512",
                          "--num-envs", "2", "--num-steps", "128", "--eval-episodes", "1", "--seed", "0"],
                         capture_output=True, text=True, timeout=300, check=True).stdout
    lengths = [int(n) for n in re.findall(r"episodic_length=(\d+)", out)]
    assert len(lengths) >= 2 and all(0 < n <= 120 for n in lengths)
    assert re.search(r"^summary: episodes=\d+ mean_length=", out, re.M)
    assert re.search(r"^evaluation: 1 episodes, control cost [\d.]+ \(full episodes [01]\), zero action [\d.]+", out,
                     re.M)
