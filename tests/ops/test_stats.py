"""farsighter.stats: the bootstrap interval covers what it should, and the three-outcome verdict."""

from __future__ import annotations

import numpy as np
import pytest

from farsighter.stats import DiffCI, bootstrap_diff, statistic, verdict


def test_ci_covers_the_true_difference_of_means() -> None:
    # 200 independent experiments with known means 3 and 1: a 95% interval should cover the true
    # difference 2 in most of them (percentile bootstrap with 20 seeds undercovers a little).
    rng = np.random.default_rng(123)
    covered = 0
    for i in range(200):
        a, b = rng.normal(3.0, 1.0, 20), rng.normal(1.0, 2.0, 20)
        ci = bootstrap_diff(a, b, n_boot=2_000, seed=i)
        assert ci.lo <= ci.diff <= ci.hi
        assert ci.diff == pytest.approx(a.mean() - b.mean())
        covered += ci.lo <= 2.0 <= ci.hi
    assert 0.88 <= covered / 200 <= 0.99


def test_ci_narrows_with_more_seeds_and_excludes_zero_for_a_clear_gap() -> None:
    rng = np.random.default_rng(0)
    small = bootstrap_diff(rng.normal(2, 1, 5), rng.normal(0, 1, 5))
    large = bootstrap_diff(rng.normal(2, 1, 200), rng.normal(0, 1, 200))
    assert large.hi - large.lo < small.hi - small.lo
    assert large.lo > 0 and large.lo < 2.0 < large.hi
    assert (large.n_a, large.n_b) == (200, 200)
    assert "percentile bootstrap" in large.method


def test_identical_constant_groups_do_not_hold() -> None:
    for value in (0.0, 1.0, 0.1, -200.0):  # 0.1: the resampled means must not differ by an ulp
        ci = bootstrap_diff([value] * 5, [value] * 3)
        assert (ci.diff, ci.lo, ci.hi) == (0.0, 0.0, 0.0)
        assert verdict(ci) == "does not hold"
        assert verdict(ci, higher_is_better=False) == "does not hold"
    ci = bootstrap_diff([0.1] * 4, [0.1] * 4, stat="var")
    assert (ci.lo, ci.hi) == (0.0, 0.0) and verdict(ci) == "does not hold"


def test_clearly_separated_groups_in_each_direction() -> None:
    high, low = [10.0, 11.0, 12.0, 10.5, 11.5], [0.0, 1.0, -1.0, 0.5, 0.2]
    up = bootstrap_diff(high, low)
    assert up.lo > 0
    assert verdict(up, higher_is_better=True) == "holds"
    assert verdict(up, higher_is_better=False) == "does not hold"
    down = bootstrap_diff(low, high)
    assert down.hi < 0
    assert verdict(down, higher_is_better=True) == "does not hold"
    assert verdict(down, higher_is_better=False) == "holds"
    # 5/5 solved against 0/5: every resample differs by exactly 1
    solved = bootstrap_diff([1.0] * 5, [0.0] * 5)
    assert (solved.lo, solved.hi) == (1.0, 1.0) and verdict(solved) == "holds"


def test_overlapping_noisy_groups_with_three_seeds_are_undecided() -> None:
    ci = bootstrap_diff([1.0, 5.0, 3.0], [2.0, 4.5, 2.5])
    assert ci.lo < 0 < ci.hi
    assert verdict(ci) == "undecided"
    assert verdict(ci, higher_is_better=False) == "undecided"


def test_fewer_than_two_seeds_is_undecided() -> None:
    one = bootstrap_diff([100.0], [0.0, 0.0, 0.0])
    assert one.lo == one.hi == 100.0 and one.n_a == 1
    assert verdict(one) == "undecided"
    empty = bootstrap_diff([], [1.0, 2.0])
    assert np.isnan(empty.diff) and verdict(empty) == "undecided"
    assert verdict(DiffCI(0.0, 0.0, 0.0, 1, 5, "")) == "undecided"


def test_interval_touching_zero_is_undecided() -> None:
    assert verdict(DiffCI(1.0, 0.0, 2.0, 5, 5, "")) == "undecided"
    assert verdict(DiffCI(-1.0, -2.0, 0.0, 5, 5, ""), higher_is_better=False) == "undecided"


def test_var_stat_matches_np_var() -> None:
    a, b = np.array([1.0, 4.0, 2.0, 8.0]), np.array([3.0, 3.5, 2.0])
    ci = bootstrap_diff(a, b, stat="var")
    assert ci.diff == pytest.approx(np.var(a) - np.var(b))
    assert statistic(a, "var") == pytest.approx(np.var(a))
    assert statistic(a) == pytest.approx(a.mean())
    # a single resample of identical values has variance 0: the interval reaches below the point
    assert ci.lo < ci.diff < ci.hi
    # the replicate variances are population variances (ddof=0): with one value per group every
    # resample has variance exactly 0
    assert bootstrap_diff([5.0], [7.0], stat="var").hi == 0.0


def test_deterministic_for_a_fixed_seed() -> None:
    a, b = [1.0, 2.5, 3.0, 0.5], [0.0, 2.0, 1.0]
    assert bootstrap_diff(a, b, seed=7) == bootstrap_diff(a, b, seed=7)
    assert bootstrap_diff(a, b, seed=7) != bootstrap_diff(a, b, seed=8)


def test_bad_input_is_refused() -> None:
    with pytest.raises(ValueError, match="stat"):
        bootstrap_diff([1.0, 2.0], [1.0, 2.0], stat="median")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="non-finite"):
        bootstrap_diff([1.0, float("nan")], [1.0, 2.0])
    with pytest.raises(ValueError, match="confidence"):
        bootstrap_diff([1.0, 2.0], [1.0, 2.0], confidence=1.0)
    with pytest.raises(ValueError, match="n_boot"):
        bootstrap_diff([1.0, 2.0], [1.0, 2.0], n_boot=0)
