import json

import pytest

from lawn_cli import main


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


def test_evaluate_writes_rows_csv_and_json(tmp_path, capsys):
    import csv

    out = tmp_path / "rows.csv"
    assert main(["evaluate", "--policy", "epa", "--episodes", "2", "--seed", "4", "--out", str(out),
                 "--set", "num_slots=12", "--workers", "1", "--quiet"]) == 0
    rows = list(csv.DictReader(out.open()))
    assert [r["seed"] for r in rows] == ["4", "5"] and all(r["policy"] == "epa" for r in rows)
    for key in ("control_cost", "rmse_m", "outage_rate", "decision_time_median_s", "decision_time_p95_s",
                "rmse_per_agv_m", "mean_power_w", "drone_path_length_m", "ao_iterations_mean"):
        assert key in rows[0]
    printed = capsys.readouterr().out
    assert "| epa | 2 |" in printed
    jout = tmp_path / "rows.json"
    assert main(["evaluate", "--policy", "pid", "--env", "lawn/Comm-v1", "--episodes", "1", "--out", str(jout),
                 "--set", "num_slots=8", "--quiet"]) == 0
    data = json.loads(jout.read_text())
    assert data[0]["env"] == "lawn/Comm-v1" and data[0]["slots"] == 8


def test_evaluate_rejects_bad_inputs(tmp_path, capsys):
    import pytest

    assert main(["evaluate", "--policy", "epa", "--out", str(tmp_path / "rows.txt"), "--quiet"]) == 2
    assert ".csv or .json" in capsys.readouterr().err
    assert main(["evaluate", "--policy", "ao-mpc", "--out", str(tmp_path / "r.csv"), "--policy-arg",
                 "tolerance=-2", "--quiet"]) == 2
    assert "tolerance" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["evaluate", "--policy", "nope", "--out", str(tmp_path / "r.csv")])
    assert "unknown policy 'nope'; valid: dv-mpc, dv-mpc-ce, rg-mpc" in capsys.readouterr().err


def test_parallel_evaluation_matches_serial(tmp_path):
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    args = ["evaluate", "--policy", "ao-mpc", "--episodes", "3", "--set", "num_slots=10", "--quiet"]
    assert main(args + ["--out", str(a), "--workers", "1"]) == 0
    assert main(args + ["--out", str(b), "--workers", "2"]) == 0
    ra, rb = json.loads(a.read_text()), json.loads(b.read_text())
    assert len(ra) == len(rb) == 3 and [x["seed"] for x in ra] == [0, 1, 2]
    for x, y in zip(ra, rb, strict=True):
        for key in ("seed", "control_cost", "rmse_m", "outage_rate", "mean_power_w"):
            assert x[key] == y[key]


def test_benchmark_writes_table_and_plot(tmp_path, capsys):
    out = tmp_path / "bench"
    assert main(["benchmark", "--policies", "ao-mpc", "epa", "--episodes", "2", "--out", str(out),
                 "--set", "num_slots=10", "--quiet"]) == 0
    for name in ("episodes.csv", "summary.csv", "summary.md", "benchmark.png"):
        assert (out / name).stat().st_size > 0
    table = (out / "summary.md").read_text()
    assert "| ao-mpc | 2 |" in table and "| epa | 2 |" in table
    assert "control cost" in capsys.readouterr().out


def test_the_benchmark_table_is_its_episodes_statistics(tmp_path):
    """summary.md's results table is the statistics of episodes.csv: its columns, one row per policy
    in order, each mean ± 95 % interval and the paired and geometric comparisons with the first
    policy recomputed from the rows."""
    from evaluation.cells import fmt_geometric, fmt_stat
    from evaluation.episode import read_results
    from evaluation.report import RESULT_METRICS
    from evaluation.stats import mean_ci, paired_difference, paired_geometric
    from paper.pages import first_table

    out = tmp_path / "bench"
    policies = ["epa", "pid", "sf"]
    assert main(["benchmark", "--policies", *policies, "--episodes", "3", "--out", str(out), "--set", "num_slots=10",
                 "--quiet", "--workers", "1"]) == 0
    rows = read_results(out / "episodes.csv")
    table = [[c.strip() for c in line.strip("|").split("|")] for line in first_table((out / "summary.md").read_text())]
    assert table[0] == ["policy", "episodes", *(label for _, label in RESULT_METRICS), "cost vs epa (paired)",
                        "cost vs epa (geometric [95 %], seeds won)"]
    assert [r[0] for r in table[2:]] == policies and all(r[1] == "3" for r in table[2:])
    costs = {p: {r.seed: r.control_cost for r in rows if r.policy == p} for p in policies}  # not the table's code
    paired = {p: paired_difference(costs[p], costs["epa"])[:2] for p in policies}
    geometric = {p: paired_geometric(costs[p], costs["epa"]) for p in policies}
    for cells in table[2:]:
        mine = [r.as_row() for r in rows if r.policy == cells[0]]
        for (key, _), cell in zip(RESULT_METRICS, cells[2:]):
            mean, half = mean_ci(float(r[key]) for r in mine)
            if key == "diverged":  # a count of the episodes flagged (an AGV past 25 m)
                assert cell == str(sum(int(r[key]) for r in mine)), (cells[0], key)
            else:
                assert cell == f"{fmt_stat(mean)} ± {fmt_stat(half)}", (cells[0], key)
        if cells[0] != "epa":
            mean, half = paired[cells[0]]
            assert cells[-2] == f"{mean * 100:+.1f} % ± {half * 100:.1f} %"
            assert cells[-1] == fmt_geometric(geometric[cells[0]])


