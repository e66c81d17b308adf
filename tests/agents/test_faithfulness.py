"""Algorithm 1's order, the BDQN preset as its code runs, and agent-level target invariants
(issue #10): each test here fails under a specific wrong implementation, named in its docstring."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch

from farsighter.agents import build_agent
from farsighter.agents.ddqn import DDQNAgent
from farsighter.agents.naf import NAFAgent
from farsighter.config import make_config
from farsighter.replay import ReplayBuffer, VectorStep
from tests.conftest import eq8, inner, parts, tiny

CPU = torch.device("cpu")


def cartpole_agent(tmp_path: Path, algo: str, **kw: Any) -> Any:
    cfg = tiny(algo, tmp_path, **{"learning_starts": 0, **kw})
    env = gym.make("CartPole-v1")
    return build_agent(cfg, env.observation_space, env.action_space, frame_stack=1, device=CPU)


def feed(agent: Any, n: int, seed: int = 0, episode: int = 40, obs_dim: int = 4) -> None:
    """n random steps, episodes of ``episode`` steps ending in a termination."""
    rng = np.random.default_rng(seed)
    for t in range(n):
        end = t % episode == episode - 1
        agent.observe(
            VectorStep(
                rng.normal(size=(1, obs_dim)).astype(np.float32),
                rng.integers(0, 2, size=1),
                np.array([rng.normal()]),
                np.array([end]),
                np.array([False]),
                [rng.normal(size=obs_dim).astype(np.float32)] if end else None,
            )
        )


def perturb(module: torch.nn.Module, scale: float = 0.5, seed: int = 7) -> None:
    gen = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for p in module.parameters():
            p.add_(scale * torch.randn(p.shape, generator=gen))


def minibatch(agent: Any, k: int = 1) -> dict[str, torch.Tensor]:
    from farsighter.agents.common import batch_tensors

    return batch_tensors(inner(agent).replay.sample(32, k=k, gamma=inner(agent).cfg.gamma), CPU)


# ------------------------------------------------------------------ Algorithm 1's order (item 1)


def test_refresh_comes_before_the_target_sync(tmp_path: Path) -> None:
    """On a step where the posterior refresh (line 6) and the target copy (line 8) coincide, the
    target mean is the fresh posterior mean (fails if the sync runs first)."""
    agent = cartpole_agent(
        tmp_path,
        "farsighter",
        target_update_every=100,
        blr__posterior_every=200,
        train_every=1_000_000,  # no representation updates: only the refresh moves the mean
    )
    feed(agent, 199)
    agent.learn(199)
    before = parts(agent).head.mean_AD.clone()
    feed(agent, 1, seed=1)
    agent.learn(200)  # both fall here
    assert parts(agent).head.num_refreshes == 1
    assert not torch.allclose(parts(agent).head.mean_AD, before)
    assert torch.equal(parts(agent).target_mean_AD, parts(agent).head.mean_AD)


# ------------------------------------------------------------------ target invariants (item 8)


def test_farsighter_targets_use_the_target_torso_and_target_mean(tmp_path: Path) -> None:
    """y = r + gamma^n phi_target(s')^T mean_target[a*] with a* under the online torso and the
    posterior mean (Eq. 8); fails if the target is computed with the online torso or mean."""
    agent = cartpole_agent(tmp_path, "farsighter", k=3)
    feed(agent, 300)
    inner(agent).refresh_posterior()
    parts(agent).target_mean_AD = parts(agent).head.mean_AD.clone()
    perturb(inner(agent).torso)  # online and target now differ, in torso and in mean
    parts(agent).head.set_mean(parts(agent).head.mean_AD + 0.3)
    t = minibatch(agent, k=3)
    with torch.no_grad():
        a_star = (inner(agent).torso.net(t.next_obs_B) @ parts(agent).head.mean_AD.T).argmax(1)
        q_tgt = inner(agent).loss.torso_target.net(t.next_obs_B) @ parts(agent).target_mean_AD.T
        expected = t.returns_B + t.bootstrap_B * q_tgt.gather(1, a_star[:, None])[:, 0]
    assert torch.allclose(eq8(agent, t, parts(agent).draws(len(t.actions_B))), expected, atol=1e-5)


def test_ddqn_targets_evaluate_with_the_target_network(tmp_path: Path) -> None:
    """Double Q: the online network picks a*, the target network values it (fails on a swap or
    on an online evaluation)."""
    sole = cartpole_agent(tmp_path, "ddqn")
    feed(sole, 300)
    agent: DDQNAgent = sole.agents  # one seed of the agent written over seeds
    perturb(agent.q)
    t = minibatch(agent)
    q, q_target = agent.q.net, inner(agent).loss.q_target.net  # the seed's networks alone
    with torch.no_grad():
        a_star = q(t.next_obs_B).argmax(1)
        q_tgt = q_target(t.next_obs_B).gather(1, a_star[:, None])[:, 0]
        wrong = q(t.next_obs_B).max(1).values
    expected = t.returns_B + t.bootstrap_B * q_tgt
    y = inner(agent).loss.targets(t)
    assert torch.allclose(y, expected, atol=1e-5)
    assert not torch.allclose(y, t.returns_B + t.bootstrap_B * wrong, atol=1e-3)


def test_naf_targets_use_the_target_value(tmp_path: Path) -> None:
    """y = r^k + gamma^n V'(s') from the target network (fails with the online V)."""
    cfg = tiny("naf", tmp_path, env="Pendulum-v1", preset="continuous", learning_starts=0)
    env = gym.make("Pendulum-v1")
    agent: NAFAgent = build_agent(
        cfg, env.observation_space, env.action_space, frame_stack=1, device=CPU
    )
    rng = np.random.default_rng(0)
    for t in range(300):
        end = t % 50 == 49
        agent.observe(
            VectorStep(
                rng.normal(size=(1, 3)).astype(np.float32),
                rng.uniform(-2, 2, size=(1, 1)).astype(np.float32),
                np.array([rng.normal()]),
                np.array([False]),
                np.array([end]),
                [rng.normal(size=3).astype(np.float32)] if end else None,
            )
        )
    perturb(agent.net)
    t_ = minibatch(agent)
    with torch.no_grad():
        v_target = inner(agent).loss.net_target.value(t_.next_obs_B)
        v_online = agent.net.value(t_.next_obs_B)
    y = inner(agent).loss.targets(t_)
    assert torch.allclose(y, t_.returns_B + t_.bootstrap_B * v_target.reshape(-1), atol=1e-5)
    assert not torch.allclose(y, t_.returns_B + t_.bootstrap_B * v_online.reshape(-1), atol=1e-3)


def test_no_k1_sample_starts_at_an_episode_final_row() -> None:
    """Replay validity rule 1: the final row of an episode (its last observation) never starts a
    sample, else about 1 in (episode length + 1) of a k = 1 batch crosses into the next episode."""
    buf = ReplayBuffer(1_000, (2,), np.float32, seed=0)
    episode, t = 0, 0
    for _ in range(600):  # episodes of 5 steps; obs = (episode id, t)
        end = t == 4
        final = [np.array([episode, t + 1], np.float32)] if end else None
        buf.add(
            np.array([[episode, t]], np.float32), np.array([0]), np.array([1.0]),
            np.array([end]), np.array([False]), final,
        )  # fmt: skip
        t += 1
        if end:
            episode, t = episode + 1, 0
    for seed in range(5):
        buf.rng = np.random.default_rng(seed)
        batch = buf.sample(256, k=1, gamma=1.0)
        assert (batch.next_obs[:, 0] == batch.obs[:, 0]).all()  # same episode
        assert (batch.next_obs[:, 1] == batch.obs[:, 1] + 1).all()  # the next step


# ------------------------------------------------------------------ config reaches the sampler


class SpyReplay:
    """Records the keyword arguments of every ReplayBuffer.sample call."""

    def __init__(self, replay: ReplayBuffer) -> None:
        self.calls: list[dict[str, Any]] = []
        self.inner = replay.sample

        def spy(batch_size: int, **kw: Any) -> Any:
            self.calls.append(kw)
            return self.inner(batch_size, **kw)

        replay.sample = spy  # type: ignore[method-assign]


@pytest.mark.parametrize("algo", ["ddqn", "kddqn", "farsighter", "krnd"])
def test_stride_and_recent_window_reach_the_sampler(tmp_path: Path, algo: str) -> None:
    agent = cartpole_agent(
        tmp_path, algo, k=4, stride=True, sample_recent=True, recent_window=300, train_every=1
    )
    spy = SpyReplay(inner(agent).replay)
    feed(agent, 400)
    agent.learn(10)
    assert spy.calls, "no minibatch was sampled"
    assert all(c["k"] == 4 and c["stride"] == 4 and c["recent"] == 300 for c in spy.calls)


def test_the_adapted_k_reaches_the_sampler(tmp_path: Path) -> None:
    agent = cartpole_agent(
        tmp_path,
        "farsighter",
        k=5,
        adaptive_k__enabled=True,
        adaptive_k__variance_target=1e9,  # far above any Q-variance: k grows by one
        adaptive_k__empty_buffer=False,
        adaptive_k__k_max=10,
        blr__posterior_every=300,
        train_every=1,
    )
    spy = SpyReplay(inner(agent).replay)
    feed(agent, 300)
    agent.learn(300)  # updates with k = 5, then the refresh moves k to 6
    assert parts(agent).counters.k == 6
    spy.calls.clear()
    feed(agent, 1, seed=3)
    agent.learn(301)
    assert spy.calls and all(c["k"] == 6 for c in spy.calls)


# ------------------------------------------------------------------ BDQN as its code runs (item 2)


def test_bdqn_preset_is_the_authors_code() -> None:
    cfg = make_config("bdqn", "ALE/Pong-v5", preset="bdqn")
    b = cfg.blr
    assert b.redraw == "step"  # `if frame_counter % f_sampling:` is true on 999 of 1,000 frames
    assert (b.posterior_sampling, b.posterior_target, b.target) == ("uniform", "max", "thompson")
    assert cfg.learning_starts == 50_000
    assert (b.posterior_every, b.posterior_samples, b.cov_scale) == (100_000, 100_000, 1e-3)
    # the bdqn algorithm under Table 1 keeps the BDQN paper's redraw every T steps
    plain = make_config("bdqn", "CartPole-v1", preset="control")
    assert (plain.blr.redraw, plain.blr.redraw_every) == ("every", 1_000)


def test_bdqn_preset_redraws_at_every_step(tmp_path: Path) -> None:
    agent = cartpole_agent(tmp_path, "bdqn", preset="bdqn", blr__prior_std=10.0)
    obs = np.full((1, 4), 0.3, np.float32)
    actions = [int(agent.act(obs, 10)[0]) for _ in range(200)]
    assert parts(agent).counters.draws == 200
    assert len(set(actions)) == 2


def test_thompson_target_uses_the_acting_draw(tmp_path: Path) -> None:
    """blr.target = thompson: one weight set, the latest acting draw, picks a* for the batch."""
    agent = cartpole_agent(
        tmp_path, "bdqn", blr__target="thompson", blr__redraw="step", blr__prior_std=3.0
    )
    feed(agent, 300)
    inner(agent).refresh_posterior()
    agent.act(np.zeros((1, 4), np.float32), 10)
    w_AD = parts(agent).exploration.w_EAD[0].clone()  # type: ignore[index]
    t = minibatch(agent)
    with torch.no_grad():
        a_star = (inner(agent).torso.net(t.next_obs_B) @ w_AD.T).argmax(1)
        q_tgt = inner(agent).loss.torso_target.net(t.next_obs_B) @ parts(agent).target_mean_AD.T
    expected = t.returns_B + t.bootstrap_B * q_tgt.gather(1, a_star[:, None])[:, 0]
    draws = parts(agent).counters.draws
    assert torch.allclose(eq8(agent, t, parts(agent).draws(len(t.actions_B))), expected, atol=1e-5)
    assert parts(agent).counters.draws == draws  # the target made no new draw


def test_posterior_max_target_and_uniform_sampling(tmp_path: Path) -> None:
    agent = cartpole_agent(
        tmp_path, "bdqn", blr__posterior_target="max", blr__posterior_sampling="uniform"
    )
    feed(agent, 300)
    perturb(inner(agent).torso)
    t = minibatch(agent)
    with torch.no_grad():
        q_tgt = inner(agent).loss.torso_target.net(t.next_obs_B) @ parts(agent).target_mean_AD.T
    expected = t.returns_B + t.bootstrap_B * q_tgt.max(1).values
    assert torch.allclose(inner(agent).loss.posterior_targets(t, {}), expected, atol=1e-5)
    e_N, l_N = inner(agent).replay.uniform_indices(5_000, np.random.default_rng(0))
    assert l_N.min() < 20 and l_N.max() > 280  # the whole buffer, not the latest D rows
    assert len(np.unique(l_N)) < len(l_N)  # with replacement


# ------------------------------------------------------------------ draws counted (item 8)


@pytest.mark.parametrize(
    ("redraw", "extra", "expected"),
    [("step", {}, 2 * 30), ("every", {"blr__redraw_every": 10}, 2 * 3), ("episode", {}, 2)],
)
def test_draws_count_weight_draws(
    tmp_path: Path, redraw: str, extra: dict[str, Any], expected: int
) -> None:
    agent = cartpole_agent(tmp_path, "bdqn", num_envs=2, blr__redraw=redraw, **extra)
    obs = np.zeros((2, 4), np.float32)
    for _ in range(30):
        agent.act(obs, 10)
    # one per environment and draw, none while a draw is held
    assert parts(agent).counters.draws == expected


# ------------------------------------------------------------------ smaller mismatches (item 5)


def test_stride_refresh_uses_one_tuple_per_k(tmp_path: Path) -> None:
    agent = cartpole_agent(tmp_path, "farsighter", k=4, stride=True, blr__posterior_samples=50)
    feed(agent, 400)
    seen: list[np.ndarray] = []
    replay = inner(agent).replay
    original = replay.sample_indices

    def spy(e: np.ndarray, s: np.ndarray, k: int, gamma: float, **kw: Any) -> Any:
        batch = original(e, s, k, gamma, **kw)
        seen.append(replay.t_ep[batch.env_index, batch.index % replay.capacity])
        return batch

    replay.sample_indices = spy  # type: ignore[method-assign]
    inner(agent).refresh_posterior()
    t_ep = np.concatenate(seen)
    assert (t_ep % 4 == 0).all()
    assert 40 <= len(t_ep) <= 50  # D tuples of the stride, from the latest k D rows


def test_empty_every_refresh_empties_even_when_k_stays(tmp_path: Path) -> None:
    agent = cartpole_agent(
        tmp_path,
        "farsighter",
        k=3,
        adaptive_k__enabled=True,
        adaptive_k__k_min=3,
        adaptive_k__k_max=3,  # k cannot move
        adaptive_k__empty_every_refresh=True,
    )
    feed(agent, 300)
    inner(agent).refresh_posterior()
    assert (
        parts(agent).counters.k == 3
        and (inner(agent).replay.floor == inner(agent).replay.count).all()
    )
    other = cartpole_agent(
        tmp_path, "farsighter", k=3, adaptive_k__enabled=True, adaptive_k__k_min=3,
        adaptive_k__k_max=3,
    )  # fmt: skip
    feed(other, 300)
    inner(other).refresh_posterior()
    assert (inner(other).replay.floor == 0).all()  # the default empties only when k changes


def test_naf_soft_update_every_n_steps(tmp_path: Path) -> None:
    cfg = tiny(
        "naf", tmp_path, env="Pendulum-v1", preset="continuous", learning_starts=0,
        target_update_every=100, naf__soft_update="every_n", train_every=1,
    )  # fmt: skip
    env = gym.make("Pendulum-v1")
    agent: NAFAgent = build_agent(
        cfg, env.observation_space, env.action_space, frame_stack=1, device=CPU
    )
    rng = np.random.default_rng(0)
    target = [p.clone() for p in inner(agent).loss.net_target.parameters()]
    for step in range(1, 201):
        end = step % 50 == 0
        agent.observe(VectorStep(
            rng.normal(size=(1, 3)).astype(np.float32),
            rng.uniform(-2, 2, size=(1, 1)).astype(np.float32),
            np.array([rng.normal()]), np.array([False]), np.array([end]),
            [rng.normal(size=3).astype(np.float32)] if end else None,
        ))  # fmt: skip
        agent.learn(step)
        now = list(inner(agent).loss.net_target.parameters())
        moved = any(not torch.equal(a, b) for a, b in zip(target, now, strict=True))
        assert moved == (step % 100 == 0), step  # only on the N-step boundaries
        target = [p.clone() for p in now]
