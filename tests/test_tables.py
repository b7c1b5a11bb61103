"""evaluation (run, stats): the one CSV writer and reader of the reports and the summary statistics."""

import math

import numpy as np
import pytest
from scipy import stats

from evaluation.episode import parse_bool, read_csv, write_csv
from evaluation.stats import mean_ci


@pytest.mark.parametrize("atomic", [False, True])
def test_csv_rows_round_trip_with_the_union_of_their_keys(tmp_path, atomic):
    rows = [{"policy": "epa", "seed": 0, "cost": 1.5}, {"policy": "sf", "seed": 1, "cost": 2.25, "extra": True}]
    path = write_csv(rows, tmp_path / "t.csv", atomic=atomic)
    back = read_csv(path)
    assert list(back[0]) == ["policy", "seed", "cost", "extra"]
    assert back == [{"policy": "epa", "seed": "0", "cost": "1.5", "extra": ""},
                    {"policy": "sf", "seed": "1", "cost": "2.25", "extra": "True"}]
    assert parse_bool(back[1]["extra"]) is True and not list(tmp_path.glob("*.tmp"))
    assert read_csv(tmp_path / "absent.csv") == []


def test_parse_bool_accepts_both_spellings_and_names_a_bad_cell():
    assert [parse_bool(v) for v in (True, "true", "False", "1", 0, " TRUE ")] == [True, True, False, True, False, True]
    with pytest.raises(ValueError, match="'yes'"):
        parse_bool("yes")


def test_mean_ci_is_the_t_interval_and_nan_below_two_values():
    x = np.array([3.0, 5.0, 4.0, 8.0])
    mean, half = mean_ci(x)
    assert mean == pytest.approx(5.0)
    assert half == pytest.approx(stats.t.ppf(0.975, 3) * x.std(ddof=1) / 2.0)
    assert mean_ci([2.0])[0] == 2.0 and math.isnan(mean_ci([2.0])[1])
    assert all(math.isnan(v) for v in mean_ci([]))
