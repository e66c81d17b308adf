"""benchmarks/minigrid_behaviour.py: what an agent does in a MiniGrid room while it trains."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.minigrid_behaviour import record, summarise

pytest.importorskip("minigrid")


def test_summarise_counts_runs_cells_and_goals() -> None:
    # episode 1: turn, turn, forward, forward (3 cells); episode 2: done x3 at one cell, a goal
    steps = [
        (1, 0, (1, 1), 0.0),
        (2, 0, (1, 1), 0.0),
        (3, 2, (2, 1), 0.0),
        (4, 2, (3, 1), 0.0),
        (1, 6, (1, 1), 0.0),
        (2, 6, (1, 1), 0.0),
        (3, 6, (1, 1), 0.9),
        (1, 2, (2, 1), 0.0),  # opens a third episode, which closes the second
    ]
    w = summarise(steps, 0, 8)
    assert w["actions"] == {0: 2, 2: 3, 6: 3}
    # runs of one action: 1 2 | 1 2 | 1 2 3 | 1  -> mean 13 / 8
    assert w["mean_same_action_run"] == pytest.approx(13 / 8, abs=1e-3)
    assert w["cells_per_episode"] == pytest.approx((3 + 1) / 2)  # the open third is not counted
    assert w["goals"] == 1 and w["steps"] == [0, 8]
    assert summarise(steps, 4, 7)["goals"] == 1 and summarise(steps, 0, 4)["goals"] == 0


def test_record_sees_every_training_step(tmp_path: Path) -> None:
    run = tmp_path / "run"
    args = ["--algo", "ddqn", "--env", "MiniGrid-Empty-5x5-v0", "--total-steps", "300"]
    args += [
        "--eval-every",
        "100000",
        "--no-progress",
        "--torch-threads",
        "1",
        "--run-dir",
        str(run),
    ]
    args += ["--learning-starts", "100", "--hidden-sizes", "16", "16"]
    steps = record(args)
    # the 300 training steps, then the final evaluation's (10 episodes, each its own reset)
    assert len(steps) > 300 and sum(1 for c, *_ in steps[300:] if c == 1) >= 10
    assert all(0 <= a <= 6 for _, a, _, _ in steps)
    assert all(1 <= x <= 3 and 1 <= y <= 3 for _, _, (x, y), _ in steps)  # the room's 3 x 3 cells
    assert steps[0][0] == 1  # the first step of the first episode
