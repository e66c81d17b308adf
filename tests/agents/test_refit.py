"""blr.switch_restart refit: the posterior refitted to the replay by fitted Q-iteration at the
switch (farsighter/ops/refit.py), against value iteration on a tabular chain, and in the agent."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

import farsighter.ops.refit as refit_module
from farsighter.agents.farsighter_posterior import largest_reward_sum, replay_rows
from farsighter.ops.blr import BLRHead
from farsighter.ops.refit import REFIT_SLACK, ReplayRows, bellman_targets, refit
from farsighter.replay import VectorStep
from tests.agents.test_exploration_defaults import make_agent
from tests.conftest import inner, parts

GAMMA = 0.9


def chain_rows(n: int) -> tuple[ReplayRows, np.ndarray]:
    """Every (state, action) of a deterministic chain of ``n`` states, one-hot features per
    action: action 1 moves right (from the last state it ends the episode with reward 1),
    action 0 goes back to state 0 with reward 0.1. Returns the rows and Q* by value iteration."""
    phi, act, ret, boot, nxt = [], [], [], [], []
    eye = np.eye(n)
    for s in range(n):
        for a in (0, 1):
            end = a == 1 and s == n - 1
            s2 = 0 if a == 0 else min(s + 1, n - 1)
            phi.append(eye[s])
            act.append(a)
            ret.append(1.0 if end else (0.1 if a == 0 else 0.0))
            boot.append(0.0 if end else GAMMA)
            nxt.append(eye[s2])
    q = np.zeros((n, 2))
    for _ in range(2000):  # value iteration to its fixed point
        v = q.max(axis=1)
        for i in range(len(act)):
            s, a = int(np.argmax(phi[i])), act[i]
            q[s, a] = ret[i] + boot[i] * v[int(np.argmax(nxt[i]))]
    rows = ReplayRows(
        torch.tensor(np.array(phi), dtype=torch.float64),
        torch.tensor(act),
        torch.tensor(ret, dtype=torch.float32),
        torch.tensor(boot, dtype=torch.float32),
        torch.tensor(np.array(nxt), dtype=torch.float32),
    )
    return rows, q


def tabular_head(n: int) -> BLRHead:
    return BLRHead(num_actions=2, dim=n, prior_std=1.0, noise_std=1.0)


def test_refit_reaches_the_q_values_of_value_iteration() -> None:
    """With each row weighing far more than the prior's ridge, the fitted Q-iteration's fixed
    point is Q* of the chain (the long way round: 0.1 now against 1 after n steps)."""
    n = 6
    rows, q_star = chain_rows(n)
    head = tabular_head(n)
    outcome = refit(head, rows, weight=1e6, count=3.0)
    assert outcome.accepted and 0 < outcome.iterations < 200
    q = head.mean_AD.T.double().numpy()  # one-hot features: w_a[s] is Q(s, a)
    np.testing.assert_allclose(q, q_star, atol=2e-3)
    assert (q.argmax(axis=1) == q_star.argmax(axis=1)).all()
    # the statistics are those of the rows (each counted as `count` rows) and their final
    # targets, so the head's own refresh gives this mean
    assert float(head.count_A.sum()) == pytest.approx(3.0 * len(rows))
    y = bellman_targets(rows, head.mean_AD)
    np.testing.assert_allclose(head.phiy_AD.T.numpy().max(axis=0), 1e6 * y.numpy().max(), rtol=1e-3)


def test_each_iteration_carries_a_value_back_one_window() -> None:
    """From the prior (mean 0) the first fit sees the rewards alone; each iteration takes the
    end's reward one state further back."""
    n = 6
    rows, _ = chain_rows(n)
    for iterations in (1, 3):
        head = tabular_head(n)
        assert refit(head, rows, weight=1e6, max_iterations=iterations).iterations == iterations
        right = head.mean_AD[1].double().numpy()  # Q(s, right)
        reached = [s for s in range(n) if right[s] > 0.5 * GAMMA ** (n - 1 - s)]
        assert reached == list(range(n - 1 - iterations, n)), right


def diverging_rows(ceiling: float = math.inf) -> ReplayRows:
    """Tsitsiklis and Van Roy's two rows: one feature, phi = 1 at s and 2 at s' (both lead to
    phi = 2), rewards 0 and 1."""
    return ReplayRows(
        torch.tensor([[1.0], [2.0]], dtype=torch.float64),
        torch.tensor([0, 0]),
        torch.tensor([0.0, 1.0]),
        torch.tensor([0.99, 0.99]),
        torch.tensor([[2.0], [2.0]]),
        ceiling,
    )


