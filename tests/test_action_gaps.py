"""benchmarks/action_gaps.py: a run's Q and its action gaps over random-walk states."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from benchmarks.action_gaps import MAX_STEPS, action_gaps, walk_states
from farsighter import load_agent, train


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
