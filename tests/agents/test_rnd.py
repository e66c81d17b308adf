"""RND and k-step RND: the predictor learns the states it is trained on, the intrinsic reward is
normalised by a running std, and enters the k-step sum of the window's next states."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch

import farsighter
from farsighter.agents.rnd import RNDAgent
from farsighter.config import make_config
from farsighter.ops.running import RunningMeanStd
from farsighter.replay import VectorStep
from tests.conftest import GrabAgent, tiny
from tests.replay.test_replay import fill


def _agent(tmp_path: Path, algo: str = "rnd", obs_dim: int = 4, **kw: Any) -> RNDAgent:
    cfg = tiny(algo, tmp_path / "unused", **kw)
    obs_space = gym.spaces.Box(-np.inf, np.inf, (obs_dim,), np.float32)
    return RNDAgent(
        [cfg], obs_space, gym.spaces.Discrete(3), frame_stack=1, device=torch.device("cpu")
    )


def test_running_mean_std_equals_the_batch_statistics() -> None:
    rng = np.random.default_rng(0)
    parts = [rng.normal(3.0, 2.0, size=(n, 2)) for n in (5, 50, 1)]
    rms = RunningMeanStd((2,))
    for p in parts:
        rms.update(p)
    data = np.concatenate(parts)
    assert np.allclose(rms.mean, data.mean(axis=0), rtol=1e-4)
    assert np.allclose(rms.var, data.var(axis=0), rtol=1e-4)


def test_intrinsic_reward_is_divided_by_the_running_std(tmp_path: Path) -> None:
    agent = _agent(tmp_path)
    rng = np.random.default_rng(1)
    seen: list[np.ndarray] = []
    for n in (8, 32, 3):
        e = rng.gamma(2.0, 0.5, size=n)
        seen.append(e)
        out = agent.bonuses[0].normalize(e)
        std = np.concatenate(seen).std()  # the std of every intrinsic reward so far
        assert np.allclose(out, e / std, rtol=1e-3)  # divided, not centred (as in RND)


def test_predictor_error_falls_on_trained_states_and_stays_high_elsewhere(tmp_path: Path) -> None:
    agent = _agent(tmp_path, rnd__lr=1e-3, rnd__normalize_obs=False)
    rng = np.random.default_rng(0)
    trained = torch.as_tensor(rng.normal(0.0, 0.5, size=(128, 4)), dtype=torch.float32)
    unseen = torch.as_tensor(rng.normal(0.0, 0.5, size=(128, 4)) + 4.0, dtype=torch.float32)
    before_trained = agent.bonuses[0].prediction_error(trained).mean().item()
    before_unseen = agent.bonuses[0].prediction_error(unseen).mean().item()
    for _ in range(300):
        agent.bonuses[0].train(trained)
    after_trained = agent.bonuses[0].prediction_error(trained).mean().item()
    after_unseen = agent.bonuses[0].prediction_error(unseen).mean().item()
    assert after_trained < 0.1 * before_trained
    assert after_unseen > 0.5 * before_unseen
    assert after_unseen > 10 * after_trained


def test_observations_are_whitened_with_running_statistics(tmp_path: Path) -> None:
    agent = _agent(tmp_path)
    rng = np.random.default_rng(2)
    obs = rng.normal(5.0, 3.0, size=(400, 4)).astype(np.float32)
    for o in obs:
        agent.observe([VectorStep(o[None], np.array([0]), np.array([0.0]), [False], [False], None)])
    assert np.allclose(agent.bonuses[0].obs_rms.mean, obs.mean(axis=0), atol=1e-3)
    x = agent.bonuses[0]._input(torch.as_tensor(obs)).numpy()
    assert abs(x.mean()) < 0.05 and abs(x.std() - 1.0) < 0.05 and np.abs(x).max() <= 5.0


def test_kstep_intrinsic_return_sums_the_window_next_states(tmp_path: Path) -> None:
    agent = _agent(tmp_path, algo="krnd", obs_dim=1, gamma=0.5)
    assert agent.cfg.k == 3
    fill(agent.replay, [(3, "term"), (5, "trunc")])  # obs = step id; final obs = id + 0.5
    agent.bonuses[0].normalize = lambda e: e  # type: ignore[method-assign]
    batch = agent.replay.sample_indices(np.zeros(3, np.int64), np.array([0, 1, 4]), 3, 0.5)

    def e(x: float) -> float:
        return agent.bonuses[0].prediction_error(torch.tensor([[x]])).item()

    expected = [
        e(1) + 0.5 * e(2) + 0.25 * e(2.5),  # rows 1, 2 and the final row of episode 1
        e(2) + 0.5 * e(2.5),  # the window stops at the terminal
        e(4) + 0.5 * e(5) + 0.25 * e(6),  # episode 2 starts at row 4 (obs 3)
    ]
    assert np.allclose(agent.bonuses[0].returns(batch, agent.replay), expected, rtol=1e-5)


def test_update_trains_q_and_predictor(tmp_path: Path) -> None:
    agent = _agent(tmp_path, algo="krnd", obs_dim=1)
    fill(agent.replay, [(30, "term"), (40, "trunc")])
    pred = [p.detach().clone() for p in agent.bonuses[0].predictor.parameters()]
    target = [p.detach().clone() for p in agent.bonuses[0].rnd_target.parameters()]
    loss_S = agent.update()
    assert loss_S.shape == (1,) and torch.isfinite(loss_S).all()
    assert any(
        not torch.equal(a, b)
        for a, b in zip(pred, agent.bonuses[0].predictor.parameters(), strict=True)
    )
    assert all(
        torch.equal(a, b)
        for a, b in zip(target, agent.bonuses[0].rnd_target.parameters(), strict=True)
    )
    d = agent.member(0).diagnostics()
    assert d["k"] == 3 and d["intrinsic_reward"] > 0 and np.isfinite(d["predictor_loss"])


def test_config_defaults() -> None:
    assert make_config("rnd").k == 1 and make_config("krnd").k == 3
    cfg = make_config("krnd")
    assert cfg.rnd.feature_dim == 512 and cfg.rnd.obs_clip == 5.0


def test_atari_smoke_with_frame_stacks(tmp_path: Path) -> None:
    pytest.importorskip("ale_py")
    cfg = make_config(
        "krnd",
        "ALE/Breakout-v5",
        total_steps=300,
        learning_starts=200,
        buffer_size=1_000,
        batch_size=8,
        train_every=4,
        target_update_every=100,
        eval_every=0,
        eval_episodes=1,
        eval_max_steps=50,
        checkpoint_every=0,
        log_every=100,
        progress=False,
        device="cpu",
        run_dir=str(tmp_path / "run"),
    )
    grab = GrabAgent()
    summary = farsighter.train(cfg, callbacks=[grab])
    assert summary["global_step"] == 300
    agent = grab.agent.batch  # the seed's agent (an RNDAgent of one seed)
    assert agent.replay.frame_stack == 4 and not agent.bonuses[0].whiten
    assert np.isfinite(grab.agent.diagnostics()["intrinsic_reward"])