def test_a_diverging_fit_is_rejected() -> None:
    """One feature, phi = 1 at s and 2 at s': least squares over the two rows moves the weight
    by 6 gamma / 5 > 1 each iteration (Tsitsiklis and Van Roy's divergence). Without a ceiling
    the refit gives up once its targets pass what no fixed point of these rows reaches,
    |r| / (1 - gamma), and leaves the head at its prior."""
    rows = diverging_rows()
    head = BLRHead(num_actions=1, dim=1, prior_std=1.0, noise_std=1.0)
    outcome = refit(head, rows, weight=1e4)
    assert not outcome.accepted and 5 < outcome.iterations < 200
    assert 101.0 * 1.01 < outcome.largest < 101.0 * 1.5  # the first target past the bound
    assert float(head.count_A.sum()) == 0 and not head.mean_AD.any()


def test_an_overestimating_fit_is_rejected_and_a_sound_one_kept() -> None:
    """The ceiling: the same diverging rows with a ceiling of 3 are rejected at the first target
    above 3 (and its slack), long before the divergence bound; the chain, whose fixed point
    takes its reward 1, is kept with a ceiling of 1 and rejected with one of 0.5."""
    rows = diverging_rows(ceiling=3.0)
    head = BLRHead(num_actions=1, dim=1, prior_std=1.0, noise_std=1.0)
    outcome = refit(head, rows, weight=1e4)
    assert not outcome.accepted and 3.0 + REFIT_SLACK < outcome.largest < 10.0
    assert not head.mean_AD.any()
    chain, _ = chain_rows(6)
    for ceiling, accepted in ((1.0, True), (0.5, False)):
        chain.ceiling = ceiling
        head = tabular_head(6)
        assert refit(head, chain, weight=1e6).accepted is accepted
        assert bool(head.mean_AD.any()) is accepted


def switched_agent(path: Path, mode: str) -> Any:
    """An agent of ``blr.switch_restart = mode`` that updated at every step of a four-state
    walk, then switched at the paid step (the 13th, which ends the episode)."""
    values = {
        "blr.mode": "incremental",
        "blr.optimism": "until-reward",
        "blr.data_weight": 100.0,
        "k": 1,
        "batch_size": 4,
        "train_every": 2,
        "blr.switch_restart": mode,
    }
    eye = np.eye(4, dtype=np.float32)
    agent = make_agent(path, **values)
    for t in range(13):  # three observations in turn, then a fourth that pays and ends it
        obs = eye[3 if t == 12 else t % 3][None]
        action = agent.act(obs, t)
        end, reward = t == 12, 1.0 if t == 12 else 0.0
        step = VectorStep(
            obs,
            action,
            np.array([reward]),
            np.array([end]),
            np.array([False]),
            [eye[0]] if end else None,
        )
        agent.observe(step)
        if t < 12:
            agent.learn(t)  # updates from step 0 (learning_starts 0)
    assert parts(agent).calibrated
    return agent


def test_the_switch_refits_the_posterior_to_the_replay(tmp_path: Path) -> None:
    """blr.switch_restart refit: at the first positive reward the statistics are the replay's
    rows (each counted as the statistics count a step), the targets' mean is the fit's, and the
    paid step's value is learned at once; a restart from the prior knows nothing of it."""
    refitted, prior = (switched_agent(tmp_path / m, m) for m in ("refit", "prior"))
    eye = np.eye(4, dtype=np.float32)
    rows = 13  # every step's one-step window, the paid one's ended by its terminal
    p, prior_head, whole = parts(refitted), parts(prior).head, inner(refitted)
    assert float(p.head.count_A.sum()) == pytest.approx(rows * 4 / 2)
    torch.testing.assert_close(p.target_mean_AD, p.head.mean_AD)
    assert float(prior_head.count_A.sum()) == 0 and not prior_head.mean_AD.any()
    # the paid step's value, learned at once; the prior has no values at all
    q_refit, _ = refitted.q_estimate(eye)
    assert p.counters.updates > 0
    # the rows it fitted carry the ceiling of their returns (the paid step's 1)
    fitted = replay_rows(whole.replay, whole.cfg, 1, torch.device("cpu"), whole.torso.net)
    assert fitted.ceiling == pytest.approx(1.0)
    paid = int(whole.replay.actions[0, 12])
    assert q_refit[3, paid] > 0.3 and q_refit[3, paid] == q_refit.max(), q_refit


