"""farsighter.aggregate: hand-checked point estimates, bootstrap intervals, and the written report."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rliable")  # an optional extra; a broken install still fails loudly

from farsighter.aggregate import (  # noqa: E402
    AGGREGATE_KEYS,
    METRICS,
    aggregate,
    iqm,
    per_task,
    performance_profile,
    probability_of_improvement,
    validate_scores,
    write_outputs,
)
from farsighter.errors import FarsighterError  # noqa: E402

# 4 runs x 2 tasks; the 8 values sorted are 0, 1, 2, 3, 4, 5, 9, 10.
TABLE = np.array([[0.0, 10.0], [1.0, 3.0], [2.0, 4.0], [9.0, 5.0]])


def noisy(seed: int, runs: int = 5, tasks: int = 4) -> np.ndarray:
    return np.random.default_rng(seed).normal(1.0, 0.5, size=(runs, tasks))


def test_point_estimates_match_hand_arithmetic() -> None:
    hand_iqm = (2 + 3 + 4 + 5) / 4  # the middle 50% of the sorted values
    assert iqm(TABLE) == pytest.approx(hand_iqm)
    (row,) = aggregate({"a": TABLE}, reps=200, gap_threshold=4.0)
    assert row["iqm"] == pytest.approx(hand_iqm)
    task_means = [(0 + 1 + 2 + 9) / 4, (10 + 3 + 4 + 5) / 4]
    assert row["mean"] == pytest.approx((task_means[0] + task_means[1]) / 2)
    assert row["median"] == pytest.approx((task_means[0] + task_means[1]) / 2)
    # mean of max(4 - x, 0) over the 8 values: 4 + 3 + 2 + 1 from 0..3, nothing from the rest.
    assert row["optimality_gap"] == pytest.approx((4 + 3 + 2 + 1) / 8)
    assert (row["agent"], row["runs"], row["tasks"]) == ("a", 4, 2)
    assert tuple(row) == AGGREGATE_KEYS


def test_median_is_over_task_means() -> None:
    x = np.array([[1.0, 10.0, 4.0], [3.0, 20.0, 2.0]])  # task means 2, 15, 3
    (row,) = aggregate({"a": x}, reps=200)
    assert row["median"] == pytest.approx(3.0)
    assert row["mean"] == pytest.approx((2 + 15 + 3) / 3)


def test_per_task_rows() -> None:
    rows = per_task({"a": TABLE, "b": TABLE[:1]}, ["t0", "t1"])
    assert [(r["agent"], r["task"]) for r in rows] == [
        ("a", "t0"),
        ("a", "t1"),
        ("b", "t0"),
        ("b", "t1"),
    ]
    assert rows[0]["mean"] == pytest.approx(3.0)
    assert rows[0]["std"] == pytest.approx(np.std([0, 1, 2, 9], ddof=1))
    assert rows[2] == {"agent": "b", "task": "t0", "mean": 0.0, "std": 0.0, "runs": 1}


def test_ci_contains_the_point_estimate() -> None:
    rows = aggregate({"a": noisy(1), "b": noisy(2) + 0.3}, reps=200)
    for row in rows:
        for m in METRICS:
            assert row[f"{m}_lo"] <= row[m] <= row[f"{m}_hi"], (row["agent"], m)
            assert row[f"{m}_lo"] < row[f"{m}_hi"]


@pytest.mark.parametrize("runs", [1, 5])
def test_ci_is_degenerate_when_runs_agree(runs: int) -> None:
    x = np.tile([0.2, 0.7, 1.3], (runs, 1))
    (row,) = aggregate({"a": x}, reps=200)
    for m in METRICS:
        assert row[f"{m}_lo"] == row[m] == row[f"{m}_hi"]


def test_one_task_one_run() -> None:
    (row,) = aggregate({"a": np.array([[0.5]])}, reps=50)
    assert row["iqm"] == row["iqm_lo"] == row["iqm_hi"] == pytest.approx(0.5)
    assert row["optimality_gap"] == pytest.approx(0.5)
    assert per_task({"a": [[0.5]]}, ["t"])[0]["std"] == 0.0


def test_same_seed_same_rows_and_global_rng_untouched() -> None:
    scores = {"a": noisy(3), "b": noisy(4)}
    np.random.seed(123)  # noqa: NPY002
    first = aggregate(scores, reps=200, seed=7)
    # The global state is back where it was: the next draw is the first draw after seed(123).
    assert np.random.random_sample() == np.random.RandomState(123).random_sample()  # noqa: NPY002
    assert aggregate(scores, reps=200, seed=7) == first
    other = aggregate(scores, reps=200, seed=8)
    assert other != first
    assert [r["iqm"] for r in other] == [r["iqm"] for r in first]  # only the CIs move


def test_probability_of_improvement() -> None:
    y = noisy(5)
    scores = {"x": y + 10.0, "y": y, "same": y.copy()}
    dominates, identical = probability_of_improvement(scores, [("x", "y"), ("same", "y")], reps=200)
    assert (dominates["x"], dominates["y"]) == ("x", "y")
    assert dominates["probability"] == dominates["lo"] == dominates["hi"] == 1.0
    assert identical["probability"] == 0.5
    assert identical["lo"] <= 0.5 <= identical["hi"]


def test_probability_of_improvement_counts_ties_as_half() -> None:
    # X runs {1, 3} against Y runs {1, 2}: (1 vs 1) tie = 0.5, (1 vs 2) = 0, (3 vs 1) = 1,
    # (3 vs 2) = 1, over 4 pairs.
    scores = {"x": np.array([[1.0], [3.0]]), "y": np.array([[1.0], [2.0]])}
    (row,) = probability_of_improvement(scores, [("x", "y")], reps=200)
    assert row["probability"] == pytest.approx((0.5 + 0 + 1 + 1) / 4)
    assert row["lo"] <= row["probability"] <= row["hi"]
    # Run counts may differ: a third Y run adds (1 vs 4) = 0 and (3 vs 4) = 0.
    scores["y"] = np.array([[1.0], [2.0], [4.0]])
    (row,) = probability_of_improvement(scores, [("x", "y")], reps=50)
    assert row["probability"] == pytest.approx((0.5 + 0 + 1 + 1 + 0 + 0) / 6)
    with pytest.raises(FarsighterError, match="unknown agent"):
        probability_of_improvement(scores, [("x", "z")], reps=10)


def test_performance_profile_bounds() -> None:
    x = noisy(6)
    prof = performance_profile({"a": x}, [x.min() - 1, x.max() + 1], reps=200)
    profile, lo, hi = prof["a"]
    assert profile.tolist() == lo.tolist() == hi.tolist() == [1.0, 0.0]
    mid = float(np.median(x))
    (profile, lo, hi) = performance_profile({"a": x}, [mid], reps=200)["a"]
    assert profile[0] == pytest.approx(np.mean(x > mid))
    assert lo[0] <= profile[0] <= hi[0]


@pytest.mark.parametrize(
    ("scores", "tasks", "message"),
    [
        ({}, None, "empty"),
        ({"a": np.zeros(3)}, None, "2-D"),
        ({"a": np.zeros((2, 2, 2))}, None, "2-D"),
        ({"a": np.zeros((0, 2))}, None, "no runs"),
        ({"a": np.zeros((2, 2)), "b": np.zeros((2, 3))}, None, "different task counts"),
        ({"a": np.zeros((2, 2))}, ["t0", "t1", "t2"], "len\\(tasks\\)"),
        ({"a": np.array([[0.0, np.nan]])}, None, "NaN"),
    ],
)
def test_validate_scores_errors(scores: dict, tasks: list[str] | None, message: str) -> None:
    with pytest.raises(FarsighterError, match=message):
        validate_scores(scores, tasks)


def test_validate_scores_returns_float_arrays() -> None:
    out = validate_scores({"a": [[1, 2]]}, ["t0", "t1"])
    assert out["a"].dtype == np.float64 and out["a"].shape == (1, 2)


def read_header(path: Path) -> list[str]:
    with path.open(newline="") as f:
        return next(csv.reader(f))


def test_write_outputs(tmp_path: Path) -> None:
    scores = {
        "farsighter": noisy(7, runs=3, tasks=2) + 0.5,
        "ddqn": noisy(8, 3, 2),
        "rnd": noisy(9, 3, 2),
    }
    paths = write_outputs(tmp_path, scores, ["A", "B"], normalized_name="human-normalised", reps=50)
    names = ["per_task.csv", "aggregate.csv", "aggregate.md", "probability_of_improvement.csv"]
    names += ["figures/aggregate.png", "figures/profiles.png"]
    assert sorted(paths.values()) == sorted(tmp_path / n for n in names)
    assert read_header(tmp_path / "per_task.csv") == ["agent", "task", "mean", "std", "runs"]
    assert read_header(tmp_path / "aggregate.csv") == list(AGGREGATE_KEYS)
    with (tmp_path / "probability_of_improvement.csv").open(newline="") as f:
        poi = list(csv.DictReader(f))
    assert [(r["x"], r["y"]) for r in poi] == [("farsighter", "ddqn"), ("farsighter", "rnd")]
    md = (tmp_path / "aggregate.md").read_text()
    assert "| Agent | Runs | Tasks | IQM | Mean | Median | Optimality gap |" in md
    assert "stratified bootstrap" in md and "50 reps" in md and "human-normalised" in md
    row = aggregate(scores, reps=50)[0]
    assert f"{row['iqm']:.2f} [{row['iqm_lo']:.2f}, {row['iqm_hi']:.2f}]" in md
    for png in ("aggregate.png", "profiles.png"):
        assert (tmp_path / "figures" / png).stat().st_size > 1000


def test_write_outputs_one_agent_one_run_one_task(tmp_path: Path) -> None:
    paths = write_outputs(tmp_path, {"a": np.array([[0.3]])}, ["t"], reps=20)
    assert "probability_of_improvement" not in paths
    assert not (tmp_path / "probability_of_improvement.csv").exists()
    assert (tmp_path / "figures" / "profiles.png").stat().st_size > 0


def test_minmax_normalization_per_task_over_all_agents() -> None:
    from farsighter.aggregate import minmax_normalized

    scores = {"a": np.array([[0.0, 5.0], [10.0, 5.0]]), "b": np.array([[5.0, 5.0]])}
    out = minmax_normalized(scores)
    # task 0 spans 0..10 over both agents; task 1 is constant (every run 5): 0
    np.testing.assert_allclose(out["a"], [[0.0, 0.0], [1.0, 0.0]])
    np.testing.assert_allclose(out["b"], [[0.5, 0.0]])
