"""benchmarks/value_calibration.py: Q along greedy episodes against the returns that followed."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from benchmarks.value_calibration import calibrate, discounted_returns
from farsighter import load_agent, train


def test_discounted_returns_run_backwards_from_the_last_step() -> None:
    g = discounted_returns([0.0, 0.0, 1.0], 0.9)
    np.testing.assert_allclose(g, [0.81, 0.9, 1.0])
    assert discounted_returns([2.0], 0.5).tolist() == [2.0]


def test_calibrate_compares_q_with_the_return_that_followed(
    tmp_path: Path, tiny_config: Any
) -> None:
    # CartPole pays 1 a step, so G_0 of an episode of length T is (1 - 0.99^T) / 0.01
    train(tiny_config("ddqn", tmp_path / "run", total_steps=600, learning_starts=100, eval_every=0))
    row = calibrate(tmp_path / "run", episodes=1, seed=7, max_return=100.0)
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