def test_a_rejected_refit_is_the_restart_from_the_prior(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A fit that fails its check leaves the agent where ``prior`` puts it, bit for bit: the
    same posterior, the same widths, the same targets' mean and the same next draws."""
    monkeypatch.setattr(refit_module, "fit_is_sound", lambda y, limits: False)
    rejected, prior = (switched_agent(tmp_path / m, m) for m in ("refit", "prior"))
    mine, theirs = parts(rejected), parts(prior)
    for name in ("phiphiT_ADD", "phiy_AD", "count_A", "mean_AD"):
        torch.testing.assert_close(getattr(mine.head, name), getattr(theirs.head, name))
    assert (mine.head.noise_std, mine.head.prior_std) == (
        theirs.head.noise_std,
        theirs.head.prior_std,
    )
    torch.testing.assert_close(mine.target_mean_AD, theirs.target_mean_AD)
    obs = np.eye(4, dtype=np.float32)[:1]
    assert [int(rejected.act(obs, 13 + t)[0]) for t in range(20)] == [
        int(prior.act(obs, 13 + t)[0]) for t in range(20)
    ]


def same_posterior(a: Any, b: Any) -> None:
    """The same statistics, widths, targets' mean and next 20 draws."""
    pa, pb = parts(a), parts(b)
    for name in ("phiphiT_ADD", "phiy_AD", "count_A", "mean_AD"):
        torch.testing.assert_close(getattr(pa.head, name), getattr(pb.head, name), rtol=0, atol=0)
    assert (pa.head.noise_std, pa.head.prior_std) == (pb.head.noise_std, pb.head.prior_std)
    torch.testing.assert_close(pa.target_mean_AD, pb.target_mean_AD, rtol=0, atol=0)
    obs = np.eye(4, dtype=np.float32)[:1]
    assert [int(a.act(obs, 13 + t)[0]) for t in range(20)] == [
        int(b.act(obs, 13 + t)[0]) for t in range(20)
    ]


def test_refit_zero_keeps_a_sound_fit_and_zeroes_the_targets_of_a_rejected_one(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """blr.switch_restart refit-zero: where the fit passes its check the agent is refit's, bit
    for bit; where it fails, zero-targets' (the rows kept, their targets 0), not the prior's."""
    kept, refitted = (switched_agent(tmp_path / "a" / m, m) for m in ("refit-zero", "refit"))
    same_posterior(kept, refitted)
    assert float(parts(kept).head.phiy_AD.abs().sum()) > 0  # the fit's targets (the paid step's)
    monkeypatch.setattr(refit_module, "fit_is_sound", lambda y, limits: False)
    rejected, zeroed, prior = (
        switched_agent(tmp_path / "b" / m, m) for m in ("refit-zero", "zero-targets", "prior")
    )
    same_posterior(rejected, zeroed)
    assert float(parts(rejected).head.phiy_AD.abs().sum()) == 0
    assert float(parts(rejected).head.count_A.sum()) > float(parts(prior).head.count_A.sum()) == 0


def test_a_switch_before_any_update_restarts_from_the_prior(tmp_path: Path) -> None:
    """Before the first update the features are the initial network's: the refit falls back to
    the prior (statistics zeroed, mean 0)."""
    agent = make_agent(
        tmp_path,
        **{
            "blr.mode": "incremental",
            "blr.optimism": "until-reward",
            "blr.switch_restart": "refit",
        },
    )
    obs = np.eye(4, dtype=np.float32)[:1]
    for t in range(5):
        end = t == 4
        agent.observe(
            VectorStep(
                obs,
                agent.act(obs, t),
                np.array([1.0 if end else 0.0]),
                np.array([end]),
                np.array([False]),
                [obs[0]] if end else None,
            )
        )
    p = parts(agent)
    assert p.calibrated and p.counters.updates == 0
    assert float(p.head.count_A.sum()) == 0 and not p.head.mean_AD.any()


def test_the_ceiling_is_the_largest_reward_sum_the_replay_showed(tmp_path: Path) -> None:
    """The ceiling: the largest discounted sum of rewards from any step to any later step of its
    episode (an episode ended by its time limit counts to its last step; a cost after a reward
    does not lower it)."""
    agent = make_agent(tmp_path)
    obs = np.zeros((1, 4), np.float32)
    # episode 1: 0, 0, 1 (terminated); episode 2: 0.5 then 0.5 (truncated); a step of a third
    for reward, term, trunc in [
        (0, 0, 0),
        (0, 0, 0),
        (1, 1, 0),
        (0.5, 0, 0),
        (0.5, 0, 1),
        (0, 0, 0),
    ]:
        agent.observe(
            VectorStep(
                obs,
                np.array([0]),
                np.array([reward], dtype=np.float32),
                np.array([bool(term)]),
                np.array([bool(trunc)]),
                [obs[0]] if term or trunc else None,
            )
        )
    replay = inner(agent).replay
    e_N, l_N = replay.recent_indices(100)
    assert largest_reward_sum(replay, e_N, l_N, 0.9) == pytest.approx(1.0)
    assert largest_reward_sum(replay, e_N, l_N, 1.0) == pytest.approx(1.0)
    # without the terminal reward the second episode's 0.5 + 0.9 * 0.5 is the largest
    replay.rewards[0, 2] = 0.0
    assert largest_reward_sum(replay, e_N, l_N, 0.9) == pytest.approx(0.95)
    # a cost after the rewards (its return to the end 0.5 - 0.9 * 0.5 * 0.9 ...) leaves it
    replay.rewards[0, 4] = -5.0
    assert largest_reward_sum(replay, e_N, l_N, 0.9) == pytest.approx(0.5)
