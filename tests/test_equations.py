"""Each equation in one place: an edit of one function reaches every env, planner and prior.

A copy of the package runs once as it is (compiling its kernels into its own cache), then with
two one-function edits made in place, as a researcher would make them: the outage law
(:func:`lawn_env.channel.outage_law`: the argument doubled and the high-SNR order raised by one)
and the AGV transition (:func:`lawn_env.dynamics.agv_matrices`: the velocity damped). The test
checks that the simulator, the Comm MPC, rg-mpc's and dv-mpc's link models, the RL interface's prior, the
prediction model and the LQR gain all follow the edits, and that the kernels cached before the
edit are not reused (:mod:`lawn_env.kernel_cache`).
"""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import linalg, special

ROOT = Path(__file__).resolve().parent.parent

PROBE = r'''
import json, sys
import numpy as np, gymnasium as gym
import lawn_env
from lawn_env import action_codec, presets
from lawn_env.channel import LinkParams
from lawn_env.dynamics import PredictionModel
from agents import make_policy

cfg = presets.get("default")
out = {"origin": lawn_env.__file__}
env = gym.make("lawn/Joint-v1").unwrapped
env.reset(seed=1)
snap = env.snapshot()
action = np.linspace(-0.5, 0.5, env.action_space.shape[0]).astype(np.float32)
_, _, _, _, info = env.step(action)
link = LinkParams.from_config(cfg)
d2 = link.distance_sq(info["drone_position"], snap.x_aug[:, 0:2])
out["x"] = link.outage_argument_sq(info["power_w"], d2).tolist()
out["outage"] = info["outage_probability"].tolist()
out["x_before"], out["x_after"] = snap.x_aug.tolist(), env.sim.x_aug.tolist()
out["applied"] = info["applied_increment"].tolist()
model = PredictionModel.from_config(cfg)
out["a_aug"], out["b_aug"], out["lqr_gain"] = model.a_aug.tolist(), model.b_aug.tolist(), model.lqr_gain.tolist()

comm = gym.make("lawn/Comm-v1").unwrapped
comm.reset(seed=1)
snap = comm.snapshot()
_, _, _, _, info = comm.step(np.zeros(6, dtype=np.float32))
planning = LinkParams.from_config(cfg, planning=True)
d2 = planning.distance_sq(info["drone_position"], snap.x_aug[:, 0:2])
out["comm_x"] = planning.outage_argument_sq(info["power_w"], d2).tolist()
out["comm_psi"] = info["success_probability_planned"].tolist()
out["comm_prediction"] = comm.mpc.model.c[6:12].tolist()

codec = action_codec(cfg, "comm", "rl")
data = codec.mpc.prepare(snap.x_aug, snap.reference, snap.slot)
out["stakes"] = codec.mpc.command_stakes(data).tolist()
out["prior_d2"] = planning.distance_sq(snap.drone_position, snap.x_aug[:, 0:2]).tolist()
out["prior"] = codec.power_prior(snap.x_aug, snap.drone_position, data).tolist()

for name, key in (("rg-mpc", "rg"), ("dv-mpc", "dv")):  # scipy's law, and its closed-form part
    policy = make_policy(name, cfg)
    policy.reset(seed=0)
    plan = policy.plan(snap)
    out[key + "_psi"] = np.asarray(plan.info["success_probability"]).tolist()
    d2 = planning.distance_sq(plan.drone_position, snap.x_aug[:, 0:2])
    out[key + "_x"] = planning.outage_argument_sq(plan.power_w, d2).tolist()
print(json.dumps(out))
'''

EDITS = {
    "lawn_env/channel.py": ('    SUCCESS, so their decisions keep scipy\'s last bit). The five are one law: they change together."""\n',
                            '    SUCCESS, so their decisions keep scipy\'s last bit). The five are one law: they change together."""\n'
                            '    if part == ORDER:\n        return m + 1.0\n    x = 2.0 * x\n'),
    "lawn_env/dynamics.py": ("    a[0, 2] = a[1, 3] = dt\n", "    a[0, 2] = a[1, 3] = dt\n    a[2, 2] = a[3, 3] = 0.9\n"),
}


