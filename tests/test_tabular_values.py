"""benchmarks/tabular_values.py: exact Q* of a transition table, and the states it reads."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from benchmarks.tabular_values import measure, next_to_goal, optimal_q, terminal_states
from farsighter import make_config, train


def test_optimal_q_of_a_two_state_table() -> None:
    # state 0: stop for 1, or move to state 1 for nothing; state 1: stop for 2, or move back
    table = {
        0: {0: [(1.0, 0, 1.0, True)], 1: [(1.0, 1, 0.0, False)]},
        1: {0: [(1.0, 1, 2.0, True)], 1: [(1.0, 0, 0.0, False)]},
    }
    q = optimal_q(table, 0.9)
    # Q(1, stop) = 2, Q(0, move) = 0.9 * 2, Q(1, back) = 0.9 * V(0) = 0.9 * 1.8
    np.testing.assert_allclose(q, [[1.0, 1.8], [2.0, 1.62]], atol=1e-8)
    # a noisy move: half the time it stays put, so Q(0, move) = 0.9 (0.5 V(1) + 0.5 V(0))
    table[0][1] = [(0.5, 1, 0.0, False), (0.5, 0, 0.0, False)]
    q = optimal_q(table, 0.9)
    v0, v1 = q[0].max(), q[1].max()
    assert q[0, 1] == pytest.approx(0.9 * (0.5 * v1 + 0.5 * v0))


def test_frozen_lake_ends_and_the_state_next_to_its_goal() -> None:
    table = gym.make("FrozenLake-v1").unwrapped.P  # type: ignore[attr-defined]
    ends = terminal_states(table)
    assert ends == {5, 7, 11, 12, 15}  # the four holes and the goal
    assert next_to_goal(table, ends) == [14]  # 11, the other neighbour of the goal, is a hole
    q = optimal_q(table, 0.99)
    assert q[14].argmax() == 1  # down: a slip either way is right (the goal) or left
    assert round(float(q[0].max()), 3) == 0.542


def test_measure_reads_a_trained_run(tmp_path: Path) -> None:
    cfg = make_config(
        "ddqn",
        "FrozenLake-v1",
        total_steps=600,
        learning_starts=100,
        eval_every=0,
        eval_episodes=1,
        run_dir=str(tmp_path / "run"),
        progress=False,
        torch_threads=1,
    )
    train(cfg)
    row = measure(tmp_path / "run")
    assert (row["algo"], row["env"], row["seed"]) == ("ddqn", "FrozenLake-v1", cfg.seed)
    assert row["start_state"]["q_star"][0] == pytest.approx(0.542, abs=1e-3)
    right, live = (int(x) for x in row["greedy_is_optimal"].split("/"))
    assert live == 11 and 0 <= right <= live
    assert {w["state"] for w in row["next_to_goal_wrong"]} <= {14}
