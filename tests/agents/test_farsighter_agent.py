"""Farsighter/BDQN agent invariants: draws per step, redraw cadences, posterior refresh,
adaptive k with buffer emptying, incremental mode, target mean."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

from farsighter.agents import build_agent
from farsighter.agents.farsighter_posterior import accumulate
from farsighter.agents.protocol import Sole
from farsighter.exploration import SCHEDULES
from farsighter.replay import VectorStep
from tests.conftest import inner, parts, tiny


def make_agent(tmp_path: Path, algo: str = "farsighter", **kw: object) -> Sole:
    cfg = tiny(algo, tmp_path, learning_starts=0, **kw)
    env = gym.make("CartPole-v1")
    agent = build_agent(
        cfg, env.observation_space, env.action_space, frame_stack=1, device=torch.device("cpu")
    )
    assert isinstance(agent, Sole)
    return agent


def feed(agent: Sole, n: int, seed: int = 0, positive: bool | None = None) -> None:
    """``n`` random transitions (an episode ends every 40); rewards standard normal, or their
    magnitudes (``positive`` True) or negated magnitudes (False)."""
    rng = np.random.default_rng(seed)
    sign = {None: None, True: 1.0, False: -1.0}[positive]
    for t in range(n):
        end = t % 40 == 39
        reward = rng.normal()
        agent.observe(
            VectorStep(
                rng.normal(size=(1, 4)).astype(np.float32),
                rng.integers(0, 2, size=1),
                np.array([reward if sign is None else sign * abs(reward)]),
                np.array([end]),
                np.array([False]),
                [rng.normal(size=4).astype(np.float32)] if end else None,
            )
        )


def test_kstep_draws_a_fresh_sample_at_every_step(tmp_path: Path) -> None:
    agent = make_agent(tmp_path, blr__prior_std=10.0)
    obs = np.zeros((1, 4), np.float32) + 0.3
    actions = [int(agent.act(obs, 10)[0]) for _ in range(200)]
    assert parts(agent).counters.draws == 200  # Algorithm 2 line 2: one draw per environment step
    assert len(set(actions)) == 2  # the same state gets different Thompson actions


def test_bdqn_redraws_every_T_steps(tmp_path: Path) -> None:
    agent = make_agent(tmp_path, "bdqn", blr__prior_std=10.0, blr__redraw_every=50)
    obs = np.random.default_rng(1).normal(size=(1, 4)).astype(np.float32)
    actions = [int(agent.act(obs, 10)[0]) for _ in range(500)]
    blocks = [set(actions[i : i + 50]) for i in range(0, 500, 50)]
    assert all(len(b) == 1 for b in blocks)  # fixed weights within a block
    assert len({next(iter(b)) for b in blocks}) == 2  # different draws across blocks


def test_greedy_evaluation_is_deterministic(tmp_path: Path) -> None:
    agent = make_agent(tmp_path)
    obs = np.random.default_rng(2).normal(size=(8, 4)).astype(np.float32)
    assert np.array_equal(agent.act(obs, 10, explore=False), agent.act(obs, 10, explore=False))


def test_posterior_refresh_shrinks_variance_and_target_mean_stays(tmp_path: Path) -> None:
    agent = make_agent(tmp_path)
    feed(agent, 600)
    phi = inner(agent).torso.net(torch.randn(32, 4))
    before = parts(agent).head.predictive_var(phi).mean().item()
    target_before = parts(agent).target_mean_AD.clone()
    inner(agent).refresh_posterior()
    assert parts(agent).head.num_refreshes == 1
    assert parts(agent).head.predictive_var(phi).mean().item() < before
    assert torch.equal(parts(agent).target_mean_AD, target_before)  # only copied every N steps
    torso_target = {k: v.clone() for k, v in inner(agent).loss.torso_target.state_dict().items()}
    for _ in range(10):
        inner(agent).update()
    assert all(
        torch.equal(torso_target[k], v)
        for k, v in inner(agent).loss.torso_target.state_dict().items()
    )


def test_adaptive_k_moves_and_empties_buffer(tmp_path: Path) -> None:
    agent = make_agent(
        tmp_path,
        k=5,
        adaptive_k__enabled=True,
        adaptive_k__variance_target=1e9,
        adaptive_k__k_min=2,
        adaptive_k__k_max=6,
    )
    feed(agent, 600)
    inner(agent).refresh_posterior()
    assert parts(agent).counters.k == 6  # variance below the target: k += 1
    assert (
        len(inner(agent).replay) > 0
        and (inner(agent).replay.floor == inner(agent).replay.count).all()
    )
    feed(agent, 300, seed=1)
    inner(agent).refresh_posterior()
    assert parts(agent).counters.k == 6  # clamped at k_max

    low = make_agent(
        tmp_path,
        k=3,
        adaptive_k__enabled=True,
        adaptive_k__variance_target=0.0,
        adaptive_k__k_min=2,
        adaptive_k__empty_buffer=False,
    )
    feed(low, 600)
    inner(low).refresh_posterior()
    assert (
        parts(low).counters.k == 2 and (inner(low).replay.floor == 0).all()
    )  # above the target: k -= 1, buffer kept


def test_incremental_mode_accumulates_update_minibatches(tmp_path: Path) -> None:
    agent = make_agent(tmp_path, blr__mode="incremental", k=3, train_every=2, batch_size=16)
    feed(agent, 500)
    for _ in range(40):
        inner(agent).update()
    assert parts(agent).head.count_A.sum().item() == 40 * 16  # every update's minibatch was added
    # each row has weight train_every / batch_size, so one env step has unit weight on average
    fresh = make_agent(tmp_path, blr__mode="incremental", train_every=2, batch_size=16)
    phi_BD, a_B, y_B = torch.randn(16, 32), torch.zeros(16, dtype=torch.int64), torch.randn(16)
    accumulate(inner(fresh).cfg, parts(fresh).head, parts(fresh).recent_phi, phi_BD, a_B, y_B)
    w = 2 / 16
    assert torch.allclose(
        parts(fresh).head.phiphiT_ADD[0].float(), w * phi_BD.T @ phi_BD, atol=1e-5
    )
    assert torch.allclose(parts(fresh).head.phiy_AD[0].float(), w * phi_BD.T @ y_B, atol=1e-5)
    phi = inner(agent).torso.net(torch.randn(32, 4)).detach()
    before = parts(agent).head.predictive_var(phi).mean().item()
    replay_rows = len(inner(agent).replay)
    inner(agent).refresh_posterior()  # no features recomputed from the buffer
    assert len(inner(agent).replay) == replay_rows
    assert parts(agent).head.num_refreshes == 1
    assert parts(agent).head.predictive_var(phi).mean().item() < before
    y_stats = parts(agent).head.phiy_AD.clone()
    inner(agent).refresh_posterior()
    assert torch.equal(parts(agent).head.phiy_AD, y_stats)  # a refresh alone adds nothing


def test_data_weight_scales_the_rows_weight_in_the_statistics(tmp_path: Path) -> None:
    """blr.data_weight c multiplies each row's weight train_every / batch_size: the statistics
    are c times those of the default, so a novel direction's mean moves c times as far from the
    prior per sample."""
    phi_BD, a_B, y_B = torch.randn(16, 32), torch.zeros(16, dtype=torch.int64), torch.randn(16)
    heads = []
    for c in (1.0, 8.0):
        agent = make_agent(
            tmp_path, blr__mode="incremental", blr__data_weight=c, train_every=2, batch_size=16
        )
        accumulate(inner(agent).cfg, parts(agent).head, parts(agent).recent_phi, phi_BD, a_B, y_B)
        heads.append(parts(agent).head)
    one, eight = heads
    assert torch.allclose(eight.phiphiT_ADD, 8 * one.phiphiT_ADD, atol=1e-4)
    assert torch.allclose(eight.phiy_AD, 8 * one.phiy_AD, atol=1e-4)
    assert torch.allclose(eight.count_A, one.count_A)  # rows counted, not weighted


def test_q_variance_without_adaptive_k_is_the_refreshs_own_when_read(tmp_path: Path) -> None:
    """With adaptive k off the Q-variance is computed when read (diagnostics, checkpoints):
    it is the value at the refresh, from the rows the refresh held, however many minibatches
    were added after it; a loaded checkpoint keeps its saved value."""
    from farsighter.ops.blr import greedy_predictive_variance

    agent = make_agent(
        tmp_path, blr__mode="incremental", blr__random_features=16, k=3, batch_size=128
    )
    feed(agent, 300)
    for refresh in range(3):
        for _ in range(16 if refresh == 0 else 5):  # 16 x 128 rows: the window is full, in place
            inner(agent).update()
        inner(agent).refresh_posterior()
        at_refresh = greedy_predictive_variance(parts(agent).head, parts(agent).recent_phi.rows())
        for _ in range(7):  # more rows in the recent window, the posterior unchanged
            inner(agent).update()
        assert agent.episode_diagnostics() == {"k": 3.0}  # an episode's row: nothing computed
        assert parts(agent).counters._pending is not None
        if refresh == 1:  # read through a checkpoint first
            assert agent.state_dict(include_replay=False)["counters"]["q_variance"] == at_refresh
        assert agent.diagnostics()["q_variance"] == at_refresh
    saved = agent.state_dict(include_replay=False)
    other = make_agent(
        tmp_path, blr__mode="incremental", blr__random_features=16, k=3, batch_size=128
    )
    feed(other, 300)
    for _ in range(5):
        inner(other).update()
    inner(other).refresh_posterior()  # its own deferred value, replaced by the load
    other.load_state_dict(saved)
    assert other.diagnostics()["q_variance"] == at_refresh


def test_recent_rows_keep_the_latest_rows_in_order() -> None:
    """The ring buffer of incremental mode's recent features holds what concatenating and
    keeping the last rows held, after adds of every size (larger than it too), and round-trips
    through its saved form."""
    from farsighter.agents.common import RecentRows

    gen = torch.Generator().manual_seed(0)
    ring, reference = RecentRows(10), None
    assert ring.rows() is None and ring.state_dict() is None
    for n in [3, 4, 1, 7, 10, 25, 2, 9, 9, 11]:
        rows = torch.randn(n, 2, generator=gen)
        ring.add(rows)
        reference = rows if reference is None else torch.cat([reference, rows])
        reference = reference[-10:]
        assert torch.equal(ring.rows(), reference)
        copy = RecentRows(10)
        copy.load_state_dict(ring.state_dict())
        assert torch.equal(copy.rows(), reference)


@pytest.mark.parametrize("redraw", list(SCHEDULES))
def test_exploration_resumes_its_draws_from_new_and_old_checkpoints(
    tmp_path: Path, redraw: str
) -> None:
    """Every blr.redraw value has its schedule, and an agent restored from a checkpoint (the
    current layout, or the one from before the exploration object, with its pieces under the
    agent's own keys) acts as the uninterrupted agent does."""
    from typing import get_args, get_type_hints

    from farsighter.config import BLRConfig

    assert set(SCHEDULES) == set(get_args(get_type_hints(BLRConfig)["redraw"]))
    rng = np.random.default_rng(3)
    obs = [rng.normal(size=(1, 4)).astype(np.float32) for _ in range(6)]
    agent = make_agent(tmp_path, blr__prior_std=10.0, blr__redraw=redraw, blr__redraw_every=3)
    for t in range(10):
        agent.act(obs[t % 4], 10)  # states repeat: revisit redraws
    saved = agent.state_dict(include_replay=False)
    old = {k: v for k, v in saved.items() if k != "exploration"}
    old.update(saved["exploration"])  # the layout before: w_EAD, draws, redraw_E, visits
    later = [agent.act(obs[t % 6], 10) for t in range(12)]
    for state in (saved, old):
        twin = make_agent(tmp_path, blr__prior_std=10.0, blr__redraw=redraw, blr__redraw_every=3)
        twin.load_state_dict(state)
        assert [twin.act(obs[t % 6], 10) for t in range(12)] == later
        assert parts(twin).counters.draws == parts(agent).counters.draws
