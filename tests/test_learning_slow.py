"""Small real learning runs (minutes each; excluded by default, run with ``pytest -m slow``).

Each one reproduces a figure of ``benchmarks/results/`` for one seed: the agent must reach the
score, not merely run. The full three-seed checks are ``python -m benchmarks.learning``.
"""

from __future__ import annotations

import csv
from pathlib import Path

import pytest
import torch

from farsighter import make_config, train

pytestmark = pytest.mark.slow


def _evals(run_dir: Path) -> list[float]:
    with (run_dir / "eval.csv").open() as fh:
        return [float(r["eval_return_mean"]) for r in csv.DictReader(fh)]


def _train(
    tmp_path: Path, algo: str, env: str, preset: str, steps: int, **kw: object
) -> list[float]:
    torch.set_num_threads(1)
    cfg = make_config(
        algo,
        env,
        preset=preset,
        seed=1,
        total_steps=steps,
        eval_every=5_000,
        eval_episodes=10,
        progress=False,
        device="cpu",
        checkpoint_every=0,
        run_dir=str(tmp_path / "run"),
        **kw,
    )
    train(cfg)
    return _evals(tmp_path / "run")


def test_farsighter_reaches_475_on_cartpole(tmp_path: Path) -> None:
    # benchmarks/results/learning_cartpole.json: seed 1 first reached 475 at 10k steps
    evals = _train(tmp_path, "farsighter", "CartPole-v1", "cartpole", 30_000, k=3)
    assert max(evals) >= 475, evals


def test_farsighter_naf_beats_minus_300_on_pendulum(tmp_path: Path) -> None:
    # benchmarks/results/learning_pendulum.json: seed 1 above -300 from 5k steps on
    evals = _train(tmp_path, "farsighter-naf", "Pendulum-v1", "continuous", 15_000, k=2)
    assert max(evals) > -300, evals


def test_farsighter_solves_the_bridge_maze(tmp_path: Path) -> None:
    # docs/results/maze: Farsighter (k=10) solves the maze greedily in 5 of 5 seeds at 40k
    from farsighter.studies.maze import AGENTS, run_config

    agent = next(a for a in AGENTS if a.label == "Farsighter (k=10)")
    train(run_config(agent, 1, 40_000, tmp_path / "maze"))
    assert _evals(tmp_path / "maze")[-1] > -200  # a failure is exactly -200 (time limit)
