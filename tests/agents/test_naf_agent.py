"""Invariants of the continuous agents (naf, knaf, bnaf, farsighter-naf): acting, TD targets,
the alternating updates of section 4.3 and the soft target update."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

from farsighter.agents import build_agent
from farsighter.agents.naf import NAFAgent
from farsighter.config import Config
from farsighter.ops.bayes_layer import BayesianLinear
from farsighter.ops.naf import naf_q, naf_td_target
from farsighter.replay import VectorStep
from tests.conftest import tiny

OBS = gym.spaces.Box(-np.inf, np.inf, (3,), np.float32)
ACT = gym.spaces.Box(np.array([-2.0, -1.0], np.float32), np.array([2.0, 0.5], np.float32))


def make_agent(algo: str, **kw: object) -> NAFAgent:
    values: dict[str, object] = {
        "learning_starts": 50,
        "naf.elbo_every": 100,
        "naf.elbo_steps": 5,
        "naf.elbo_batch": 32,
    }
    values.update(kw)
    cfg: Config = tiny(algo, Path("unused"), env="Pendulum-v1", preset="continuous", **values)
    agent = build_agent(cfg, OBS, ACT, frame_stack=1, device=torch.device("cpu"))
    assert isinstance(agent, NAFAgent)
    return agent


def fill(agent: NAFAgent, steps: int = 300, seed: int = 0) -> None:
    rng = np.random.default_rng(seed)
    for t in range(steps):
        end = t % 40 == 39
        agent.observe(
            VectorStep(
                rng.normal(size=(1, 3)).astype(np.float32),
                rng.uniform(ACT.low, ACT.high, size=(1, 2)).astype(np.float32),
                np.array([rng.normal()]),
                np.array([end and t % 80 == 79]),
                np.array([end and t % 80 != 79]),
                [rng.normal(size=3).astype(np.float32)] if end else None,
            )
        )


def params(module: torch.nn.Module) -> dict[str, torch.Tensor]:
    return {k: v.detach().clone() for k, v in module.state_dict().items()}


def same(a: dict[str, torch.Tensor], b: dict[str, torch.Tensor]) -> bool:
    return all(torch.equal(a[k], b[k]) for k in a)


@pytest.mark.parametrize("algo", ["bnaf", "farsighter-naf"])
def test_mean_mu_is_deterministic_and_sampled_actions_differ(algo: str) -> None:
    agent = make_agent(algo)
    obs = np.random.default_rng(1).normal(size=(4, 3)).astype(np.float32)
    greedy1, greedy2 = agent.act(obs, 1_000, explore=False), agent.act(obs, 1_000, explore=False)
    assert greedy1.shape == (4, 2) and greedy1.dtype == np.float32
    assert np.array_equal(greedy1, greedy2)
    sampled1, sampled2 = agent.act(obs, 1_000), agent.act(obs, 1_000)
    assert not np.array_equal(sampled1, sampled2)  # a fresh weight draw every step
    twins = agent.act(np.repeat(obs[:1], 2, axis=0), 1_000)
    assert not np.array_equal(twins[0], twins[1])  # one draw per environment
    for a in (greedy1, sampled1, sampled2):
        assert (a >= ACT.low).all() and (a <= ACT.high).all()
    v_B1, var_B1 = agent.q_estimate(obs)
    assert v_B1.shape == (4, 1) and var_B1 is not None and (var_B1 > 0).all()


@pytest.mark.parametrize("noise", ["gaussian", "ou"])
def test_naf_noise_and_bounds(noise: str) -> None:
    agent = make_agent("naf", **{"naf.noise": noise, "naf.noise_std": 0.5})
    obs = np.zeros((2, 3), np.float32)
    greedy = agent.act(obs, 1_000, explore=False)
    noisy = agent.act(obs, 1_000)
    assert not np.array_equal(greedy, noisy)
    assert (noisy >= ACT.low).all() and (noisy <= ACT.high).all()
    assert agent.q_estimate(obs)[1] is None
    early = agent.act(obs, 0)  # uniform before learning_starts
    assert (early >= ACT.low).all() and (early <= ACT.high).all()


@pytest.mark.parametrize("algo", ["knaf", "farsighter-naf"])
def test_td_target_matches_ops(algo: str) -> None:
    agent = make_agent(algo, k=3)
    fill(agent)
    t = agent._sample(64)
    assert t is not None
    with torch.no_grad():
        v_next = agent.loss.net_target.head.v(agent.loss.net_target.torso(t.next_obs_B)).squeeze(-1)
    expected = naf_td_target(t.returns_B, t.bootstrap_B, v_next)
    assert torch.allclose(agent.loss.targets(t), expected)
    terminal = t.bootstrap_B == 0
    assert torch.equal(agent.loss.targets(t)[terminal], t.returns_B[terminal])
    # Q of the online network is Eq. 4 with mu at the posterior mean
    with torch.no_grad():
        phi = agent.net.torso(t.obs_B)
        v, l_mat = agent.net.head(phi)
        mu = agent.net.mu_from_out(agent.net.mu_out_mean(phi))
        q_B, _ = agent.net.q(t.obs_B, t.actions_B, True)
        assert torch.allclose(q_B, naf_q(v, mu, l_mat, t.actions_B))


def test_elbo_update_changes_only_the_mu_layer() -> None:
    agent = make_agent("farsighter-naf")
    fill(agent)
    layer = agent.net.mu_layer
    assert isinstance(layer, BayesianLinear)
    torso, head, target = (
        params(agent.net.torso),
        params(agent.net.head),
        params(agent.loss.net_target),
    )
    mu_before = params(layer)
    agent.elbo_update()
    assert same(torso, params(agent.net.torso))
    assert same(head, params(agent.net.head))
    assert same(target, params(agent.loss.net_target))
    after = params(layer)
    for name in ("weight_mu", "weight_rho", "bias_mu", "bias_rho"):
        assert not torch.equal(mu_before[name], after[name]), name
    assert np.isfinite(agent.counters.q_variance) and agent.counters.q_variance > 0


def test_td_update_leaves_the_bayesian_mu_layer_and_trains_the_plain_one() -> None:
    bayes, plain = make_agent("bnaf"), make_agent("naf")
    for agent, mu_moves in ((bayes, False), (plain, True)):
        fill(agent)
        torso, mu = params(agent.net.torso), params(agent.net.mu_layer)
        for _ in range(3):
            assert agent.update() is not None
        assert not same(torso, params(agent.net.torso))
        assert same(mu, params(agent.net.mu_layer)) != mu_moves


def test_soft_target_update_moves_by_tau() -> None:
    agent = make_agent("naf", **{"naf.tau": 0.25})
    fill(agent)
    before = params(agent.loss.net_target)
    agent.update()
    online = params(agent.net)
    for name, old in before.items():
        if name in ("low_A", "high_A"):
            continue
        assert torch.allclose(
            agent.loss.net_target.state_dict()[name], old + 0.25 * (online[name] - old), atol=1e-6
        ), name


def test_learn_cadence_and_adaptive_k() -> None:
    agent = make_agent(
        "farsighter-naf",
        k=3,
        **{
            "adaptive_k.enabled": True,
            "adaptive_k.variance_target": 1e6,  # always below: k grows by one per ELBO update
            "adaptive_k.k_max": 10,
            "adaptive_k.empty_buffer": False,
        },
    )
    fill(agent)
    metrics = agent.learn(100)
    assert "td_loss" in metrics and "elbo_loss" in metrics
    assert agent.counters.k == 4 and agent.diagnostics()["k"] == 4.0
    assert "elbo_loss" not in agent.learn(101)  # next ELBO update at step 200
    assert "elbo_loss" in agent.learn(200) and agent.counters.k == 5
    assert set(agent.diagnostics()) >= {"k", "q_variance", "mu_sigma"}


def test_state_dict_round_trip() -> None:
    a, b = make_agent("farsighter-naf"), make_agent("farsighter-naf", seed=9)
    fill(a)
    a.learn(100)
    b.load_state_dict(a.state_dict())
    obs = np.ones((1, 3), np.float32)
    assert np.array_equal(a.act(obs, 500), b.act(obs, 500))  # same generator state too
    assert same(params(a.net), params(b.net)) and a.counters.k == b.counters.k
