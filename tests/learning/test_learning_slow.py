"""Small real learning runs (minutes each; excluded by default, run with ``pytest -m slow``).

Three seeds each, judged on the FINAL greedy evaluation (not the best one seen during training):
the agent must have learned and kept it. The default suite's one learning check is
``tests/learning/test_learning.py``.
"""

from __future__ import annotations

import csv
from pathlib import Path

import pytest
import torch

from farsighter import make_config, train

pytestmark = pytest.mark.slow

SEEDS = (1, 2, 3)


def known_failure(reason: str) -> pytest.MarkDecorator:
    """A seed measured to fail its check: strict, so a fix that makes it pass is noticed."""
    return pytest.mark.xfail(reason=reason, strict=True)


# Measured with the cartpole preset's fresh posterior (issue #12; the general preset's
# incremental refresh every 100 steps, residual-scaled sigma, propagating targets, a draw held per
# episode): final evaluations 490.0, 392.8, 480.3 at 30k. Before (Table 1's stale posterior),
# seeds 2 and 3 failed. Since the targets' noise is drawn as one normal per row and action (the
# same distribution, other draws; session 16): seeds 1 and 2 pass (seed 2: 500.0), seed 3
# reached 500.0 at 25k and fell to 28.2 at 30k (evaluations 184.2, 371.2, 199.3, 292.1, 500.0,
# 28.2), so 2 of 3 pass, as before.
CARTPOLE_SEEDS = (
    1,
    2,
    pytest.param(3, marks=known_failure("final evaluation 28.2 < 475 at 30k (measured)")),
)
MAZE_SEEDS = (
    1,
    pytest.param(2, marks=known_failure("final greedy episode fails at 40k (docs/results/maze)")),
    3,
)


def _evals(run_dir: Path) -> list[float]:
    with (run_dir / "eval.csv").open() as fh:
        return [float(r["eval_return_mean"]) for r in csv.DictReader(fh)]


def _train(
    tmp_path: Path, algo: str, env: str, preset: str, steps: int, seed: int, **kw: object
) -> list[float]:
    torch.set_num_threads(1)
    cfg = make_config(
        algo,
        env,
        preset=preset,
        seed=seed,
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


@pytest.mark.parametrize("seed", CARTPOLE_SEEDS)
def test_farsighter_balances_cartpole(tmp_path: Path, seed: int) -> None:
    evals = _train(tmp_path, "farsighter", "CartPole-v1", "cartpole", 30_000, seed, k=3)
    assert evals[-1] >= 475, evals


@pytest.mark.parametrize("seed", SEEDS)
def test_farsighter_naf_swings_up_pendulum(tmp_path: Path, seed: int) -> None:
    # benchmarks/results/learning_pendulum.json: final evaluations -109, -128, -132 at 30k
    evals = _train(tmp_path, "farsighter-naf", "Pendulum-v1", "continuous", 30_000, seed, k=2)
    assert evals[-1] > -300, evals


@pytest.mark.parametrize("seed", MAZE_SEEDS)
def test_farsighter_solves_the_bridge_maze(tmp_path: Path, seed: int) -> None:
    from farsighter.studies.maze import AGENTS, run_config

    agent = next(a for a in AGENTS if a.label == "Farsighter (k=10)")
    train(run_config(agent, seed, 40_000, tmp_path / "maze"))
    assert _evals(tmp_path / "maze")[-1] > -200  # a failure is exactly -200 (time limit)


# The general default chosen on the exploration suite in session 47 (farsighter/config/presets.py)
# never reaches CliffWalking's goal: no training episode ended in 20k steps in seeds 1, 2, 3 (every
# evaluation -2000, the evaluation's cap), measured in session 49. Session 45's default (the
# fourteen settings of PREVIOUS_GENERAL_FARSIGHTER) walked the shortest path from 10k (seed 1) and
# 15k (seed 2); DDQN's defaults from 15k (seed 1). CliffWalking is in none of the suite's sets: a
# held-out task on which the default regressed (issue #62). Session 50's default (the k-step return
# cut where the mean sees a move costing more than 3 steps) does not walk the -13 path at 20k
# either (seeds 1, 2, 3; this test, 3 xfailed).
REGRESSED = known_failure("the general default does not walk the shortest path in 20k steps")


@pytest.mark.parametrize("seed", [pytest.param(s, marks=REGRESSED) for s in SEEDS])
def test_farsighter_defaults_walk_cliffwalking(tmp_path: Path, seed: int) -> None:
    # The defaults (the general preset) on a task nobody tuned them for: -1 a step, -100 and
    # back to the start for a step off the cliff, the goal ends the episode; the shortest path
    # returns -13.
    evals = _train(tmp_path, "farsighter", "CliffWalking-v1", "auto", 20_000, seed)
    assert evals[-1] == -13.0, evals
