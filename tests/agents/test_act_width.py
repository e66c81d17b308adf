"""blr.act_width = action-gap: the acting draws widened to the posterior mean's action gaps."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from farsighter import make_config, train
from farsighter.agents.common import RecentRows
from farsighter.agents.farsighter_posterior import FarsighterCounters, refresh_posterior
from farsighter.config.presets import PREVIOUS_GENERAL_FARSIGHTER
from farsighter.ops.blr import BLRHead, action_gap_scale


def _head(prior_std: float = 1.0) -> BLRHead:
    """Two actions over two features whose posterior mean is set by hand."""
    head = BLRHead(num_actions=2, dim=2, prior_std=prior_std, noise_std=1.0)
    head.set_mean(torch.tensor([[1.0, 0.0], [0.0, -5.0]]))
    return head


def test_the_factor_is_the_mean_gap_over_the_prior_sigma_and_at_least_one() -> None:
    # q(e1) = (1, 0): gap 1; q(e2) = (0, -5): gap 5; mean 3
    rows = torch.eye(2)
    assert action_gap_scale(_head(1.0), rows) == pytest.approx(3.0)
    assert action_gap_scale(_head(0.5), rows) == pytest.approx(6.0)
    assert action_gap_scale(_head(1.0), rows[:1]) == 1.0  # a gap of 1 does not narrow
    assert action_gap_scale(_head(10.0), rows) == 1.0  # within the prior's width
    assert action_gap_scale(_head(1.0), torch.zeros(0, 2)) == 1.0


def test_the_factor_widens_the_acting_draws_alone() -> None:
    """The acting draws' spread around the mean grows by act_scale, with the same normals; the
    targets' draws and the predictive variance keep the posterior's width; the factor is saved
    with the head."""
    head = BLRHead(num_actions=2, dim=3, prior_std=1.0, noise_std=1.0)
    gen = torch.Generator().manual_seed(0)
    head.accumulate(torch.randn(50, 3, generator=gen), torch.arange(50) % 2, torch.randn(50))
    head.refresh()
    x = torch.randn(4, 3, generator=gen)

    def draws() -> tuple[torch.Tensor, ...]:
        g = torch.Generator().manual_seed(1)
        w = head.sample_weights(5, generator=g) - head.mean_AD
        one = head.sample_weights(1, generator=g) - head.mean_AD  # the n <= 2 product
        noise = head.q_noise(x, generator=torch.Generator().manual_seed(2))
        return w, one, noise, head.predictive_var(x)

    w1, one1, noise1, var1 = draws()
    head.act_scale = 2.5
    w2, one2, noise2, var2 = draws()
    torch.testing.assert_close(w2, 2.5 * w1)
    torch.testing.assert_close(one2, 2.5 * one1)
    assert torch.equal(noise2, noise1) and torch.equal(var2, var1)
    other = BLRHead(num_actions=2, dim=3)
    other.load_state_dict(head.state_dict())
    assert other.act_scale == 2.5
    state = head.state_dict()
    del state["act_scale"]  # a checkpoint from before the option
    other.load_state_dict(state)
    assert other.act_scale == 1.0


@pytest.mark.parametrize("act_width", ["posterior", "action-gap"])
def test_a_refresh_sets_the_factor_from_the_recent_states(act_width: str) -> None:
    """An incremental refresh (what the agent and every seed of a seed batch call) sets the
    factor from the features of the latest minibatches, and only with the option on."""
    cfg = make_config("farsighter", "CartPole-v1", preset="general", **{"blr.act_width": act_width})
    head = BLRHead(num_actions=2, dim=2, prior_std=1.0, noise_std=1.0)
    e1 = torch.tensor([[1.0, 0.0]]).expand(200, 2)
    head.accumulate(e1, torch.zeros(200, dtype=torch.long), torch.full((200,), 8.0))
    recent = RecentRows(16)
    recent.add(e1[:16])
    counters = FarsighterCounters(k=1)
    rng = np.random.default_rng(0)
    refresh_posterior(cfg, head, counters, recent, None, rng, torch.device("cpu"), None, None)  # type: ignore[arg-type]
    # the mean learned Q(e1, 0) ~ 8 against Q(e1, 1) = 0
    assert head.mean_AD[0, 0] == pytest.approx(8.0, abs=0.1)
    if act_width == "posterior":
        assert head.act_scale == 1.0
    else:
        assert head.act_scale == pytest.approx(float(head.mean_AD[0, 0]), rel=1e-6)


def test_the_defaults_widen_the_draws_where_a_penalty_opens_a_gap(tmp_path: Path) -> None:
    """A run of session 45's default on CliffWalking (-100 for a step off the edge, -1 otherwise,
    where the option was measured): the values
    learn a gap of tens between the cliff step and the others, and the acting draws widen with
    it; with the posterior's own width they do not."""
    scales = {}
    for width in ("action-gap", "posterior"):
        cfg = make_config(
            "farsighter",
            "CliffWalking-v1",
            total_steps=1_500,
            eval_every=0,
            progress=False,
            run_dir=str(tmp_path / width),
            **{**PREVIOUS_GENERAL_FARSIGHTER, "blr.act_width": width},
        )
        assert cfg.preset == "general" and cfg.blr.scale == "residual"
        train(cfg)
        head = torch.load(tmp_path / width / "checkpoint.pt", weights_only=False)["agent"]["head"]
        scales[width] = head["act_scale"]
    assert scales["action-gap"] > 2.0 and scales["posterior"] == 1.0, scales
