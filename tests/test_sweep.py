import csv
import json
import os
import shutil
import signal
import subprocess
import sys
import time

import gymnasium as gym
import numpy as np
import pytest

from evaluation.sweep import SweepTableError, load_spec, read_rows, read_table, run_sweep
from lawn_env import DisturbanceConfig, ScenarioConfig
from paper.experiments import EXPERIMENTS, make_figures
from paper.pages import ROOT, block_body

SPEC = {"name": "t", "env": "lawn/Joint-v1", "preset": "default", "set": {"num_slots": 8},
        "grid": {"channel.blocklength": [256, 1024]}, "policies": ["epa", "pid"], "seeds": 3}


def _keys(rows):
    return [(r.grid["channel.blocklength"], r.policy, r.seed) for r in rows]


def _cells(rows):
    """The rows as the table's text: what a sweep row is equal by."""
    return [{k: str(v) for k, v in r.as_row().items()} for r in rows]


def test_sweep_rows_and_resume(tmp_path):
    table = tmp_path / "t.csv"
    partial = run_sweep(SPEC, table, max_runs=5, progress=False)
    assert len(partial) == 5
    rows = run_sweep(SPEC, table, progress=False)
    assert len(rows) == 12 and len(set(_keys(rows))) == 12
    again = run_sweep(SPEC, table, progress=False)  # nothing left to do
    assert _cells(again) == _cells(rows)
    uninterrupted = run_sweep(SPEC, tmp_path / "u.csv", progress=False)
    by_key = {k: r.result.control_cost for k, r in zip(_keys(uninterrupted), uninterrupted)}
    assert all(by_key[k] == r.result.control_cost for k, r in zip(_keys(rows), rows))
    assert rows[0].lawn_version and json.loads(rows[0].config)["num_slots"] == 8


def test_sweep_survives_being_killed(tmp_path):
    spec = dict(SPEC, seeds=6, set={"num_slots": 30})
    spec_file = tmp_path / "spec.json"
    spec_file.write_text(json.dumps(spec))
    table = tmp_path / "k.csv"
    cmd = [sys.executable, "-m", "lawn_cli", "sweep", str(spec_file), "--out", str(table), "--workers", "1", "--quiet"]
    proc = subprocess.Popen(cmd, cwd=os.getcwd())
    deadline = time.time() + 60
    while time.time() < deadline and len(read_table(table)) < 3:
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    killed = read_table(table)
    assert 3 <= len(killed) < 24, "kill the sweep mid-run"
    subprocess.run(cmd, cwd=os.getcwd(), check=True)
    rows = read_table(table)
    assert len(rows) == 24 and len(set(_keys(rows))) == 24
    assert _cells(rows[: len(killed)]) == _cells(killed)  # finished rows kept as they were


def test_sweep_resume_is_keyed_by_the_resolved_config_and_refuses_foreign_tables(tmp_path):
    """A changed ``set`` reruns instead of reusing rows; a table written by another
    spec is refused with a clear message unless extended."""
    small = dict(SPEC, grid={"channel.blocklength": [256]}, policies=["epa"], seeds=2)
    table = tmp_path / "t.csv"
    first = run_sweep(small, table, progress=False)
    assert len(first) == 2 and len({r.config_hash for r in first}) == 1
    changed = dict(small, set={"num_slots": 9})
    with pytest.raises(SweepTableError, match="holds 2 rows that sweep 't' would not produce.*--extend"):
        run_sweep(changed, table, progress=False)
    extended = run_sweep(changed, table, progress=False, extend=True)
    assert len(extended) == 4 and {json.loads(r.config)["num_slots"] for r in extended} == {8, 9}
    assert len({r.config_hash for r in extended}) == 2
    other = tmp_path / "other.csv"
    run_sweep(dict(small, grid={"power_budget_dbw": [0.0]}, name="o"), other, progress=False)
    with pytest.raises(SweepTableError):
        run_sweep(small, other, progress=False)


