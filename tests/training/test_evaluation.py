"""Evaluation runs its episodes as a batch: each episode returns what it returns stepped alone."""

from __future__ import annotations

import csv
import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

import farsighter
from farsighter.config import Config
from farsighter.envs import make_env, make_eval_envs
from farsighter.session import EvalResult, evaluate_episodes
from tests.conftest import GrabAgent, parts, tiny

MAZE = "farsighter/BridgeMaze-v0"
MEDIAN = -1  # eval_max_steps: the median return of the uncapped episodes


def stepped_alone(agent: Any, cfg: Config, episodes: int, seed: int) -> EvalResult:
    """The reference: one environment, one episode after the other, each acted on alone (a
    batch of one row) as the sequential evaluation did; episode i reset with seed + i and its
    eval_epsilon coins from default_rng(seed + i) (episode 0 is the sequential one's first)."""
    env = make_env(cfg, seed=0, training=False)
    n_actions = int(env.action_space.n)  # type: ignore[attr-defined]
    returns, successes = [], []
    for i in range(episodes):
        rng = np.random.default_rng(seed + i)
        obs, info = env.reset(seed=seed + i)
        total, steps, done = 0.0, 0, False
        while not done and steps < cfg.eval_max_steps:
            if rng.random() < cfg.eval_epsilon:
                action = int(rng.integers(n_actions))
            else:
                action = agent.act(np.asarray(obs)[None], 0, explore=False)[0]
            obs, reward, terminated, truncated, info = env.step(action)
            total += float(reward)
            steps += 1
            done = terminated or truncated
        returns.append(total)
        if "is_success" in info:
            successes.append(float(info["is_success"]))
    env.close()
    return EvalResult(returns, successes)


def batched(agent: Any, cfg: Config, width: int, episodes: int, seed: int) -> EvalResult:
    envs = make_eval_envs(cfg, width, seed=100)
    try:
        return evaluate_episodes(agent, cfg, envs, episodes, seed, global_step=0)
    finally:
        for env in envs:
            env.close()


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Any, Config]]:
    """A DDQN on CartPole and a Farsighter on the bridge maze, trained a few hundred steps (their
    greedy policies differ from episode to episode on CartPole and act on the posterior mean)."""
    out = {}
    for algo, env, steps in (("ddqn", "CartPole-v1", 1_500), ("farsighter", MAZE, 600)):
        grab = GrabAgent()
        run = tmp_path_factory.mktemp(algo) / "run"
        cfg = tiny(algo, run, env=env, total_steps=steps, eval_every=0, checkpoint_every=0)
        farsighter.train(cfg, callbacks=[grab])
        out[env] = (grab.agent, cfg)
    return out


class MazeOracle:
    """A fixed greedy policy on the bridge maze: Q*'s action in each cell (the trained agents'
    greedy episodes on the deterministic maze are all the same; with eval_epsilon this one's
    reach the apple at different steps, or not before the cap)."""

    def __init__(self) -> None:
        maze: Any = make_env(tiny("ddqn", Path("unused"), env=MAZE), seed=0).unwrapped
        self.action = {
            maze.obs_for(r, c).tobytes(): maze.optimal_action(r, c)
            for r in range(maze.height)
            for c in range(maze.width)
            if maze._free[r, c] and (r, c) != maze.goal
        }

    def act(self, obs_E: np.ndarray, global_step: int, explore: bool = True) -> np.ndarray:
        return np.array([self.action[o.tobytes()] for o in obs_E])


