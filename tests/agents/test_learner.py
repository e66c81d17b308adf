"""The learner (farsighter.agents.learner): the one owner of the update's fast path, and the
target cache as a wrapper on the target network that clears itself when the target is copied."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from torch import nn

from farsighter.agents.learner import Learner
from tests.conftest import tiny


def _loss(net: nn.Module) -> object:
    def loss(inputs: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        pred = net(inputs["x"]).squeeze(-1)
        return {"loss": ((pred - inputs["y"]) ** 2).mean(), "pred": pred}

    return loss


def _batch(seed: int) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    return {"x": torch.randn(8, 3, generator=g), "y": torch.randn(8, generator=g)}


def _net(seed: int = 0) -> nn.Linear:
    torch.manual_seed(seed)
    return nn.Linear(3, 1)


@pytest.mark.parametrize("max_norm", [0.0, 0.01])
def test_the_learner_clips_the_gradient_it_steps_with(tmp_path: Path, max_norm: float) -> None:
    cfg = tiny("ddqn", tmp_path)
    net = _net()
    before = torch.cat([p.detach().flatten().clone() for p in net.parameters()])
    sgd = torch.optim.SGD(net.parameters(), lr=1.0)
    learner = Learner(_loss(net), net.parameters(), cfg, torch.device("cpu"), sgd, max_norm)
    out = learner(_batch(1))
    assert not out["loss"].requires_grad and set(out) == {"loss", "pred"}
    step = torch.cat([p.detach().flatten() for p in net.parameters()]) - before
    if max_norm:  # SGD at lr 1 moves by the gradient: its norm is the clipped one
        assert step.norm() == pytest.approx(max_norm, rel=1e-3)
    else:
        assert step.norm() > 0.1


def test_a_loaded_learner_continues_alike_and_shares_no_state(tmp_path: Path) -> None:
    cfg = tiny("ddqn", tmp_path, optimizer="adam")
    nets = [_net(), _net()]
    a, b = (Learner(_loss(n), n.parameters(), cfg, torch.device("cpu")) for n in nets)
    a(_batch(1))
    b.load_state_dict(a.state_dict())
    nets[1].load_state_dict(nets[0].state_dict())
    for seed in (2, 3):
        assert torch.equal(a(_batch(seed))["loss"], b(_batch(seed))["loss"])
    for p, q in zip(nets[0].parameters(), nets[1].parameters(), strict=True):
        assert torch.equal(p, q)
    ours = [s["exp_avg"].data_ptr() for s in a.opt.state.values()]
    assert not set(ours) & {s["exp_avg"].data_ptr() for s in b.opt.state.values()}


def test_an_eager_learner_is_never_compiled(tmp_path: Path) -> None:
    cfg = tiny("ddqn", tmp_path, compile=True)
    net = nn.Linear(3, 1)
    eager = Learner(_loss(net), net.parameters(), cfg, torch.device("cpu"), eager=True)
    assert eager.step == eager._update and eager.graphs is False
    compiled = Learner(_loss(net), net.parameters(), cfg, torch.device("cpu"))
    assert hasattr(compiled.step, "_torchdynamo_orig_callable")