def _probe(tree: Path) -> dict:
    env = dict(os.environ, PYTHONPATH=str(tree))
    env.pop("NUMBA_CACHE_DIR", None)  # the copy's own cache, in its tree
    done = subprocess.run([sys.executable, "-c", PROBE], env=env, cwd=tree, capture_output=True, text=True,
                          timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    out = json.loads(done.stdout.strip().splitlines()[-1])
    assert out["origin"].startswith(str(tree))
    return {k: np.asarray(v) for k, v in out.items() if k != "origin"}


def _lqr_gain(a_aug, b_aug):
    """The DARE gain (Q1 = I6, Q2 = I2, the default weights), from scipy: the oracle."""
    q3 = linalg.solve_discrete_are(a_aug, b_aug, np.eye(6), np.eye(2))
    return np.linalg.solve(np.eye(2) + b_aug.T @ q3 @ b_aug, b_aug.T @ q3 @ a_aug)


@pytest.mark.slow
def test_one_function_edits_reach_every_env_planner_and_prior(tmp_path):
    copy = tmp_path / "lawn"
    for package in ("lawn_env", "agents"):
        shutil.copytree(ROOT / package, copy / package, ignore=shutil.ignore_patterns("__pycache__"))
    base = _probe(copy)  # compiles the copy's kernels into its cache
    for path, (old, new) in EDITS.items():
        source = (copy / path).read_text()
        assert source.count(old) == 1, path
        (copy / path).write_text(source.replace(old, new))
    edited = _probe(copy)  # the same cache: a kernel compiled before the edit must not come back
    m = 2.0  # the default Nakagami m

    # the outage law: the simulator's outage, the Comm MPC's planned psi, rg-mpc's psi and the prior
    np.testing.assert_array_equal(base["outage"], special.gammainc(m, base["x"]))
    np.testing.assert_array_equal(edited["outage"], special.gammainc(m, 2.0 * edited["x"]))
    np.testing.assert_array_equal(base["comm_psi"], special.gammaincc(m, base["comm_x"]))
    np.testing.assert_array_equal(edited["comm_psi"], special.gammaincc(m, 2.0 * edited["comm_x"]))
    np.testing.assert_allclose(base["rg_psi"], special.gammaincc(m, base["rg_x"]), rtol=1e-12)
    np.testing.assert_allclose(edited["rg_psi"], special.gammaincc(m, 2.0 * edited["rg_x"]), rtol=1e-12)
    np.testing.assert_allclose(base["dv_psi"], special.gammaincc(m, base["dv_x"]), rtol=1e-12)  # the closed form
    np.testing.assert_allclose(edited["dv_psi"], special.gammaincc(m, 2.0 * edited["dv_x"]), rtol=1e-12)
    for out, order in ((base, m), (edited, m + 1.0)):
        log_w = (np.log(out["stakes"]) + order * np.log(out["prior_d2"])) / (order + 1.0)
        np.testing.assert_allclose(out["prior"], np.exp(log_w - log_w.max()), rtol=1e-12)

    # the transition: the simulator, the prediction model, the LQR gain and the Comm MPC
    a_edited = edited["a_aug"]
    assert a_edited[2, 2] == a_edited[3, 3] == 0.9 and base["a_aug"][2, 2] == 1.0
    for out in (base, edited):
        np.testing.assert_allclose(out["x_after"], out["x_before"] @ out["a_aug"].T + out["applied"] @ out["b_aug"].T,
                                   rtol=1e-12, atol=1e-12)
        np.testing.assert_array_equal(out["comm_prediction"], out["a_aug"])
        np.testing.assert_allclose(out["lqr_gain"], _lqr_gain(out["a_aug"], out["b_aug"]), rtol=1e-9, atol=1e-12)