@pytest.mark.parametrize(
    ("agent_of", "eval_epsilon", "cap"),
    [("CartPole-v1", 0.0, 500), ("CartPole-v1", 0.2, 500), ("CartPole-v1", 0.0, MEDIAN)]
    + [(MAZE, 0.0, 200), (MAZE, 0.3, 200), ("oracle", 0.5, 200), ("oracle", 0.5, 40)],
)
def test_batched_returns_equal_each_episode_stepped_alone(
    trained: dict[str, tuple[Any, Config]], agent_of: str, eval_epsilon: float, cap: int
) -> None:
    agent, cfg = (MazeOracle(), trained[MAZE][1]) if agent_of == "oracle" else trained[agent_of]
    episodes, seed = 7, 11
    if cap == MEDIAN:  # a cap that ends some of the episodes, whatever the training gave
        cap = int(np.median(stepped_alone(agent, cfg, episodes, seed).returns))
    cfg = dataclasses.replace(cfg, eval_epsilon=eval_epsilon, eval_max_steps=cap)
    reference = stepped_alone(agent, cfg, episodes, seed)
    if agent_of != MAZE:  # episodes that differ, so that a slip of seeds or coins shows
        assert len(set(reference.returns)) > 1, reference.returns
    if cfg.env == MAZE:
        assert len(reference.successes) == episodes
    if agent_of == "oracle" and cap == 40:
        assert 0 < sum(reference.successes) < episodes, reference.successes
    if cap < 100:  # the cap ends some episodes, not all
        ended_by_cap = [abs(r) == cap for r in reference.returns]
        assert any(ended_by_cap) and not all(ended_by_cap), reference.returns
    for width in (1, 3, episodes, 10):  # one at a time, in turns, all at once (10: more than asked)
        result = batched(agent, cfg, width, episodes, seed)
        assert result.returns == reference.returns, width
        assert result.successes == reference.successes, width


def test_evaluation_draws_nothing_from_the_agent(trained: dict[str, tuple[Any, Config]]) -> None:
    agent, cfg = trained[MAZE]
    cfg = dataclasses.replace(cfg, eval_epsilon=0.5)
    before = (parts(agent).rng.bit_generator.state, parts(agent).gen.get_state().clone())
    before_counters = dataclasses.asdict(parts(agent).counters)
    batched(agent, cfg, 3, 5, seed=1)
    assert parts(agent).rng.bit_generator.state == before[0]
    assert torch.equal(parts(agent).gen.get_state(), before[1])
    assert dataclasses.asdict(parts(agent).counters) == before_counters


def test_the_loop_evaluates_the_phase_seed_as_a_batch(tmp_path: Path) -> None:
    """A run's final evaluation: seed cfg.seed + 7919 x (evaluations so far), as before."""
    grab = GrabAgent()
    cfg = tiny(
        "ddqn",
        tmp_path / "run",
        total_steps=1_000,
        eval_every=0,
        eval_episodes=5,
        eval_max_steps=300,
    )
    farsighter.train(cfg, callbacks=[grab])
    with (tmp_path / "run" / "eval.csv").open() as fh:
        (row,) = list(csv.DictReader(fh))
    reference = stepped_alone(grab.agent, cfg, 5, cfg.seed + 7919)
    assert len(set(reference.returns)) > 1
    assert row["eval_episodes"] == "5"
    assert float(row["eval_return_mean"]) == pytest.approx(np.mean(reference.returns), rel=1e-5)


def test_progress_is_shown_only_when_asked(
    trained: dict[str, tuple[Any, Config]], capsys: pytest.CaptureFixture[str]
) -> None:
    agent, cfg = trained["CartPole-v1"]
    envs = make_eval_envs(cfg, 2, seed=0)
    evaluate_episodes(agent, cfg, envs, 3, seed=0, global_step=1234, progress=True)
    err = capsys.readouterr().err
    assert "eval at step 1234" in err and "0/3" in err and "episode" in err, err
    evaluate_episodes(agent, cfg, envs, 3, seed=0, global_step=1234)
    assert capsys.readouterr().err == ""
    for env in envs:
        env.close()


def test_a_run_shorter_than_the_cap_evaluates_at_most_as_many_steps_as_it_trains(
    trained: dict[str, tuple[Any, Config]],
) -> None:
    """A run shorter than eval_max_steps is no protocol run: its evaluation episodes are capped
    at total_steps // eval_episodes; a run at least eval_max_steps long keeps the cap."""
    agent, cfg = trained["CartPole-v1"]
    episodes, seed = 5, 3
    long = stepped_alone(agent, dataclasses.replace(cfg, eval_max_steps=500), episodes, seed)
    assert max(long.returns) > 12  # CartPole pays 1 a step: the trained policy balances longer
    short = dataclasses.replace(cfg, total_steps=60, eval_episodes=5, eval_max_steps=500)
    result = batched(agent, short, 3, episodes, seed)
    assert max(result.returns) == 12 and result.returns == [min(r, 12) for r in long.returns]
    at_cap = dataclasses.replace(cfg, total_steps=500, eval_episodes=5, eval_max_steps=500)
    assert batched(agent, at_cap, 3, episodes, seed) == long
