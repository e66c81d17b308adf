"""farsighter inspect: probes of trained runs (farsighter/probes.py), from Python and the CLI."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from farsighter import load_agent, make_config, train
from farsighter.cli import main as cli_main
from farsighter.probes import (
    MAX_STEPS,
    action_gaps,
    discounted_returns,
    next_to_goal,
    optimal_q,
    tabular_values,
    terminal_states,
    value_calibration,
    walk_states,
)

# ---------------------------------------------------------------------------- action-gaps


def test_gaps_are_read_from_the_runs_own_q_at_the_walked_states(
    tmp_path: Path, tiny_config: Any
) -> None:
    """The walk is the run's environment's (reproducible, episodes end or stop at MAX_STEPS),
    and every figure is the agent's own Q there: the best against the second-best action, the
    predictive sd of the greedy action."""
    train(tiny_config("farsighter", tmp_path / "run", env="Acrobot-v1", total_steps=300))
    policy = load_agent(tmp_path / "run")
    states = walk_states(policy, 3)
    assert 3 <= len(states) <= 3 * MAX_STEPS and states.shape[1] == 6
    np.testing.assert_array_equal(states, walk_states(load_agent(tmp_path / "run"), 3))
    row = action_gaps(tmp_path / "run", 3)
    q, var = policy.agent.q_estimate(states)
    q = np.asarray(q, dtype=np.float64)
    assert row["states"] == len(states)
    top = np.sort(q, axis=1)[:, -2:]  # three actions: the second best is not the worst
    assert row["gap_median"] == pytest.approx(np.median(top[:, 1] - top[:, 0]), abs=1e-5)
    assert row["best_q_max"] == pytest.approx(q.max(), abs=1e-4)
    assert row["best_q_median"] == pytest.approx(np.median(q.max(axis=1)), abs=1e-4)
    greedy_sd = np.sqrt(np.asarray(var)[np.arange(len(q)), q.argmax(axis=1)])
    assert row["predictive_sd_median"] == pytest.approx(np.median(greedy_sd), rel=1e-4)
    # an agent without a posterior has no sd to report
    train(tiny_config("ddqn", tmp_path / "ddqn", env="CartPole-v1", total_steps=300))
    assert "predictive_sd_median" not in action_gaps(tmp_path / "ddqn", 2)


# ---------------------------------------------------------------------------- tabular-values


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
    row = tabular_values(tmp_path / "run")
    assert (row["algo"], row["env"], row["seed"]) == ("ddqn", "FrozenLake-v1", cfg.seed)
    assert row["start_state"]["q_star"][0] == pytest.approx(0.542, abs=1e-3)
    right, live = (int(x) for x in row["greedy_is_optimal"].split("/"))
    assert live == 11 and 0 <= right <= live
    assert {w["state"] for w in row["next_to_goal_wrong"]} <= {14}


# ---------------------------------------------------------------------------- value-calibration


def test_discounted_returns_run_backwards_from_the_last_step() -> None:
    g = discounted_returns([0.0, 0.0, 1.0], 0.9)
    np.testing.assert_allclose(g, [0.81, 0.9, 1.0])
    assert discounted_returns([2.0], 0.5).tolist() == [2.0]


def test_calibrate_compares_q_with_the_return_that_followed(
    tmp_path: Path, tiny_config: Any
) -> None:
    # CartPole pays 1 a step, so G_0 of an episode of length T is (1 - 0.99^T) / 0.01
    train(tiny_config("ddqn", tmp_path / "run", total_steps=600, learning_starts=100, eval_every=0))
    row = value_calibration(tmp_path / "run", episodes=1, seed=7, max_return=100.0)
    assert row["env"] == "CartPole-v1" and row["episodes"] == 1
    assert row["ended_share"] == 1.0  # an untrained pole falls long before the time limit
    steps = row["states"]  # one episode: its length T, one reward of 1 a step
    assert row["return_start_mean"] == pytest.approx((1 - 0.99**steps) / 0.01, rel=1e-4)
    # Q at the start: the run's Q of its greedy action at the reset state of seed 7
    policy = load_agent(tmp_path / "run")
    env = policy.make_env(seed=7)
    obs, _ = env.reset(seed=7)
    q, _ = policy.agent.q_estimate(np.asarray(obs)[None])
    env.close()
    assert row["q_start_mean"] == pytest.approx(float(q[0].max()), abs=1e-4)
    assert row["q_max"] >= row["q_start_mean"] - 1e-4
    assert row["share_above_max_return"] == 0.0  # 600 steps of learning: Q far below 100


# ---------------------------------------------------------------------------- command line


def test_the_command_prints_and_writes_one_row_per_run(
    tmp_path: Path, tiny_config: Any, capsys: pytest.CaptureFixture[str]
) -> None:
    train(tiny_config("ddqn", tmp_path / "run", total_steps=300, eval_every=0))
    out = tmp_path / "out" / "gaps.json"
    run = str(tmp_path / "run")
    assert cli_main(["inspect", "action-gaps", run, run, "--episodes", "2", "--out", str(out)]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed == json.loads(out.read_text())
    assert printed["probe"] == "action-gaps" and printed["episodes"] == 2
    assert printed["command"].startswith("farsighter inspect action-gaps ")
    assert [r["run_dir"] for r in printed["runs"]] == [run, run]
    assert printed["runs"][0] == action_gaps(run, 2)
    # CartPole publishes no transition table: one line, exit 2
    assert cli_main(["inspect", "tabular-values", run]) == 2
    assert "no transition table" in capsys.readouterr().err


def test_bad_input_is_one_line_and_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli_main(["inspect", "--help"]) == 0
    assert "value-calibration" in capsys.readouterr().out
    assert cli_main(["inspect", "nope", "x"]) == 2
    assert "unknown probe 'nope'; accepted: action-gaps" in capsys.readouterr().err
    assert cli_main(["inspect", "value-calibration"]) == 2
    assert "one or more run directories" in capsys.readouterr().err
