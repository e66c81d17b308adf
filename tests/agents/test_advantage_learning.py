"""blr.advantage_learning: the advantage-learning operator on the calibrated targets (after
blr.optimism until-reward's switch), in the operator itself, in the targets the update trains
on, and in the posterior's statistics."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from farsighter.agents.farsighter_targets import TensorBatch
from farsighter.config import make_config, validate
from farsighter.errors import ConfigError
from farsighter.ops.targets import advantage_learning
from tests.agents.test_exploration_defaults import make_agent
from tests.conftest import inner, parts


def _iterate(alpha: float, gamma: float = 0.9, sweeps: int = 3_000) -> np.ndarray:
    """Q of a two-state task by iterating the operator: in state 0, action 0 stays (reward 0)
    and action 1 moves to state 1, which pays 1 and ends the episode, whatever its action."""
    q = np.zeros((2, 2))
    for _ in range(sweeps):
        y = np.array([[gamma * q[0].max(), gamma * 1.0], [1.0, 1.0]])
        # Q(s, a) <- y(s, a) - alpha (max_b Q(s, b) - Q(s, a)), through the library's operator
        y_t = advantage_learning(
            torch.tensor(y.ravel()),
            torch.tensor(np.repeat(q, 2, axis=0)),
            torch.tensor([0, 1, 0, 1]),
            alpha,
        )
        q = y_t.numpy().reshape(2, 2)
    return q


@pytest.mark.parametrize("alpha", [0.5, 0.9])
def test_the_operator_keeps_the_greedy_value_and_widens_the_gap(alpha: float) -> None:
    """Bellemare et al. (2016): the greedy action's value stays V*, a wasted step's gap,
    (1 - gamma) V* under the Bellman operator, grows to (1 - gamma) V* / (1 - alpha)."""
    plain, widened = _iterate(0.0), _iterate(alpha)
    np.testing.assert_allclose(plain[0], [0.81, 0.9], atol=1e-9)  # V* 0.9, the stay 0.81
    np.testing.assert_allclose(widened[0, 1], plain[0, 1], atol=1e-9)
    gap = widened[0, 1] - widened[0, 0]
    np.testing.assert_allclose(gap, (plain[0, 1] - plain[0, 0]) / (1 - alpha), rtol=1e-6)


def _minibatch(n: int = 16) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(5)
    return {
        "obs_B": torch.randn(n, 4, generator=g),
        "next_obs_B": torch.randn(n, 4, generator=g),
        "actions_B": torch.arange(n) % 2,
        "returns_B": torch.rand(n, generator=g),
        "bootstrap_B": torch.full((n,), 0.9),
        "eps_BA@0": torch.zeros(n, 2),  # the optimistic targets' draws, none
    }


def test_the_update_and_the_statistics_train_on_the_lowered_targets(tmp_path: Path) -> None:
    """After the switch, the target of an action the target network does not rank first is
    lowered by alpha times its gap there, the greedy action's is kept; the loss and the rows
    added to the posterior's statistics both carry it; before the switch nothing changes."""
    values = {"preset": "general", "blr.advantage_learning": 0.8, "blr.mode": "incremental"}
    agent, plain = (
        make_agent(tmp_path / "a", **values),
        make_agent(tmp_path / "p", **{"preset": "general", "blr.advantage_learning": 0.0}),
    )
    for a in (agent, plain):
        loss, p = inner(a).loss, parts(a)
        loss.torso_target.load_state_dict(inner(agent).loss.torso.state_dict())
        loss.torso.load_state_dict(inner(agent).loss.torso.state_dict())
        g = torch.Generator().manual_seed(1)
        p.target_mean_AD.copy_(torch.randn(p.target_mean_AD.shape, generator=g))
        p.head.mean_AD.copy_(p.target_mean_AD)
    inputs = _minibatch()
    a_loss, p_loss = inner(agent).loss, inner(plain).loss
    torch.testing.assert_close(a_loss(inputs)["loss"], p_loss(inputs)["loss"])  # optimistic
    for a in (agent, plain):
        parts(a).calibrate()
    lowered, kept = a_loss(inputs), p_loss(inputs)
    t = TensorBatch.of(inputs)
    q_BA = a_loss.torso_target.net(t.obs_B) @ parts(agent).target_mean_AD.T
    greedy_B = q_BA.argmax(dim=1) == t.actions_B
    drop_B = kept["y_post_B@0"] - lowered["y_post_B@0"]
    assert greedy_B.any() and (~greedy_B).any()
    torch.testing.assert_close(drop_B[greedy_B], torch.zeros(int(greedy_B.sum())))
    gap_B = q_BA.max(dim=1).values - q_BA.gather(1, t.actions_B[:, None])[:, 0]
    torch.testing.assert_close(drop_B[~greedy_B], 0.8 * gap_B[~greedy_B])
    assert float(drop_B[~greedy_B].min()) > 0
    assert float(lowered["loss"]) != float(kept["loss"])


def test_advantage_learning_is_checked() -> None:
    with pytest.raises(ConfigError, match=r"blr.advantage_learning must be in \[0, 1\)"):
        validate(
            make_config(
                "farsighter", "CartPole-v1", preset="general", **{"blr.advantage_learning": 1.0}
            )
        )
    with pytest.raises(ConfigError, match=r"must be in \[0, 1\)"):
        validate(make_config("farsighter", "CartPole-v1", **{"blr.advantage_learning": -0.1}))
    # without a switch it never acts, and a run may still carry it (the default's, a flag away)
    validate(make_config("farsighter", "CartPole-v1", **{"blr.optimism": "always"}))


def test_the_switch_makes_the_learner_capture_the_update_again(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A captured CUDA graph replays the branches taken at capture, and the calibrated loss
    branches where its inputs need not show it (mean targets before and after the switch): the
    switch makes the learner capture again (tests/agents/test_cuda_graph.py checks the updates on a
    GPU)."""
    agent = make_agent(tmp_path, **{"preset": "general", "blr.target": "mean", "k_target": "k"})
    forgotten = []
    monkeypatch.setattr(inner(agent).learner, "forget_graphs", lambda: forgotten.append(1))
    inner(agent).calibrate(restart=False)
    assert forgotten == [1]
