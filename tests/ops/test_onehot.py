"""The one-hot gather (farsighter.ops.onehot) gives F.linear's values bit for bit, and the
networks that use it give the values they give without it."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch
import torch.nn.functional as F

from farsighter.networks import MLPTorso, QNetwork, RandomFeatureTorso
from farsighter.ops import onehot
from farsighter.ops.onehot import (
    gathered_linear,
    one_hot_rows,
    stacked_gathered_linear,
    worth_gathering,
)
from farsighter.stacked import StackedQNetwork


def one_hot(rows: int, width: int, g: torch.Generator, zero_rows: int = 0) -> torch.Tensor:
    x = torch.zeros(rows, width)
    x[torch.arange(rows), torch.randint(0, width, (rows,), generator=g)] = 1.0
    x[:zero_rows] = 0.0  # deep sea's observation after the last row is all zero
    return x


@pytest.mark.parametrize("rows", [1, 7, 128])
@pytest.mark.parametrize(("inp", "out"), [(400, 128), (36, 512), (900, 64), (100, 2)])
def test_gather_is_f_linear_bit_for_bit(rows: int, inp: int, out: int) -> None:
    g = torch.Generator().manual_seed(rows * inp + out)
    for scale in (1e-3, 1.0, 30.0):
        w, b = torch.randn(out, inp, generator=g) * scale, torch.randn(out, generator=g)
        for zero_rows in (0, 1):
            x = one_hot(rows, inp, g, zero_rows)
            hot = one_hot_rows(x)
            assert hot is not None
            got = gathered_linear(hot, w, b)
            assert got.is_contiguous()
            assert torch.equal(got, F.linear(x, w, b))
            # the seed-stacked form: each seed's slice is its F.linear
            S = 3
            xs = torch.stack([one_hot(rows, inp, g, zero_rows) for _ in range(S)])
            ws, bs = torch.randn(S, out, inp, generator=g), torch.randn(S, out, generator=g)
            hot_s = one_hot_rows(xs)
            assert hot_s is not None
            got_s = stacked_gathered_linear(hot_s, ws, bs)
            for s in range(S):
                assert torch.equal(got_s[s], F.linear(xs[s], ws[s], bs[s])), (s, zero_rows)


@pytest.mark.parametrize(
    "row",
    [
        [0.0, 2.0, 0.0],  # one nonzero, not 1
        [1.0, 1.0, 0.0],  # two ones
        [1.0, -1.0, 1.0],  # sums to 1 with three nonzeros
        [0.5, 0.5, 0.0],  # sums to 1 with two nonzeros
        [-1.0, 0.0, 0.0],
        [float("nan"), 0.0, 0.0],
        [0.25, 0.0, 0.0],
    ],
)
def test_rows_that_are_not_one_hot_are_refused(row: list[float]) -> None:
    x = torch.tensor([[0.0, 0.0, 1.0], row])
    assert one_hot_rows(x) is None
    assert one_hot_rows(torch.tensor([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])) is not None


def test_gather_only_where_it_pays_and_never_under_autocast() -> None:
    w = torch.zeros(128, 400)
    assert worth_gathering(torch.zeros(128, 400), w)
    assert not worth_gathering(torch.zeros(1, 4), torch.zeros(8, 4))  # too little work
    assert not worth_gathering(torch.zeros(128, 400, dtype=torch.float64), w)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        assert not worth_gathering(torch.zeros(128, 400), w)


def _without_gather(monkeypatch: Any) -> None:
    monkeypatch.setattr(onehot, "MIN_WORK", 1 << 62)


def test_networks_give_the_same_values_with_and_without_the_gather(monkeypatch: Any) -> None:
    """Forward values of a QNetwork, a random-feature torso and their seed stack on one-hot rows
    (deep sea N = 20), with gradients flowing and without: equal with the gather switched off.
    The gather must also be taken (a network that never took it would pass trivially)."""
    space = gym.spaces.Box(0.0, 1.0, (400,), np.float32)
    torch.manual_seed(0)
    nets = [QNetwork(space, 2, (128, 128)) for _ in range(3)]
    torsos = [RandomFeatureTorso(MLPTorso(400, (64,)), 400, 512) for _ in range(3)]
    g = torch.Generator().manual_seed(1)
    x = one_hot(128, 400, g, zero_rows=2)
    xs = torch.stack([one_hot(128, 400, g, zero_rows=1) for _ in range(3)])
    stacked_q, stacked_t = StackedQNetwork(nets), StackedQNetwork(torsos)

    def values() -> list[torch.Tensor]:
        out = []
        with torch.no_grad():
            out += [nets[0](x), torsos[0](x), stacked_q(xs), stacked_t(xs), stacked_t.psi(xs)]
        out += [nets[0](x).detach(), torsos[0](x).detach()]
        q = stacked_q(xs)  # with autograd: the gather forward, the product's backward
        q.square().sum().backward()
        out += [q.detach(), *(p.grad.clone() for p in stacked_q.parameters())]
        stacked_q.zero_grad()
        return out

    calls = []
    real = onehot.one_hot_rows

    def counted(t: torch.Tensor) -> Any:
        result = real(t)
        calls.append(result is not None)
        return result

    monkeypatch.setattr(onehot, "one_hot_rows", counted)  # what hot_rows calls
    with_gather = values()
    assert sum(calls) >= 5, calls  # target nets, psi, stacks: each took the gather
    _without_gather(monkeypatch)
    calls.clear()
    without = values()
    assert not calls
    for a, b in zip(with_gather, without, strict=True):
        assert torch.equal(a, b)


@pytest.mark.parametrize(
    "row",
    [
        [1.0, 1e-30, 0.0],  # the float sum rounds to 1
        [1.0 - 2.0**-24, 2.0**-24, 0.0],  # sums to 1 exactly
        [0.5, 1.1754944e-38, 0.0],  # bits sum to those of 1.0
        [-0.0, 1.0, 0.0],  # a sign bit
        [float("inf"), 0.0, 0.0],
        [1e-45, 0.0, 0.0],  # a denormal
    ],
)
def test_rows_that_fool_a_sum_are_refused(row: list[float]) -> None:
    assert one_hot_rows(torch.tensor([[0.0, 0.0, 1.0], row])) is None


def test_one_hot_rows_gives_each_rows_column() -> None:
    g = torch.Generator().manual_seed(3)
    x = one_hot(64, 900, g, zero_rows=3)
    hot = one_hot_rows(x)
    assert hot is not None
    index, value = hot
    assert torch.equal(value, x.sum(1))
    assert torch.equal(index[3:], x[3:].argmax(1))


def test_a_compiled_network_takes_no_gather() -> None:
    """Inside a step being compiled the one-hot check (which reads values) is not made, so a
    network over one-hot rows compiles as one graph, with F.linear's values."""
    g = torch.Generator().manual_seed(0)
    x = one_hot(256, 400, g)
    net = RandomFeatureTorso(MLPTorso(400, (64,)), 400, 512)
    assert worth_gathering(x, net.rf_weight)  # eager: the gather (the test above)
    with torch.no_grad():
        eager = net(x)
        compiled = torch.compile(net, fullgraph=True, dynamic=False)(x)
    torch.testing.assert_close(compiled, eager, rtol=1e-5, atol=1e-5)