def test_gap_command_writes_tables_and_figures(tmp_path, capsys):
    out = tmp_path / "gap"
    args = ["gap", "--policies", "ao-mpc", "rg-mpc", "--episodes", "1", "--every", "4", "--set", "num_slots=8",
            "--convergence-slots", "2", "--out", str(out), "--quiet", "--workers", "1",
            "--global-arg", "psi_points=41", "--global-arg", "drone_spacing_m=2.5", "--global-arg", "power_levels=40"]
    assert main(args) == 0
    for name in ("gap_rows.csv", "gap_summary.csv", "gap_summary.md", "gap.png", "convergence.csv", "convergence.png"):
        assert (out / name).stat().st_size > 0
    table = (out / "gap_summary.md").read_text()
    assert "| ao-mpc | 2 |" in table and "| rg-mpc | 2 |" in table
    printed = capsys.readouterr().out
    assert "slot 2: after iteration 1" in printed
    assert main(args[:-2] + ["--global-arg", "bogus=1", "--overwrite"]) == 2
    assert "bogus" in capsys.readouterr().err


def test_bad_counts_seeds_and_specs_are_one_line_errors(tmp_path, capsys):
    """Bad numbers fail at parse time (exit 2, naming the argument); bad sweep specs are
    one line naming the file and what is wrong, never a traceback or a silent exit 0."""
    import pytest

    for argv, needle in ((["evaluate", "--policy", "epa", "--episodes", "0", "--out", "x.csv"], "--episodes: 0 must be >= 1"),
                         (["benchmark", "--episodes", "-3"], "--episodes: -3 must be >= 1"),
                         (["gap", "--every", "0"], "--every: 0 must be >= 1"),
                         (["gap", "--every", "-1"], "--every: -1 must be >= 1"),
                         (["evaluate", "--policy", "epa", "--seed", "-1", "--out", "x.csv"], "--seed: -1 must be >= 0")):
        with pytest.raises(SystemExit) as exit_:
            main(argv)
        assert exit_.value.code == 2 and needle in capsys.readouterr().err
    specs = {"bad.yml": ("grid: [\n  x", "not valid YAML (line 2"), "empty.yml": ("", "an empty document"),
             "list.yml": ("- 1\n", "got list"), "scalar.yml": ("grid: {channel.blocklength: 256}", "non-empty list"),
             "none.yml": ("policies: []", "policies must be a non-empty list"), "neg.yml": ("seeds: -3", "seeds=-3"),
             "bad.json": ("{", "not valid JSON")}
    for name, (text, needle) in specs.items():
        (tmp_path / name).write_text(text)
        assert main(["sweep", str(tmp_path / name), "--out", str(tmp_path / "t.csv"), "--quiet"]) == 2
        err = capsys.readouterr().err
        assert needle in err and name in err and "Traceback" not in err and err.count("\n") == 1, err


