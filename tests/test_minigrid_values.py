"""benchmarks/minigrid_values.py: a run's Q of stepping onto MiniGrid's goal, read at placements."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from benchmarks.minigrid_values import FORWARD, goal_values, observation_at
from farsighter import load_agent, train

pytest.importorskip("minigrid")
EMPTY = "MiniGrid-Empty-5x5-v0"


def test_a_placement_is_seen_as_the_environment_shows_it(tmp_path: Path, tiny_config: Any) -> None:
    """The observation of a placement is the one the run's wrapped environment returns when the
    agent walks there: a wrapper skipped or applied twice, or the wrong cell, fails."""
    train(tiny_config("ddqn", tmp_path / "run", env=EMPTY, total_steps=300, eval_every=0))
    policy = load_agent(tmp_path / "run")
    env = policy.make_env(seed=0)
    obs, _ = env.reset(seed=0)
    start = tuple(int(v) for v in env.unwrapped.agent_pos)
    assert start == (1, 1) and env.unwrapped.agent_dir == 0  # Empty's start: top left, facing +x
    walked, *_ = env.step(FORWARD)
    np.testing.assert_array_equal(observation_at(env, (2, 1), 0), walked)
    np.testing.assert_array_equal(observation_at(env, (1, 1), 0), obs)
    assert not np.array_equal(observation_at(env, (1, 1), 1), obs)  # another direction differs
    env.close()
    row = goal_values(tmp_path / "run")
    assert row["env"] == EMPTY and row["placements"] == 9 * 4 - 4  # 3 x 3 free cells, less the goal
    assert row["goal_pays_at_most"] == pytest.approx(1 - 0.9 / 100)  # T = 4 * 5 * 5
    beside = {tuple(b["cell"]): b for b in row["beside_goal"]}
    assert set(beside) == {(2, 3), (3, 2)}
    # Q of forward at (2, 3) facing +x: the run's Q of that observation
    env = policy.make_env(seed=0)
    env.reset(seed=0)
    q, _ = policy.agent.q_estimate(observation_at(env, (2, 3), 0)[None])
    env.close()
    assert beside[(2, 3)]["q_onto_goal"] == pytest.approx(float(q[0][FORWARD]), abs=1e-4)
    others = np.delete(np.asarray(q[0]), FORWARD)
    assert beside[(2, 3)]["q_best_other"] == pytest.approx(float(others.max()), abs=1e-4)
