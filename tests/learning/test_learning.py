"""The default suite's real learning check (about 30 s on one core): Farsighter (k = 10) finds
the distant apple of the bridge maze and its final greedy policy walks there. A failure returns
exactly -200 (the time limit); the optimal return is 75."""

from __future__ import annotations

import csv
from pathlib import Path

from farsighter import train
from farsighter.studies.maze import AGENTS, run_config


def test_farsighter_solves_the_bridge_maze_in_40k_steps(tmp_path: Path) -> None:
    agent = next(a for a in AGENTS if a.label == "Farsighter (k=10)")
    train(run_config(agent, 1, 40_000, tmp_path / "maze"))
    with (tmp_path / "maze" / "eval.csv").open() as fh:
        final = [float(r["eval_return_mean"]) for r in csv.DictReader(fh)][-1]
    assert final > 50, final  # reaches the apple, near the optimal return of 75
