"""Goal-conditioned tasks: dict observations flattened, success rates logged, hindsight replay
relabels with future achieved goals; the spaces check; MuJoCo tasks build."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch

import farsighter
from farsighter.agents import build_agent
from farsighter.config import Config
from farsighter.envs import check_spaces, make_env
from farsighter.envs.factory import goal_spec
from farsighter.errors import EnvError
from farsighter.replay import FINAL, VectorStep
from farsighter.replay.her import episode_last_rows, relabel_future
from tests.conftest import tiny

GOAL_ENV = "tests.goal_env:PointGoal-v0"


def goal_cfg(run_dir: Path, **kw: Any) -> Config:
    values: dict[str, Any] = {
        "total_steps": 400,
        "learning_starts": 100,
        "batch_size": 32,
        "eval_every": 200,
        "eval_episodes": 3,
        "checkpoint_every": 0,
        "naf.elbo_every": 100,
        "naf.elbo_steps": 2,
        "naf.elbo_batch": 32,
    }
    values.update(kw)
    return tiny("farsighter-naf", run_dir, env=GOAL_ENV, preset="continuous", **values)


def test_dict_observations_are_flattened(tmp_path: Path) -> None:
    env = make_env(goal_cfg(tmp_path), seed=0)
    obs, _ = env.reset(seed=0)
    raw = env.unwrapped._obs()  # type: ignore[attr-defined]
    assert env.observation_space.shape == (6,) and obs.dtype == np.float32
    np.testing.assert_allclose(
        obs, np.concatenate([raw["observation"], raw["desired_goal"]]), rtol=1e-6
    )
    her_env = make_env(goal_cfg(tmp_path, **{"naf.her": True}), seed=0)
    obs, _ = her_env.reset(seed=0)
    raw = her_env.unwrapped._obs()  # type: ignore[attr-defined]
    assert her_env.observation_space.shape == (8,)
    np.testing.assert_allclose(
        obs,
        np.concatenate([raw["observation"], raw["achieved_goal"], raw["desired_goal"]]),
        rtol=1e-6,
    )


def test_success_rates_are_logged_beside_metrics(tmp_path: Path) -> None:
    summary = farsighter.train(goal_cfg(tmp_path / "run"))
    run = Path(summary["run_dir"])
    with (run / "success.csv").open() as fh:
        train_rows = list(csv.DictReader(fh))
    assert len(train_rows) == 20  # 400 steps of 20-step episodes
    assert {r["success"] for r in train_rows} <= {"0", "1"}
    with (run / "eval_success.csv").open() as fh:
        evals = list(csv.DictReader(fh))
    assert [int(r["global_step"]) for r in evals] == [200, 400]
    assert all(0.0 <= float(r["eval_success_rate"]) <= 1.0 for r in evals)
    with (run / "metrics.csv").open() as fh:
        assert "success" not in next(csv.reader(fh))


def test_hindsight_relabelling_uses_future_achieved_goals(tmp_path: Path) -> None:
    cfg = goal_cfg(tmp_path / "run", k=3, **{"naf.her": True, "naf.her_ratio": 1.0})
    env = make_env(cfg, seed=0)
    agent = build_agent(
        cfg, env.observation_space, env.action_space, frame_stack=1, device=torch.device("cpu")
    )
    obs, _ = env.reset(seed=0)
    for _ in range(130):  # six full episodes and one running
        action = env.action_space.sample()
        nxt, reward, term, trunc, _ = env.step(action)
        agent.observe(
            VectorStep(
                obs[None],
                action[None],
                np.array([reward]),
                np.array([term]),
                np.array([trunc]),
                [nxt] if term or trunc else None,
            )
        )
        obs = nxt if not (term or trunc) else env.reset()[0]
    replay, spec = agent.replay, agent.her
    assert spec is not None and (spec.obs_dim, spec.goal_dim) == (4, 2)
    assert (goal_spec(cfg).obs_dim, goal_spec(cfg).goal_dim) == (4, 2)
    batch = replay.sample(64, k=3, gamma=0.9)
    end = episode_last_rows(replay, batch.env_index, batch.index)
    assert (replay.flags[0, end[end < replay.count[0] - 1] % replay.capacity] & FINAL).all()
    new = relabel_future(
        batch, replay, spec, k=3, gamma=0.9, ratio=1.0, rng=np.random.default_rng(0)
    )
    frames = replay.frames[0]
    for i in range(64):
        t, n, goal = batch.index[i], batch.steps[i], new.obs[i, spec.desired]
        # the new goal is the achieved goal of a later row of the same episode
        later = frames[t + 1 : end[i] + 1, spec.achieved]
        assert np.isclose(later, goal).all(axis=1).any()
        np.testing.assert_array_equal(new.next_obs[i, spec.desired], goal)
        np.testing.assert_array_equal(new.obs[i, : spec.obs_dim], batch.obs[i, : spec.obs_dim])
        rewards = spec.compute_reward(
            frames[t + 1 : t + 1 + n, spec.achieved], np.repeat(goal[None], n, axis=0), None
        )
        assert np.isclose(new.returns[i], (rewards * 0.9 ** np.arange(n)).sum())
    assert agent.update() is not None  # the agent samples through HER


def test_spaces_check() -> None:
    box = gym.spaces.Box(-1, 1, (3,), np.float32)
    with pytest.raises(EnvError, match="needs a continuous"):
        check_spaces("naf", box, gym.spaces.Discrete(2))
    with pytest.raises(EnvError, match="needs a discrete action space"):
        check_spaces("ddqn", box, box)
    with pytest.raises(EnvError, match="finite action bounds"):
        check_spaces("bnaf", box, gym.spaces.Box(-np.inf, np.inf, (2,)))
    check_spaces("farsighter-naf", box, box)


@pytest.mark.parametrize(
    ("env_id", "obs_dim", "act_dim"),
    [("Walker2d-v5", 17, 6), ("FetchPickAndPlace-v4", 28, 4), ("HandManipulateBlock-v1", 68, 20)],
)
def test_mujoco_tasks_build_flat(tmp_path: Path, env_id: str, obs_dim: int, act_dim: int) -> None:
    cfg = tiny("farsighter-naf", tmp_path, env=env_id, preset="continuous")
    env = make_env(cfg, seed=0)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (obs_dim,) and env.action_space.shape == (act_dim,)
    check_spaces(cfg.algo, env.observation_space, env.action_space)
    agent = build_agent(
        cfg, env.observation_space, env.action_space, frame_stack=1, device=torch.device("cpu")
    )
    action = agent.act(obs[None], 10_000)[0]
    _, _, _, _, info = env.step(action)
    assert ("is_success" in info) == (env_id != "Walker2d-v5")
    env.close()


def test_missing_robotics_extra_is_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import sys

    monkeypatch.setitem(sys.modules, "gymnasium_robotics", None)  # import raises ImportError
    cfg = tiny("farsighter-naf", tmp_path, env="FetchNotRegistered-v1", preset="continuous")
    with pytest.raises(EnvError, match=r"pip install 'farsighter\[mujoco\]'"):
        make_env(cfg, seed=0)