def test_sweep_drops_truncated_and_duplicated_rows_and_reruns_them(tmp_path):
    small = dict(SPEC, grid={"channel.blocklength": [256]}, policies=["epa"], seeds=3)
    table = tmp_path / "t.csv"
    rows = run_sweep(small, table, progress=False)
    lines = table.read_text().splitlines()
    header, body = lines[0], lines[1:]
    # a duplicate of the first row, and the last row cut inside its metrics (a killed write)
    table.write_text("\n".join([header, body[0], body[0], body[1], body[2][: len(body[2]) // 3]]) + "\n")
    with pytest.warns(UserWarning, match="dropped 2 unusable rows.*line 3: a duplicate.*line 5: its config is not complete JSON"):
        again = run_sweep(small, table, progress=False)
    assert len(again) == 3 and sorted(r.seed for r in again) == [0, 1, 2]
    by_seed = {r.seed: r.result.control_cost for r in rows}
    assert all(by_seed[r.seed] == r.result.control_cost for r in again)  # the rerun row is the same episode
    read = read_rows(table)
    assert len(read.rows) == 3 and not read.dropped


def test_a_table_rewritten_through_its_records_is_the_same_file(tmp_path):
    """Rows read back (SweepRow.from_row) and written again (as_row) give the table's bytes: the same
    columns in the same order, every cell as it was."""
    small = dict(SPEC, grid={"channel.blocklength": [256]}, policies=["epa", "pid"], seeds=2)
    table = tmp_path / "t.csv"
    run_sweep(small, table, progress=False)
    written = table.read_bytes()
    lines = table.read_text().splitlines()
    table.write_text("\n".join([*lines, lines[1]]) + "\n")  # a duplicate: dropped, the table rewritten
    with pytest.warns(UserWarning, match="dropped 1 unusable rows"):
        rows = run_sweep(small, table, progress=False)
    assert table.read_bytes() == written
    assert {r.policy for r in rows} == {"epa", "pid"} and all(r.grid == {"channel.blocklength": "256"} for r in rows)


def test_sweep_spec_errors(tmp_path):
    with pytest.raises(ValueError, match="unknown sweep spec keys \\['gird'\\]"):
        load_spec({"gird": {}})
    with pytest.raises(ValueError, match="unknown config key 'channel.blocklenght'"):
        load_spec({"grid": {"channel.blocklenght": [1]}})
    with pytest.raises(ValueError, match="unknown policy 'nope'"):
        load_spec({"policies": ["nope"]})
    with pytest.raises(ValueError, match="does not exist"):
        load_spec(tmp_path / "none.yml")


def test_ray_backend_runs_a_tiny_sweep(tmp_path):
    pytest.importorskip("ray")
    rows = run_sweep(dict(SPEC, seeds=1, policies=["epa"]), tmp_path / "r.csv", workers=2, backend="ray", progress=False)
    assert len(rows) == 2


def test_quick_figures_are_built_from_their_tables(tmp_path):
    timings = make_figures([], tmp_path, quick=True, workers=2, progress=False)
    assert set(timings) == set(EXPERIMENTS)
    for name, exp in EXPERIMENTS.items():
        assert (tmp_path / f"{name}.png").stat().st_size > 5000 and (tmp_path / f"{name}.pdf").exists()
        for table in exp.table_names(quick=True):
            assert (tmp_path / "data" / f"{table}.csv").exists()
    tables = {p.name: p.stat().st_mtime_ns for p in (tmp_path / "data").glob("*.csv")}
    for name in EXPERIMENTS:
        (tmp_path / f"{name}.png").unlink()
    make_figures([], tmp_path, quick=True, workers=1, progress=False)  # plots only: every table is complete
    assert {p.name: p.stat().st_mtime_ns for p in (tmp_path / "data").glob("*.csv")} == tables
    assert all((tmp_path / f"{name}.png").exists() for name in EXPERIMENTS)
    with pytest.raises(ValueError, match="unknown figures"):
        make_figures(["fig9"], tmp_path)
    from paper.experiments import check_claims, format_claims, read_claims, write_claims
    from paper.experiments.reproduction import write_reproduction

    (tmp_path / "docs").mkdir()
    shutil.copy2(ROOT / "docs" / "REPRODUCTION.md", tmp_path / "docs" / "REPRODUCTION.md")  # the page's blocks
    with pytest.raises(FileNotFoundError, match="run `lawn figures"):
        write_reproduction(tmp_path, tmp_path / "docs")  # the page reads the claims' results, not the tables
    claims = check_claims(tmp_path)
    assert {c.figure for c in claims} == set(EXPERIMENTS)
    assert all(c.verdict in ("holds", "differs", "not significant") and c.value for c in claims)
    assert len({c.key for c in claims}) == len(claims)
    assert format_claims(claims).count("\n") == len(claims) + 1
    write_claims(claims, tmp_path)
    assert read_claims(tmp_path) == claims and (tmp_path / "claims.md").read_text().startswith("| figure |")
    reason = "One slot's cost does not resolve a difference"  # a section of the page
    explanations = {"ce.": reason, "rate.": "A section the page lacks"}
    path = write_reproduction(tmp_path, tmp_path / "docs", explanations=explanations)
    misses = block_body(path, "reproduction-misses")
    assert "Generated by `lawn figures" in misses and "commit" in misses  # provenance
    ce = [c for c in claims if c.verdict != "holds" and c.key.startswith("ce.")]
    assert (f"Why: [{reason}](#one-slots-cost-does-not-resolve-a-difference)" in misses) == bool(ce)
    unexplained = [c.key for c in claims if c.verdict != "holds" and not c.key.startswith("ce.")]
    if unexplained:  # rate.: the page has no such section
        assert all(key in misses.split("**Not yet explained:**")[1] for key in unexplained)
    assert block_body(path, "reproduction").count("\n| ") >= len(claims)  # the claims' table, one row per claim
    assert (tmp_path / "docs" / "figures" / "reproduction" / "ce.png").exists()


def test_paired_claims_use_the_same_seeds_and_their_intervals():
    from evaluation.stats import paired_difference, verdict
    from paper.experiments.claims import multi_claim, paired_claim

    a = {0: 90.0, 1: 180.0, 2: 95.0, 3: 9.0}
    b = {0: 100.0, 1: 200.0, 2: 100.0, 4: 1.0}  # seed 3 and 4 unpaired: ignored
    mean, half, n = paired_difference(a, b)
    assert n == 3 and mean == pytest.approx(np.mean([-0.1, -0.1, -0.05]))
    assert verdict(mean, half, "negative") == "holds" and verdict(mean, half, "positive") == "differs"
    assert verdict(0.1, 0.2, "negative") == "not significant"
    assert verdict(mean, float("nan"), "negative") == "n/a"
    assert verdict(0.001, 0.002, "tie") == "holds" and verdict(0.05, 0.01, "tie") == "differs"
    assert verdict(0.0, 0.05, "tie") == "not significant"
    c = paired_claim("f", "k", "a beats b", "cost", a, b, "negative")
    assert c.verdict == "holds" and c.seeds == 3 and c.value.startswith("-8.3 %")
    both = multi_claim("f", "k", "a beats b twice", "cost", [("x", a, b), ("y", {0: 1.0, 1: 2.0}, {0: 1.5, 1: 2.5})],
                       "negative")
    assert both.seeds == 2 and both.verdict == "not significant"  # the fewest seeds; y's 2 seeds cannot resolve it
    assert both.value.startswith("x: -8.3 %")


def test_disturbance_mode():
    with pytest.raises(ValueError, match="disturbance.actuator_lag_s"):
        ScenarioConfig(disturbance={"actuator_lag_s": -1})
    assert not ScenarioConfig().disturbance.active and DisturbanceConfig(control_period_slots=2).active
    env = gym.make("lawn/Joint-v1", config="disturbed").unwrapped
    obs, _ = env.reset(seed=0)
    assert not np.allclose(env.sim.x_obs, env.sim.x_aug)  # policies see noisy measurements
    q0 = env.sim.drone_position.copy()
    a = np.zeros(env.action_space.shape, dtype=np.float32)
    a[:8] = 0.5
    _, _, _, _, info0 = env.step(a)  # slot 0: a command slot
    assert not np.allclose(env.sim.drone_position, q0)  # the wind moved a drone that commanded no move
    _, _, _, _, info1 = env.step(a)  # slot 1: no command (control period 2)
    assert np.allclose(info1["applied_increment"], 0.0)
    assert np.abs(info0["applied_increment"]).max() > 0
    a_env = gym.make("lawn/Joint-v1", config="disturbed")
    b_env = gym.make("lawn/Joint-v1", config="disturbed")
    oa, _ = a_env.reset(seed=3)
    ob, _ = b_env.reset(seed=3)
    for _ in range(10):
        act = np.full(a_env.action_space.shape, 0.1, dtype=np.float32)
        oa, ra, *_ = a_env.step(act)
        ob, rb, *_ = b_env.step(act)
        assert np.array_equal(oa, ob) and ra == rb


def _session_processes(sid: int) -> list[int]:
    """PIDs of live processes in session ``sid`` (read from /proc: field 6 of /proc/PID/stat)."""
    out = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as fh:
                fields = fh.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[3]) == sid and fields[0] != "Z":
            out.append(int(entry))
    return out


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_killed_sweep_leaves_no_worker_processes(tmp_path, sig):
    """Killing `lawn sweep --workers 2` (SIGKILL or SIGTERM) leaves no process behind,
    and the rows it finished are kept."""
    spec = dict(SPEC, seeds=6, set={"num_slots": 30})
    spec_file = tmp_path / "spec.json"
    spec_file.write_text(json.dumps(spec))
    table = tmp_path / "k.csv"
    cmd = [sys.executable, "-m", "lawn_cli", "sweep", str(spec_file), "--out", str(table), "--workers", "2",
           "--quiet"]
    proc = subprocess.Popen(cmd, cwd=os.getcwd(), start_new_session=True)
    deadline = time.time() + 90
    while time.time() < deadline and len(read_table(table)) < 2:
        time.sleep(0.05)
    assert len(_session_processes(proc.pid)) >= 3  # the command and its two workers
    proc.send_signal(sig)
    proc.wait()
    deadline = time.time() + 10
    while time.time() < deadline and _session_processes(proc.pid):
        time.sleep(0.1)
    assert _session_processes(proc.pid) == []
    assert len(read_rows(table)[0]) >= 2


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_sweep_killed_twenty_times_then_resumed_equals_the_clean_table(tmp_path):
    """`lawn sweep --workers 2` killed at up to 20 random moments (SIGKILL or SIGTERM),
    resumed each time, then finished, writes the same file as an uninterrupted sweep, byte for byte
    apart from the decision-time columns; no process outlives a kill. The kills stop once a run
    has finished the table; at least 5 of them must have interrupted it (the sweep is sized for
    about 15 s of work on 2 cores, several runs' worth)."""
    spec = dict(SPEC, seeds=32, set={"num_slots": 120}, policies=["epa", "pid", "lqr"])
    total = 2 * 3 * 32
    spec_file = tmp_path / "spec.json"
    spec_file.write_text(json.dumps(spec))
    clean, table = tmp_path / "clean.csv", tmp_path / "killed.csv"
    base = [sys.executable, "-m", "lawn_cli", "sweep", str(spec_file), "--workers", "2", "--quiet", "--out"]
    subprocess.run(base + [str(clean)], cwd=os.getcwd(), check=True)
    rng = np.random.default_rng(12)
    interrupted = 0
    for _ in range(20):
        if table.exists() and len(read_table(table)) >= total:
            break
        proc = subprocess.Popen(base + [str(table)], cwd=os.getcwd(), start_new_session=True,
                                stderr=subprocess.DEVNULL)
        time.sleep(float(rng.uniform(1.0, 4.0)))
        proc.send_signal(signal.SIGKILL if rng.random() < 0.5 else signal.SIGTERM)
        proc.wait()
        deadline = time.time() + 10
        while time.time() < deadline and _session_processes(proc.pid):
            time.sleep(0.1)
        assert _session_processes(proc.pid) == []
        interrupted += not table.exists() or len(read_table(table)) < total
    assert interrupted >= 5, f"only {interrupted} kills interrupted the sweep"
    subprocess.run(base + [str(table)], cwd=os.getcwd(), check=True)

    def without_timing(path):
        lines = path.read_text().splitlines()
        header = lines[0].split(",")
        timing = {i for i, name in enumerate(header) if name.startswith("decision_time")}
        return [[v for i, v in enumerate(row) if i not in timing] for row in csv.reader(lines)]

    assert without_timing(table) == without_timing(clean)


def test_sweep_drops_a_row_whose_config_does_not_match_its_hash_and_reruns_it(tmp_path):
    small = dict(SPEC, grid={"channel.blocklength": [256]}, policies=["epa"], seeds=2)
    table = tmp_path / "t.csv"
    rows = run_sweep(small, table, progress=False)
    text = table.read_text()
    tampered = text.replace('""num_slots"": 8', '""num_slots"": 7', 1)  # CSV doubles the JSON's quotes
    assert tampered != text
    table.write_text(tampered)
    with pytest.warns(UserWarning, match="dropped 1 unusable rows.*its config does not match its config_hash"):
        again = run_sweep(small, table, progress=False)
    assert [r.result.control_cost for r in again] == [r.result.control_cost for r in rows]  # rerun: the same episode


def test_sweep_refuses_an_unknown_backend(tmp_path):
    with pytest.raises(ValueError, match="unknown backend 'slurm'; valid: process, ray"):
        run_sweep(dict(SPEC, seeds=1, policies=["epa"]), tmp_path / "b.csv", backend="slurm", progress=False)


def test_sweep_reruns_when_policy_arguments_or_the_version_change(tmp_path, monkeypatch):
    import lawn_env

    small = dict(SPEC, grid={"channel.blocklength": [256]}, policies=["ao-mpc"], seeds=1)
    table = tmp_path / "t.csv"
    first = run_sweep(small, table, progress=False)
    tuned = dict(small, policy_args={"ao-mpc": {"tolerance": 1e-3}})
    with pytest.raises(SweepTableError, match="holds 1 rows"):
        run_sweep(tuned, table, progress=False)  # another policy argument: not this sweep's row
    both = run_sweep(tuned, table, progress=False, extend=True)
    assert sorted(r.policy_args for r in both) == ['{"tolerance": 0.001}', "{}"]
    monkeypatch.setattr(lawn_env, "__version__", "99.0.0")
    with pytest.raises(SweepTableError, match="another lawn version than 99.0.0"):
        run_sweep(small, table, progress=False)
    newer = run_sweep(small, table, progress=False, extend=True)
    assert sorted(r.lawn_version for r in newer) == sorted([first[0].lawn_version] * 2 + ["99.0.0"])


def test_summarize_sweep_gives_the_mean_and_interval_per_point_and_policy():
    from evaluation.episode import EpisodeResult
    from evaluation.stats import mean_ci
    from evaluation.sweep import SweepRow, summarize_sweep

    rows = [SweepRow("s", {"g": g}, EpisodeResult(p, "lawn/Joint-v1", i, control_cost=c, rmse_m=1.0, outage_rate=0.0),
                     "0", "h", "{}", "{}")
            for i, (g, p, c) in enumerate([("1", "a", 10.0), ("1", "a", 14.0), ("1", "b", 3.0), ("2", "a", 5.0),
                                            ("2", "a", 7.0)])]
    lines = summarize_sweep(rows, ["g"]).splitlines()
    assert lines[0] == "| g | policy | runs | control_cost | rmse_m | outage_rate |" and lines[1] == "|---|" * 1 + "---|" * 5
    mean, half = mean_ci([10.0, 14.0])
    assert lines[2] == f"| 1 | a | 2 | {mean:.4g} ± {half:.2g} | 1 ± 0 | 0 ± 0 |"
    assert lines[3] == "| 1 | b | 1 | 3 ± nan | 1 ± nan | 0 ± nan |"  # one run: no interval
    assert lines[4].startswith("| 2 | a | 2 | 6 ± ") and len(lines) == 5
