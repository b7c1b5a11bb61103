"""Every row of the README's benchmark table replays its recorded episodes (evaluation/digests.py):
a change that moves any policy's episodes (ao-mpc and sf included) fails here until the digests and
the tables are regenerated in the same commit (scripts/refresh_docs.sh --only benchmark)."""

import json

import pytest

from evaluation import digests as benchmark
from paper.pages import ROOT, block_body, first_table

RECORDED = json.loads(benchmark.DIGESTS.read_text())


def test_the_digests_cover_every_row_of_the_readme_table():
    rows = [line.split("|")[1].strip() for line in first_table(block_body(ROOT / "README.md", "benchmark"))[2:]]
    assert rows == list(benchmark.README_ROWS) == list(RECORDED)
    assert all([r["seed"] for r in RECORDED[name]] == list(benchmark.DIGEST_SEEDS) for name in RECORDED)


@pytest.mark.parametrize("row", list(RECORDED))
def test_a_table_row_replays_its_recorded_episodes(row):
    now = [benchmark.episode_record(row, seed) for seed in benchmark.DIGEST_SEEDS]
    for before, after in zip(RECORDED[row], now):
        assert after == before, (
            f"{row}, seed {before['seed']}: control cost {after['control_cost']} now, {before['control_cost']} "
            "recorded; if the change is meant, regenerate the tables and the digests together "
            "(bash scripts/refresh_docs.sh --only benchmark)")


def test_a_changed_episode_changes_its_digest(monkeypatch):
    """One slot's stage cost moved in its tenth significant digit changes the digest; a last-bit
    difference does not."""
    record = benchmark.episode_record("epa", 0)
    real = benchmark.run_episode

    def moved(scale):
        def run(*args, **kwargs):
            row = real(*args, **kwargs)
            costs = row.stage_costs.copy()
            costs[7] *= scale
            return row.with_(stage_costs=costs)
        return run

    monkeypatch.setattr(benchmark, "run_episode", moved(1 + 1e-8))
    assert benchmark.episode_record("epa", 0)["digest"] != record["digest"]
    monkeypatch.setattr(benchmark, "run_episode", moved(1 + 1e-15))
    assert benchmark.episode_record("epa", 0)["digest"] == record["digest"]
