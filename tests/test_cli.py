import json

from training.cli import main


def test_demo_writes_metrics_and_plot(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--seed", "3", "--out", str(out), "--set", "num_slots=20"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["slots"] == 20 and metrics["control_cost"] > 0
    assert (out / "paths.png").stat().st_size > 10_000
    printed = capsys.readouterr().out
    assert "control_cost" in printed and "rmse_m" in printed


def test_demo_is_deterministic(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    main(["demo", "--seed", "1", "--out", str(a), "--set", "num_slots=15"])
    main(["demo", "--seed", "1", "--out", str(b), "--set", "num_slots=15"])
    ma, mb = (json.loads((p / "metrics.json").read_text()) for p in (a, b))
    ma.pop("decision_time_median_s"), mb.pop("decision_time_median_s")
    assert ma == mb


def test_bad_override_is_one_clear_error(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path), "--set", "channel.blocklength=0"]) == 2
    err = capsys.readouterr().err
    assert "channel.blocklength" in err and "greater than or equal to 1" in err
    assert main(["demo", "--out", str(tmp_path), "--set", "chanel.m=2"]) == 2
    assert "unknown config key 'chanel'" in capsys.readouterr().err
