"""OB2I: backward induction against hand-computed targets, the UCB-bonus, the per-head hidden
layers of the authors' network, every head learning from every sample, acting, and an Atari-shaped
smoke run."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch
from torch import nn

import farsighter
from farsighter.agents.ob2i import OB2IAgent, ensemble_td_loss
from farsighter.config import make_config, validate
from farsighter.errors import ConfigError
from farsighter.networks import EnsembleHeads, EnsembleQNetwork, make_torso
from farsighter.ops.ob2i import backward_targets, next_state_bonus, ucb_bonus
from farsighter.replay import VectorStep
from tests.conftest import GrabAgent, tiny

# A three-step episode, K = 2 heads, A = 2 actions, gamma = 0.9, beta = 0.5.
R = np.array([1.0, 0.0, 2.0], np.float32)
A = np.array([0, 1, 0])
Q_NEXT = np.array(  # Q~[t] = Q_target(s_{t+1}, .) per head
    [
        [[1.0, 3.0], [2.0, 0.0]],  # s_1
        [[4.0, 2.0], [0.0, 1.0]],  # s_2
        [[7.0, 7.0], [7.0, 7.0]],  # s_3 (the last state)
    ],
    np.float32,
)


def test_backward_induction_terminal_episode_by_hand() -> None:
    # t=2: terminal, y = r = 2 for both heads; Q~(s_2, a_2=0) <- 0.5*2 + 0.5*[4, 0] = [3, 1]
    # t=1: y = 0 + 0.9 * max([3, 2], [1, 1]) = [2.7, 0.9]; Q~(s_1, a_1=1) <- [2.85, 0.45]
    # t=0: y = 1 + 0.9 * max([1, 2.85], [2, 0.45]) = [3.565, 2.8]
    zero = np.zeros((3, 2))
    y = backward_targets(R, A, Q_NEXT, zero, terminated=True, gamma=0.9, beta=0.5)
    assert np.allclose(y, [[3.565, 2.8], [2.7, 0.9], [2.0, 2.0]])
    assert Q_NEXT[1, 0, 0] == 4.0  # the input Q~ is not modified


def test_backward_induction_with_next_state_bonus_by_hand() -> None:
    bonus = np.array([[0.1, 0.2], [0.3, 0.4], [9.0, 9.0]])  # the last one is unused (terminal)
    # t=1: y = 0.9 * ([3, 1] + [0.3, 0.4]) = [2.97, 1.26]; Q~(s_1, 1) <- [2.985, 0.63]
    # t=0: y = 1 + 0.9 * ([2.985, 2] + [0.1, 0.2]) = [3.7765, 2.98]
    y = backward_targets(R, A, Q_NEXT, bonus, terminated=True, gamma=0.9, beta=0.5)
    assert np.allclose(y, [[3.7765, 2.98], [2.97, 1.26], [2.0, 2.0]])


def test_backward_induction_truncated_episode_bootstraps_from_last_state() -> None:
    # t=2: y = 2 + 0.9 * 7 = 8.3; Q~(s_2, 0) <- [6.15, 4.15]
    # t=1: y = 0.9 * [6.15, 4.15] = [5.535, 3.735]; Q~(s_1, 1) <- [4.2675, 1.8675]
    # t=0: y = 1 + 0.9 * [4.2675, 2] = [4.84075, 2.8]
    y = backward_targets(R, A, Q_NEXT, np.zeros((3, 2)), terminated=False, gamma=0.9, beta=0.5)
    assert np.allclose(y, [[4.84075, 2.8], [5.535, 3.735], [8.3, 8.3]])


def test_beta_one_is_a_monte_carlo_return_along_the_greedy_path() -> None:
    r = np.array([1.0, 1.0, 1.0, 1.0], np.float32)
    a = np.zeros(4, np.int64)
    q = np.zeros((4, 1, 2), np.float32)  # Q~ = 0 everywhere: the diffused targets dominate
    y = backward_targets(r, a, q, np.zeros((4, 1)), terminated=True, gamma=0.5, beta=1.0)
    assert np.allclose(y[:, 0], [1.875, 1.75, 1.5, 1.0])


def test_ucb_bonus_is_the_std_over_heads_and_zero_when_heads_agree() -> None:
    q_BKA = torch.tensor([[[1.0, 0.0], [3.0, 2.0], [2.0, 5.0]]])
    expected = np.array([np.std([1.0, 3.0, 2.0]), np.std([0.0, 2.0, 5.0])])
    assert np.allclose(ucb_bonus(q_BKA).numpy()[0], expected)
    same = torch.randn(4, 1, 3).expand(4, 10, 3)
    assert torch.all(ucb_bonus(same) == 0)
    # Next-state bonus at each head's greedy action, dropped where it is the action taken next.
    bonus, keep = next_state_bonus(q_BKA.numpy(), np.array([0]))
    assert np.allclose(bonus, [[expected[0], expected[0], expected[1]]])
    assert keep.tolist() == [[False, False, True]]


def _agent(tmp_path: Path, **kw: Any) -> OB2IAgent:
    cfg = tiny("ob2i", tmp_path / "unused", **kw)
    env = gym.make("CartPole-v1")
    return OB2IAgent(
        cfg, env.observation_space, env.action_space, frame_stack=1, device=torch.device("cpu")
    )  # type: ignore[arg-type]


def _fill(agent: OB2IAgent, lengths: list[int], seed: int = 0) -> None:
    rng = np.random.default_rng(seed)
    for length in lengths:
        for t in range(length):
            last = t == length - 1
            agent.observe(
                VectorStep(
                    rng.normal(size=(1, 4)).astype(np.float32),
                    np.array([rng.integers(2)]),
                    np.array([1.0]),
                    np.array([last]),
                    np.array([False]),
                    [rng.normal(size=4).astype(np.float32)] if last else None,
                )
            )


def _head_params(net: EnsembleQNetwork, k: int) -> list[torch.Tensor]:
    """Views of the parameters of head k alone (per-head layers, or a slice of the linear heads)."""
    h = net.heads
    if isinstance(h, EnsembleHeads):
        return [h.hidden_weight[k], h.hidden_bias[k], h.out_weight[k], h.out_bias[k]]
    assert isinstance(h, nn.Linear)
    return [h.weight.view(net.num_heads, net.num_actions, -1)[k], h.bias.view(net.num_heads, -1)[k]]


@pytest.mark.parametrize("separate", [True, False])
def test_bonus_is_zero_when_all_heads_agree(tmp_path: Path, separate: bool) -> None:
    agent = _agent(
        tmp_path,
        ob2i__bonus_reward_weight=1.0,
        ob2i__bonus_next_weight=1.0,
        ob2i__separate_heads=separate,
    )
    with torch.no_grad():  # every head a copy of head 0
        for k in range(1, 10):
            for p_k, p_0 in zip(_head_params(agent.q, k), _head_params(agent.q, 0), strict=True):
                p_k.copy_(p_0)
    agent.loss.q_target.load_state_dict(agent.q.state_dict())
    _fill(agent, [7])
    ep = agent.replay.sample_episode()
    y = agent.episode_targets(ep)
    # float32 rounding: numpy's std of K equal values can be ~1e-9 rather than 0
    assert abs(agent.stats["bonus_reward"]) < 1e-5 and abs(agent.stats["bonus_next"]) < 1e-5
    rows = np.arange(1, 8)
    q_next = agent.loss.q_target(agent._obs(0, rows)).detach().numpy()
    plain = backward_targets(ep.rewards, ep.actions, q_next, np.zeros((7, 10)), True, 0.99, 0.5)
    assert np.allclose(y, plain, atol=1e-5)
    assert np.allclose(y, y[:, :1])  # identical heads, identical targets


def test_bonus_is_added_when_heads_disagree(tmp_path: Path) -> None:
    agent = _agent(tmp_path, ob2i__bonus_reward_weight=1.0, ob2i__bonus_next_weight=0.0)
    _fill(agent, [5])
    ep = agent.replay.sample_episode()
    y = agent.episode_targets(ep)
    assert agent.stats["bonus_reward"] > 0
    q_next = agent.loss.q_target(agent._obs(0, np.arange(1, 6))).detach().numpy()
    plain = backward_targets(ep.rewards, ep.actions, q_next, np.zeros((5, 10)), True, 0.99, 0.5)
    assert (y > plain).all()  # the immediate bonus is optimistic for every head


MLP_SPACE = gym.spaces.Box(-1.0, 1.0, (4,), np.float32)
IMAGE_SPACE = gym.spaces.Box(0, 255, (4, 84, 84), np.uint8)


@pytest.mark.parametrize(
    ("space", "hidden_sizes", "trunk_dim", "width"),
    [
        (MLP_SPACE, (32, 16), 32, 16),
        (MLP_SPACE, (16,), 4, 16),  # one layer: the trunk is the flattened observation
        (IMAGE_SPACE, (64, 32), 3136, 512),  # the Nature CNN's conv layers, 512 units per head
    ],
)
def test_separate_heads_each_own_a_hidden_layer(
    space: gym.spaces.Box, hidden_sizes: tuple[int, ...], trunk_dim: int, width: int
) -> None:
    torch.manual_seed(0)
    net = EnsembleQNetwork(space, 3, 5, hidden_sizes, separate_heads=True)
    assert isinstance(net.heads, EnsembleHeads)
    assert net.torso.out_dim == trunk_dim
    assert net.heads.hidden_weight.shape == (5, width, trunk_dim)
    assert net.heads.out_weight.shape == (5, 3, width)
    space.seed(0)  # the space's own generator: unseeded, a draw could leave a unit dead
    obs = torch.as_tensor(np.stack([space.sample() for _ in range(2)]))
    with torch.no_grad():
        q = net(obs)
        assert q.shape == (2, 5, 3)
        for i in range(4):  # each of head 2's layers: only head 2's Q moves
            _head_params(net, 2)[i].add_(1.0)
            moved = net(obs)
            assert not torch.equal(moved[:, 2], q[:, 2])
            assert torch.equal(moved[:, [0, 1, 3, 4]], q[:, [0, 1, 3, 4]])
            q = moved


def test_batched_heads_equal_separate_linear_layers() -> None:
    torch.manual_seed(3)
    heads = EnsembleHeads(7, 5, 3, 4)
    torch.manual_seed(3)  # K separate heads, built in order, draw the same initial weights
    mlps = [nn.Sequential(nn.Linear(7, 5), nn.ReLU(), nn.Linear(5, 3)) for _ in range(4)]
    for k, mlp in enumerate(mlps):
        assert torch.equal(mlp[0].weight, heads.hidden_weight[k])
        assert torch.equal(mlp[0].bias, heads.hidden_bias[k])
        assert torch.equal(mlp[2].weight, heads.out_weight[k])
        assert torch.equal(mlp[2].bias, heads.out_bias[k])
    with torch.no_grad():  # and the forward pass is the per-head loop, for any weights
        for p in heads.parameters():
            p.normal_()
        for k, mlp in enumerate(mlps):
            mlp[0].weight.copy_(heads.hidden_weight[k])
            mlp[0].bias.copy_(heads.hidden_bias[k])
            mlp[2].weight.copy_(heads.out_weight[k])
            mlp[2].bias.copy_(heads.out_bias[k])
    x_BD = torch.randn(6, 7)
    q_BKA = heads(x_BD)
    assert q_BKA.shape == (6, 4, 3)
    assert torch.allclose(q_BKA, torch.stack([mlp(x_BD) for mlp in mlps], dim=1), atol=1e-5)


def test_shared_heads_option_keeps_linear_heads_on_one_torso() -> None:
    torch.manual_seed(1)
    net = EnsembleQNetwork(MLP_SPACE, 2, 10, (32, 16), separate_heads=False)
    assert isinstance(net.heads, nn.Linear)
    torso = (4 * 32 + 32) + (32 * 16 + 16)
    assert sum(p.numel() for p in net.parameters()) == torso + 10 * (16 * 2 + 2)
    torch.manual_seed(1)  # the network of earlier versions, weight for weight
    old_torso = make_torso(MLP_SPACE, (32, 16))
    old_heads = nn.Linear(16, 10 * 2)
    old = [*old_torso.parameters(), *old_heads.parameters()]
    assert all(torch.equal(p, o) for p, o in zip(net.parameters(), old, strict=True))
    separate = EnsembleQNetwork(MLP_SPACE, 2, 10, (32, 16), separate_heads=True)
    trunk = 4 * 32 + 32
    assert sum(p.numel() for p in separate.parameters()) == trunk + 10 * (32 * 16 + 16 + 16 * 2 + 2)


def test_loss_gives_every_head_gradient_from_every_sample() -> None:
    q_BK = torch.randn(6, 4, requires_grad=True)
    y_BK = torch.randn(6, 4)
    ensemble_td_loss(q_BK, y_BK, "mse").backward()
    assert q_BK.grad is not None
    # mean over the B x K entries, divided by K: no bootstrap mask zeroes any entry
    assert torch.allclose(q_BK.grad, 2 * (q_BK - y_BK).detach() / (6 * 4) / 4)


@pytest.mark.parametrize("separate", [True, False])
def test_update_moves_every_head_and_walks_the_episode_backward(
    tmp_path: Path, separate: bool
) -> None:
    agent = _agent(tmp_path, batch_size=4, ob2i__separate_heads=separate)
    _fill(agent, [10])
    before = [[p.detach().clone() for p in _head_params(agent.q, k)] for k in range(10)]
    assert agent.update() is not None
    assert agent.episode is not None and agent.cursor == 6  # rows 6..9 first (the end)
    for k in range(10):  # every layer of every head moved
        assert all(
            not torch.equal(b, a) for b, a in zip(before[k], _head_params(agent.q, k), strict=True)
        )
    agent.update()
    agent.update()
    assert agent.cursor == 0 and agent.counters.episodes_learned == 1  # 4 + 4 + 2 rows
    agent.update()
    assert agent.counters.episodes_learned == 2  # the next update draws a new episode


def test_one_head_per_episode_and_environment(tmp_path: Path) -> None:
    agent = _agent(tmp_path, num_envs=3, eps_start=0.0, eps_end=0.0)
    heads = agent.explore.head_E.copy()
    obs = np.zeros((3, 4), np.float32)
    q = agent.q(torch.as_tensor(obs)).detach()
    acts = agent.act(obs, global_step=10_000)
    assert list(acts) == [int(q[i, heads[i]].argmax()) for i in range(3)]
    none = np.zeros(3, bool)
    agent.observe(VectorStep(obs, acts, np.ones(3), none, none, None))
    assert np.array_equal(agent.explore.head_E, heads)  # no episode ended: same heads
    ended = np.array([True, True, True])
    for _ in range(5):
        agent.observe(VectorStep(obs, acts, np.ones(3), ended, none, list(obs)))
    assert not np.array_equal(agent.explore.head_E, heads)  # redrawn at episode ends
    mean, var = agent.q_estimate(obs)
    assert mean.shape == var.shape == (3, 2) and (var >= 0).all()
    assert np.allclose(mean, q.mean(dim=1).numpy())
    assert agent.act(obs, 0, explore=False).shape == (3,)  # the heads' vote


def test_config_defaults_and_validation(tmp_path: Path) -> None:
    cfg = make_config("ob2i", "CartPole-v1")
    assert cfg.ob2i.num_heads == 10 and cfg.ob2i.beta == 0.5
    assert cfg.ob2i.separate_heads  # the authors' network: a hidden layer per head
    assert cfg.ob2i.bonus_reward_weight == cfg.ob2i.bonus_next_weight == 5e-5
    assert (cfg.eps_start, cfg.eps_end) == (1.0, 0.1)
    # SPEC 2.3's 1.0 -> 0.1 survives presets written for epsilon-greedy DQN; a flag still wins
    for preset in ("atari", "cartpole", "control"):
        assert make_config("ob2i", "CartPole-v1", preset=preset).eps_end == 0.1
    assert make_config("ddqn", "CartPole-v1", preset="cartpole").eps_end == 0.02
    assert make_config("ob2i", "CartPole-v1", preset="cartpole", eps_end=0.05).eps_end == 0.05
    with pytest.raises(ConfigError, match="ob2i.num_heads"):
        validate(make_config("ob2i", ob2i__num_heads=1))
    with pytest.raises(ConfigError, match="whole episodes"):
        validate(make_config("ob2i", k=3))


def test_atari_smoke_with_frame_stacks(tmp_path: Path) -> None:
    pytest.importorskip("ale_py")
    cfg = make_config(
        "ob2i",
        "ALE/Breakout-v5",
        total_steps=300,
        learning_starts=100,
        buffer_size=1_000,
        batch_size=16,
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
    agent = grab.agent
    assert (
        agent.replay.frame_stack == 4 and agent.counters.episodes_learned >= 1
    )  # life-loss episodes
    assert np.isfinite(agent.diagnostics()["bonus"])


def test_checkpoint_restores_the_episode_in_progress(tmp_path: Path) -> None:
    """With the replay saved, a restored agent continues the episode it was walking backward."""
    agent = _agent(tmp_path, batch_size=4)
    _fill(agent, [10])
    agent.update()  # rows 6..9 done, cursor at 6
    restored = _agent(tmp_path, batch_size=4)
    restored.load_state_dict(agent.state_dict(include_replay=True))
    assert restored.episode is not None and restored.cursor == 6
    assert np.array_equal(restored.y_TK, agent.y_TK)
    without = _agent(tmp_path, batch_size=4)
    without.load_state_dict(agent.state_dict(include_replay=False))
    assert without.episode is None and without.cursor == 0  # its rows are not there
