"""Torso precision (fp32 / bf16 autocast) and the Nature CNN's channels-last layout."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch
from torch import nn

from farsighter import make_config
from farsighter.agents import build_agent
from farsighter.config import validate
from farsighter.errors import ConfigError
from farsighter.networks import MinAtarCNN, MLPTorso, NatureCNN, Torso, set_precision
from tests.conftest import inner


def _frames(shape: tuple[int, ...], seed: int = 0) -> torch.Tensor:
    rng = np.random.default_rng(seed)
    return torch.as_tensor(rng.integers(0, 256, size=shape, dtype=np.uint8))


def test_nature_cnn_channels_last_is_the_plain_convolution() -> None:
    torch.manual_seed(0)
    net = NatureCNN(4)
    x = _frames((3, 4, 84, 84))
    assert net.conv[0].weight.is_contiguous(memory_format=torch.channels_last)
    h = x.float() / 255.0  # the same layers on standard (NCHW) tensors
    for layer in net.conv:
        if isinstance(layer, nn.Conv2d):
            h = nn.functional.conv2d(
                h, layer.weight.contiguous(), layer.bias, stride=layer.stride
            ).contiguous()
        else:
            h = layer(h)
    expected = net.fc(h)
    torch.testing.assert_close(net(x), expected, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize(
    ("make", "x"),
    [
        (lambda: NatureCNN(4), _frames((8, 4, 84, 84))),
        (lambda: MinAtarCNN(4), _frames((8, 4, 10, 10)) % 2),
        (lambda: MLPTorso(6, (64, 64)), torch.randn(8, 6)),
    ],
)
def test_bf16_features_are_float32_and_close_to_fp32(make, x) -> None:  # type: ignore[no-untyped-def]
    torch.manual_seed(0)
    net = make()
    fp32 = net(x)
    set_precision(net, "bf16")
    bf16 = net(x)
    assert bf16.dtype == torch.float32 and fp32.dtype == torch.float32
    rel = (bf16 - fp32).norm() / fp32.norm()
    assert 0 < rel < 0.03  # rounded (bf16 keeps 8 bits of mantissa), but the same features
    bf16.sum().backward()  # gradients reach the fp32 parameters
    assert all(p.grad is not None and p.grad.dtype == torch.float32 for p in net.parameters())


@pytest.mark.parametrize("algo", ["ddqn", "farsighter", "ob2i", "rnd"])
def test_build_agent_sets_the_precision_of_every_torso(algo: str) -> None:
    cfg = make_config(algo, "CartPole-v1", precision="bf16", buffer_size=1_000)
    obs_space = gym.spaces.Box(-1, 1, (4,), np.float32)
    agent = build_agent(cfg, obs_space, gym.spaces.Discrete(2), frame_stack=1, device="cpu")
    held = [
        *vars(inner(agent)).values(),
        *vars(inner(agent).loss).values(),
    ]  # the loss owns the targets
    torsos = [
        m for v in held if isinstance(v, nn.Module) for m in v.modules() if isinstance(m, Torso)
    ]
    assert len({id(t) for t in torsos}) >= 2  # online and target at least
    assert {t.precision for t in torsos} == {"bf16"}
    actions = agent.act(np.zeros((1, 4), np.float32), global_step=10**6)
    assert actions.shape == (1,)


def test_precision_is_validated() -> None:
    cfg = make_config("ddqn", "CartPole-v1")
    import dataclasses

    with pytest.raises(ConfigError, match="precision must be fp32 or bf16"):
        runtime = dataclasses.replace(cfg.runtime, precision="fp16")  # type: ignore[arg-type]
        validate(dataclasses.replace(cfg, runtime=runtime))