def test_an_unwritable_out_fails_before_any_episode(tmp_path, capsys, monkeypatch):
    """The output location is checked before computing (a file where a folder is needed,
    a folder where a file is needed), with one line naming --out."""
    import evaluation.run
    import evaluation.sweep

    def no_work(*args, **kwargs):
        raise AssertionError("episodes ran before --out was checked")

    monkeypatch.setattr(evaluation.run, "pool_map", no_work)
    monkeypatch.setattr(evaluation.sweep, "execute", no_work)
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    assert main(["evaluate", "--policy", "rg-mpc", "--episodes", "50", "--out", str(blocker / "r.csv"), "--quiet"]) == 2
    assert main(["benchmark", "--episodes", "50", "--out", str(blocker / "bm"), "--quiet"]) == 2
    assert main(["sweep", "docs/sweeps/control-period.yml", "--out", str(tmp_path), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("--out") == 3 and "cannot write to" in err and "is a directory; give a file" in err


def _help(argv, capsys) -> str:
    with pytest.raises(SystemExit) as exit_:
        main(argv + ["--help"])
    assert exit_.value.code == 0
    return capsys.readouterr().out


def test_every_help_text_names_its_flags_defaults_and_choices(capsys):
    """``lawn --help`` lists every subcommand with its one-line help; each subcommand's help shows
    every flag with a help text, the shared flags from the one parent parser, and the registries'
    choices (presets, policies, env ids, figures)."""
    import lawn_env
    from agents import policy_names
    from lawn_cli import COMMANDS, build_parser
    from lawn_env import presets
    from paper.experiments import EXPERIMENTS

    root = _help([], capsys)
    names = [c.__name__.rsplit(".", 1)[-1] for c in COMMANDS]
    assert all(f"    {n}" in root for n in names) and "--version" in root
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    for name, parser in sub.choices.items():
        text = _help([name], capsys)
        flags = [o for a in parser._actions for o in a.option_strings if o.startswith("--")]
        assert all(f in text for f in flags), name
        assert [a.option_strings for a in parser._actions if a.option_strings and not a.help] == [], name
    shared = {"evaluate": ("--workers", "--quiet", "--seed", "--preset", "--set"), "gap": ("--workers", "--seed"),
              "figures": ("--workers", "--quiet"), "sweep": ("--workers", "--quiet"), "demo": ("--seed", "--set")}
    for name, flags in shared.items():
        text = _help([name], capsys)
        assert all(f in text for f in flags), name
        if "--workers" in flags:
            assert "processes (default: " in text
    evaluate = _help(["evaluate"], capsys)
    policy_flag = next(a for a in sub.choices["evaluate"]._actions if a.dest == "policy").help  # before wrapping
    assert all(p in policy_flag for p in policy_names()) and "zoo:NAME" in evaluate
    assert all(p in evaluate for p in presets.names()) and all(e in evaluate for e in lawn_env.ENV_IDS)
    assert "default: %" not in evaluate and "default: None" not in evaluate
    assert "first seed; episode i uses seed + i (default: 0)" in evaluate
    assert all(e in _help(["figures"], capsys) for e in EXPERIMENTS)
    assert "--protocol learned and --suite fix the test seeds" in _help(["benchmark"], capsys)


def test_shared_flags_keep_each_subcommand_s_defaults():
    """A subcommand's own default of a shared flag (benchmark's --seed: None, the paper protocol's 0)
    does not leak into the others (argparse shares a parent parser's actions)."""
    from lawn_cli import build_parser

    parser = build_parser()
    assert parser.parse_args(["benchmark"]).seed is None
    assert parser.parse_args(["evaluate", "--policy", "epa", "--out", "x.csv"]).seed == 0
    assert parser.parse_args(["gap"]).seed == 0 and parser.parse_args(["demo"]).seed == 0


def test_gap_compares_planners_only(tmp_path, capsys):
    assert main(["gap", "--policies", "anchor:stake", "--out", str(tmp_path / "g"), "--episodes", "1",
                 "--convergence-slots", "--set", "num_slots=4", "--quiet"]) == 2
    assert "--policies anchor:stake: the gap compares planners' per-slot plans" in capsys.readouterr().err


def test_the_top_level_help_imports_nothing_of_lawn():
    """``lawn --help`` and ``--version`` answer without loading lawn's compiled kernels."""
    import subprocess
    import sys

    script = ("import sys\nfrom lawn_cli import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
              "print(sorted(m for m in ('lawn_env', 'agents', 'numba') if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True, timeout=60)
    assert "evaluate" in done.stdout and done.stdout.strip().endswith("[]")


def test_comparisons_refuse_an_rl_id_naming_its_v0_id(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["evaluate", "--policy", "epa", "--env", "lawn/JointRL-v1", "--out", str(tmp_path / "r.csv")])
    err = capsys.readouterr().err
    assert "RL interface of 'lawn/Joint-v1'" in err and "pass --env lawn/Joint-v1" in err
    with pytest.raises(SystemExit):
        main(["benchmark", "--env", "lawn/Nope-v0", "--out", str(tmp_path / "b")])
    assert "unknown env id 'lawn/Nope-v0'; valid: lawn/Joint-v1, lawn/Comm-v1" in capsys.readouterr().err


def test_one_episode_commands_say_so_and_render_is_quiet(tmp_path, monkeypatch):
    import lawn_cli.render
    from lawn_cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    for name in ("render", "demo"):
        seed = next(a for a in sub.choices[name]._actions if a.dest == "seed")
        assert seed.help.startswith("the episode's seed"), name
    calls = []
    real = lawn_cli.render.render_episode  # the command's own name for it (imported at its top)
    monkeypatch.setattr(lawn_cli.render, "render_episode",
                        lambda *a, **k: calls.append(k["progress"]) or real(*a, **k))
    out = tmp_path / "e.gif"
    for flags in (["--quiet"], ["--overwrite"]):
        assert main(["render", "--policy", "epa", "--set", "num_slots=4", *flags, "--out", str(out)]) == 0
    assert calls == [False, True] and out.stat().st_size > 0


@pytest.mark.parametrize("argv, workers", [
    (["evaluate", "--policy", "epa", "--workers", "3"], 3),
    (["benchmark", "--workers=4"], 4),
    (["evaluate", "--work", "5"], 5),  # argparse's abbreviation
    (["gap", "--debug"], 2),  # the default on two cores
    (["evaluate", "--workers", "x"], 0),
    (["evaluate", "--workers", "\u00b2"], 0),  # a digit to str.isdigit, no count to int()
    (["evaluate", "--help"], 0),
    (["sweep", "--workers", "4"], 0),  # a pool of its own
    (["demo"], 0),
])
def test_the_early_start_reads_the_workers_of_a_parallel_command(argv, workers, monkeypatch):
    import os

    import lawn_cli as cli

    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    assert cli._early_workers(argv) == workers


def test_a_failed_command_does_not_wait_for_its_helpers(tmp_path):
    """The helpers start before the parser; a command the parser refuses ends them at once (a helper
    left starting would hold the exit for its whole start)."""
    import subprocess
    import sys

    script = ("import sys, multiprocessing as mp\nfrom lawn_cli import main\n"
              "sys.argv = ['lawn', 'evaluate', '--policy', 'nope', '--workers', '3', '--out', 'r.csv']\n"
              "try:\n    main()\nexcept SystemExit as e:\n    print('exit', e.code, len(mp.active_children()))\n")
    done = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert "unknown policy 'nope'" in done.stderr
    assert done.stdout.split() == ["exit", "2", "0"]


def test_evaluate_counts_its_rows_in_words(tmp_path, capsys):
    out = tmp_path / "one.csv"
    assert main(["evaluate", "--policy", "epa", "--episodes", "1", "--set", "num_slots=4", "--no-score", "--quiet",
                 "--workers", "1", "--out", str(out)]) == 0
    assert f"wrote 1 row to {out}" in capsys.readouterr().out


@pytest.mark.parametrize("policy, setting", [("rg-mpc", "power_levels=60"), ("ao-mpc", "tolerance=1e-3")])
def test_the_policy_arg_examples_of_the_help_run(tmp_path, policy, setting):
    from lawn_cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    help_text = next(a for a in sub.choices["evaluate"]._actions if a.dest == "policy_arg").help
    assert f"{setting} for {policy}" in help_text
    assert main(["evaluate", "--policy", policy, "--policy-arg", setting, "--episodes", "1", "--set", "num_slots=3",
                 "--no-score", "--quiet", "--workers", "1", "--out", str(tmp_path / "r.csv")]) == 0


def test_evaluate_without_out_writes_under_runs_evaluate(tmp_path, monkeypatch, capsys):
    """Without --out the rows go to runs/evaluate/POLICY.csv (':' and '/' as '_'), never the main job's
    runs/benchmark."""
    monkeypatch.chdir(tmp_path)
    assert main(["evaluate", "--policy", "anchor:hover", "--episodes", "1", "--set", "num_slots=6", "--no-score",
                 "--quiet"]) == 0
    assert (tmp_path / "runs" / "evaluate" / "anchor_hover.csv").is_file()
    assert not (tmp_path / "runs" / "benchmark").exists()
    assert "wrote 1 row to runs/evaluate/anchor_hover.csv" in capsys.readouterr().out
    (tmp_path / "runs" / "evaluate" / "epa.csv").mkdir()  # something in the way: the next free name, said
    assert main(["evaluate", "--policy", "epa", "--episodes", "1", "--no-score", "--quiet"]) == 0
    assert "runs/evaluate/epa.csv holds an earlier run's results; writing runs/evaluate/epa-2.csv" in \
        capsys.readouterr().out
    assert (tmp_path / "runs" / "evaluate" / "epa-2.csv").is_file()


# ---------------------------------------------------------------------- no result overwritten in silence
SHORT = ["--set", "num_slots=5"]
WRITERS = {  # command -> (its arguments without --out, the --out it is given: a file or a folder)
    "evaluate": (["evaluate", "--policy", "epa", "--episodes", "1", "--no-score", "--workers", "1", "--quiet", *SHORT],
                 "rows.csv"),
    "benchmark": (["benchmark", "--policies", "epa", "--episodes", "1", "--workers", "1", "--quiet", *SHORT], "bm"),
    "render": (["render", "--policy", "epa", "--quiet", "--set", "num_slots=3"], "episode.gif"),
    "demo": (["demo", *SHORT], "demo"),
    "gap": (["gap", "--policies", "rg-mpc", "--driver", "rg-mpc", "--episodes", "1", "--every", "4", "--set",
             "num_slots=4", "--convergence-slots", "1", "--quiet", "--workers", "1", "--global-arg", "psi_points=21",
             "--global-arg", "drone_spacing_m=5", "--global-arg", "power_levels=20"], "gap"),
}


def _contents(path):
    files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
    return {str(p): p.read_bytes() for p in files}


@pytest.mark.parametrize("command", list(WRITERS))
def test_an_out_holding_results_is_refused_unless_overwrite(command, tmp_path, capsys):
    args, name = WRITERS[command]
    out = tmp_path / name
    assert main([*args, "--out", str(out)]) == 0
    before = _contents(out)
    capsys.readouterr()
    assert main([*args, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"lawn {command}: error: --out {out} holds the results of an earlier run: pass --overwrite to "
                   "replace them, or give another --out"), err
    assert _contents(out) == before  # nothing written, nothing touched
    assert main([*args, "--out", str(out), "--overwrite"]) == 0


@pytest.mark.parametrize(("command", "default"), [("evaluate", "runs/evaluate/epa.csv"),
                                                  ("benchmark", "runs/benchmark-paper"), ("demo", "runs/demo"),
                                                  ("gap", "runs/gap")])
def test_a_default_out_holding_results_becomes_a_new_numbered_path(command, default, tmp_path, monkeypatch, capsys):
    """Without --out a command writes its default path, or where that holds an earlier run's results
    the first free NAME-2, NAME-3, ... (said); the earlier results stay as they were."""
    monkeypatch.chdir(tmp_path)
    args, _ = WRITERS[command]
    assert main(args) == 0
    first = tmp_path / default
    before = _contents(first)
    second = first.with_name(f"{first.stem}-2{first.suffix}")
    capsys.readouterr()
    assert main(args) == 0
    assert (f"lawn {command}: {default} holds an earlier run's results; writing {second.relative_to(tmp_path)}"
            in capsys.readouterr().out)
    assert _contents(first) == before and second.exists()
    assert main([*args, "--overwrite"]) == 0 and not first.with_name(f"{first.stem}-3{first.suffix}").exists()


def test_benchmark_never_writes_the_main_jobs_folder_by_default(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(WRITERS["benchmark"][0]) == 0
    assert (tmp_path / "runs" / "benchmark-paper" / "summary.md").exists()
    assert not (tmp_path / "runs" / "benchmark").exists()


def test_figures_resume_their_own_mode_and_refuse_the_other(tmp_path, capsys):
    """lawn figures keeps its tables and redraws from them on a rerun of its mode (mode.json); a
    folder of the other mode's figures is refused before any work, unless --overwrite."""
    from lawn_cli.figures import holds_results

    out = tmp_path / "figures"
    (out / "data").mkdir(parents=True)
    (out / "mode.json").write_text('{"mode": "full"}\n')
    (out / "rate.png").write_bytes(b"full figure")
    assert main(["figures", "rate", "--quick", "--out", str(out), "--quiet"]) == 2
    assert "--out " + str(out) + " holds the results of an earlier run" in capsys.readouterr().err
    assert (out / "rate.png").read_bytes() == b"full figure"

    class Args:
        quick = False

    assert not holds_results(Args(), out)  # the same mode resumes
    Args.quick = True
    assert holds_results(Args(), out) and not holds_results(Args(), tmp_path / "empty")
