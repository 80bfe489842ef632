"""eval.present.intervals: the bootstrap interval of a mean over cases, and the table of them."""
import numpy as np

from eval.present.intervals import CI, bootstrap_ci, interval_table


def test_a_constant_sample_has_a_point_interval_and_one_case_none():
    assert bootstrap_ci([2.5] * 7) == (2.5, 2.5)
    assert bootstrap_ci([1.0]) is None and bootstrap_ci([]) is None


def test_the_interval_holds_the_mean_and_is_seeded():
    v = np.random.default_rng(4).lognormal(size=40)
    lo, hi = bootstrap_ci(v)
    assert lo < v.mean() < hi and (lo, hi) == bootstrap_ci(v)
    mlo, mhi = bootstrap_ci(v, np.median)
    assert mlo <= np.median(v) <= mhi


def test_the_95_percent_interval_covers_the_true_mean_about_95_percent_of_the_time():
    """Coverage over 300 samples of 40 normal cases: within the binomial spread of 0.95
    (the percentile bootstrap runs a little short at this size, about 0.93-0.94)."""
    rng = np.random.default_rng(0)
    hits = 0
    for _ in range(300):
        lo, hi = bootstrap_ci(rng.normal(1.0, 2.0, 40))
        hits += lo <= 1.0 <= hi
    assert CI[0] == 0.95 and 0.89 <= hits / 300 <= 0.99, hits


def test_the_table_shows_each_methods_interval_with_the_columns_decimals():
    text = interval_table({"A": {"x": [1.0, 2.0, 3.0]}, "B": {"x": [5.0, 5.0, 5.0]}},
                          [("x", "X (%)", 2), ("y", "Y", 1)], 3)
    lines = text.splitlines()
    assert "95% percentile-bootstrap interval of the mean over the 3 cases" in lines[0]
    lo, hi = bootstrap_ci([1.0, 2.0, 3.0])
    assert lines[4] == f"| A | {lo:.2f} .. {hi:.2f} | -- |"
    assert lines[5] == "| B | 5.00 .. 5.00 | -- |"
    assert interval_table({"A": {"x": [1.0]}}, [("x", "X", 1)], 1) == ""
