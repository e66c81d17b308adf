"""Representation networks phi_theta(s): an MLP for flat observations, the Nature CNN for images,
the MinAtar CNN for MinAtar's 10x10 object planes.

Every torso returns float32 features. With ``precision = "bf16"`` (:func:`set_precision`) its
layers run under bfloat16 autocast and the features are cast back to float32, so what comes after
the torso (linear heads, the BLR posterior, targets, losses) stays float32. Parameters and
optimizer state are float32 either way. The Nature CNN keeps its convolutions channels-last
(NHWC), the layout oneDNN and cuDNN convolve fastest; the math is the same.
"""

from __future__ import annotations

import math
from typing import Any, Literal

import gymnasium as gym
import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from farsighter.ops.bayes_layer import BayesianLinear
from farsighter.ops.naf import NAFHead, naf_q, scale_action
from farsighter.ops.onehot import gathered_linear, hot_rows

Precision = Literal["fp32", "bf16"]


class Torso(nn.Module):
    """What the torsos share: ``forward`` scales and lays out the observations
    (:meth:`prepare`), runs :meth:`body` on them in the torso's precision and returns float32
    features of width ``out_dim``."""

    out_dim: int

    def __init__(self) -> None:
        super().__init__()
        self.precision: Precision = "fp32"

    def prepare(self, obs: torch.Tensor) -> torch.Tensor:
        """The network's input from a batch of observations. Two torsos of one architecture
        (an online and a target network) can share it: ``forward(x, prepared=True)``."""
        return obs

    def body(self, x: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError

    def forward(self, obs: torch.Tensor, prepared: bool = False) -> torch.Tensor:
        x = obs if prepared else self.prepare(obs)
        if self.precision == "fp32":
            return self.body(x)
        # no cast cache: it would outlive a CUDA graph capture (and a region casts each weight once)
        with torch.autocast(x.device.type, dtype=torch.bfloat16, cache_enabled=False):
            return self.body(x).float()


def set_precision(module: nn.Module, precision: Precision) -> None:
    """Set the precision of every torso inside ``module`` (fp32 or bf16 autocast)."""
    for sub in module.modules():
        if isinstance(sub, Torso):
            sub.precision = precision


def _channels_last(frames_BCHW: torch.Tensor) -> torch.Tensor:
    return frames_BCHW.contiguous(memory_format=torch.channels_last)


class MLPTorso(Torso):
    """Fully connected ReLU layers; ``out_dim`` is the feature dimension d."""

    def __init__(self, obs_dim: int, hidden_sizes: tuple[int, ...]) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        last = obs_dim
        for size in hidden_sizes:
            layers += [nn.Linear(last, size), nn.ReLU()]
            last = size
        self.net = nn.Sequential(*layers)
        self.out_dim = last
        self._cache_params()

    def _cache_params(self) -> None:
        # The layers' (weight, bias) tensors, read without a module attribute lookup each. The
        # optimizer and load_state_dict write into these tensors; a move (.to, .cuda, .float)
        # may replace them, so _apply takes them again.
        self._params = [(m.weight, m.bias) for m in self.net if isinstance(m, nn.Linear)]

    def _apply(self, fn: Any, recurse: bool = True) -> MLPTorso:
        super()._apply(fn, recurse)
        self._cache_params()
        return self

    def prepare(self, obs_BO: torch.Tensor) -> torch.Tensor:
        return obs_BO.float().flatten(1)

    def body(self, x: torch.Tensor) -> torch.Tensor:
        # ``self.net``'s layers called as functions: the same operations, without a module call
        # or attribute lookup per layer (a tenth of a millisecond per forward of a small net on
        # a slow CPU, paid at every environment step).
        for i, (weight, bias) in enumerate(self._params):
            x = torch.relu(_linear(x, weight, bias) if i == 0 else F.linear(x, weight, bias))
        return x


def _linear(x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor) -> torch.Tensor:
    """``F.linear`` of a network's input layer; where no gradient flows through it and the rows
    are one-hot (tabular tasks), the same values by a gather (:mod:`farsighter.ops.onehot`)."""
    grad = torch.is_grad_enabled() and (weight.requires_grad or x.requires_grad)
    hot = None if grad else hot_rows(x, weight)
    return F.linear(x, weight, bias) if hot is None else gathered_linear(hot, weight, bias)


def random_feature_map(pre: torch.Tensor, width: int) -> torch.Tensor:
    """psi = relu(pre) / sqrt(width) from the random layer's pre-activations ``pre`` = W s + b,
    in place."""
    return pre.relu_().div_(math.sqrt(width))


class RandomFeatureTorso(Torso):
    """A flat torso's learned features followed by ``width`` fixed random features of the
    observation, drawn once and never trained (buffers: saved, loaded and copied to the target
    with the weights): psi(s) = relu(W s + b) / sqrt(width), W and b standard normal.

    A Bayesian linear head over learned features alone is equally certain everywhere: every
    step adds precision to the few directions the features share (docs/design.md, "Why deep sea
    N = 20 is not found"). Over these features two observations far apart have directions of
    their own, so the posterior stays wide where the run has not been and narrows where it has:
    uncertainty about states, as the random prior functions of Osband et al. (2018) give an
    ensemble (docs/design.md, "Why a fixed random layer runs out at depth")."""

    rf_weight: torch.Tensor
    rf_bias: torch.Tensor

    def __init__(self, torso: MLPTorso, obs_dim: int, width: int) -> None:
        super().__init__()
        self.torso = torso
        self.width = width
        self.register_buffer("rf_weight", torch.randn(width, obs_dim))
        self.register_buffer("rf_bias", torch.randn(width))
        self.out_dim = torso.out_dim + width

    def prepare(self, obs_BO: torch.Tensor) -> torch.Tensor:
        return self.torso.prepare(obs_BO)

    def random_features(self, x: torch.Tensor) -> torch.Tensor:
        """psi(s) of prepared observations, (B, width). In place: nothing in it is trained."""
        return random_feature_map(_linear(x, self.rf_weight, self.rf_bias), self.width)

    def body(self, x: torch.Tensor, psi: torch.Tensor | None = None) -> torch.Tensor:
        """[learned features, psi(s)]; ``psi`` when already computed (by a torso of the same
        random layer: an online torso and its target share it)."""
        psi = self.random_features(x) if psi is None else psi
        return torch.cat([self.torso.body(x), psi], dim=1)


class NatureCNN(Torso):
    """Mnih et al. (2015) torso of appendix 9.1.1: 32x8s4, 64x4s2, 64x3s1, then 512 units."""

    def __init__(self, in_channels: int, screen: int = 84) -> None:
        super().__init__()
        self.conv = nn.Sequential(
            nn.Conv2d(in_channels, 32, 8, stride=4),
            nn.ReLU(),
            nn.Conv2d(32, 64, 4, stride=2),
            nn.ReLU(),
            nn.Conv2d(64, 64, 3, stride=1),
            nn.ReLU(),
            nn.Flatten(),
        )
        with torch.no_grad():
            n_flat = self.conv(torch.zeros(1, in_channels, screen, screen)).shape[1]
        for layer in self.conv:  # NHWC weights (Module.to(memory_format=...) does the same)
            if isinstance(layer, nn.Conv2d):
                layer.weight.data = layer.weight.data.contiguous(memory_format=torch.channels_last)
        self.fc = nn.Sequential(nn.Linear(n_flat, 512), nn.ReLU())
        self.n_flat = int(n_flat)  # width of the convolutions' output (3136 on 84x84 frames)
        self.out_dim = 512

    def prepare(self, obs_BCHW: torch.Tensor) -> torch.Tensor:
        # uint8 frames are scaled here, so the replay and the acting path keep bytes.
        return _channels_last(obs_BCHW.float() / 255.0)

    def body(self, x: torch.Tensor) -> torch.Tensor:
        return self.fc(self.conv(x))


MINATAR_SCREEN = 10
"""Side of MinAtar's observations: images of this side get the MinAtar CNN."""


class MinAtarCNN(Torso):
    """Young & Tian (2019) MinAtar torso: 16 3x3 filters, stride 1 (10x10 -> 8x8), then 128 units.
    Its input is 0/1 object planes (uint8 or bool), cast to float without scaling."""

    HIDDEN = 128

    def __init__(self, in_channels: int, screen: int = MINATAR_SCREEN) -> None:
        super().__init__()
        self.conv = nn.Sequential(nn.Conv2d(in_channels, 16, 3, stride=1), nn.ReLU(), nn.Flatten())
        self.n_flat = 16 * (screen - 2) * (screen - 2)  # 1024 on 10x10 planes
        self.fc = nn.Sequential(nn.Linear(self.n_flat, self.HIDDEN), nn.ReLU())
        self.out_dim = self.HIDDEN

    def prepare(self, obs_BCHW: torch.Tensor) -> torch.Tensor:
        return obs_BCHW.float()

    def body(self, x: torch.Tensor) -> torch.Tensor:
        return self.fc(self.conv(x))


def is_minatar_shape(shape: tuple[int, ...]) -> bool:
    """A (C, 10, 10) image: MinAtar's channels-first object planes."""
    return len(shape) == 3 and shape[1] == shape[2] == MINATAR_SCREEN


def make_torso(
    obs_space: gym.spaces.Box, hidden_sizes: tuple[int, ...]
) -> MLPTorso | NatureCNN | MinAtarCNN:
    """Images (C, 10, 10) get the MinAtar CNN, other images (C, H, W) the Nature CNN; flat
    vectors get the MLP."""
    shape = obs_space.shape
    assert shape is not None
    if is_minatar_shape(shape):
        return MinAtarCNN(shape[0], shape[1])
    if len(shape) == 3:
        return NatureCNN(shape[0], shape[1])
    return MLPTorso(int(np.prod(shape)), hidden_sizes)


class QNetwork(nn.Module):
    """Q(s, .) = W phi_theta(s) + b: a torso and a linear head (DDQN, k-DDQN)."""

    def __init__(self, obs_space: gym.spaces.Box, num_actions: int, hidden_sizes: tuple[int, ...]):
        super().__init__()
        self.torso = make_torso(obs_space, hidden_sizes)
        self.head = nn.Linear(self.torso.out_dim, num_actions)

    def prepare(self, obs: torch.Tensor) -> torch.Tensor:
        return self.torso.prepare(obs)

    def forward(self, obs: torch.Tensor, prepared: bool = False) -> torch.Tensor:
        return self.head(self.torso(obs, prepared))


def online_and_target(
    online: Torso | QNetwork, target: Torso | QNetwork, obs: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """``online(obs), target(obs)`` of two networks of one architecture, with the observations
    scaled and laid out once (the double-Q target's two forwards over s')."""
    x = online.prepare(obs)
    if (
        isinstance(online, RandomFeatureTorso)
        and isinstance(target, RandomFeatureTorso)
        and online.precision == target.precision == "fp32"
    ):
        # The random layer is the same in both (buffers never trained, copied with the target):
        # psi(s') once, the same numbers as two forwards (tests/agents/test_random_features.py).
        psi = online.random_features(x)
        return online.body(x, psi), target.body(x, psi)
    return online(x, prepared=True), target(x, prepared=True)


class NatureConvTrunk(Torso):
    """The Nature CNN without its 512-unit layer: conv layers and flatten, ``out_dim`` = n_flat
    (3136 on 84x84 frames), for networks whose heads each own that layer (OB2I)."""

    def __init__(self, in_channels: int, screen: int = 84) -> None:
        super().__init__()
        cnn = NatureCNN(in_channels, screen)
        self.conv = cnn.conv  # NatureCNN's layers, so the two stay identical; its fc is dropped
        self.out_dim = cnn.n_flat

    def prepare(self, obs_BCHW: torch.Tensor) -> torch.Tensor:
        return _channels_last(obs_BCHW.float() / 255.0)

    def body(self, x: torch.Tensor) -> torch.Tensor:
        return self.conv(x)


class MinAtarConvTrunk(Torso):
    """The MinAtar CNN without its 128-unit layer: conv layer and flatten, ``out_dim`` = 1024 on
    10x10 planes, for networks whose heads each own that layer (OB2I)."""

    def __init__(self, in_channels: int, screen: int = MINATAR_SCREEN) -> None:
        super().__init__()
        cnn = MinAtarCNN(in_channels, screen)
        self.conv = cnn.conv  # MinAtarCNN's layers, so the two stay identical; its fc is dropped
        self.out_dim = cnn.n_flat

    def prepare(self, obs_BCHW: torch.Tensor) -> torch.Tensor:
        return obs_BCHW.float()

    def body(self, x: torch.Tensor) -> torch.Tensor:
        return self.conv(x)


def make_trunk(
    obs_space: gym.spaces.Box, hidden_sizes: tuple[int, ...]
) -> tuple[MLPTorso | NatureConvTrunk | MinAtarConvTrunk, int]:
    """``make_torso`` without its last hidden layer, and that layer's width (512 for Atari
    images, 128 for MinAtar planes), for heads that each get their own copy of it. A one-layer
    MLP leaves the flattened observation."""
    shape = obs_space.shape
    assert shape is not None
    if is_minatar_shape(shape):
        return MinAtarConvTrunk(shape[0], shape[1]), MinAtarCNN.HIDDEN
    if len(shape) == 3:
        return NatureConvTrunk(shape[0], shape[1]), 512
    if not hidden_sizes:
        raise ValueError("per-head hidden layers need hidden_sizes with at least one layer")
    return MLPTorso(int(np.prod(shape)), hidden_sizes[:-1]), hidden_sizes[-1]


class EnsembleHeads(nn.Module):
    """K heads Linear(d, h) + ReLU + Linear(h, A) computed together: (B, d) -> Q (B, K, A).

    Head k's layers are ``hidden_weight[k]``, ``hidden_bias[k]`` and ``out_weight[k]``,
    ``out_bias[k]``, laid out and initialised as K separate ``nn.Linear`` pairs would be.
    """

    def __init__(self, in_dim: int, hidden: int, num_actions: int, num_heads: int) -> None:
        super().__init__()
        self.hidden_weight = nn.Parameter(torch.empty(num_heads, hidden, in_dim))
        self.hidden_bias = nn.Parameter(torch.empty(num_heads, hidden))
        self.out_weight = nn.Parameter(torch.empty(num_heads, num_actions, hidden))
        self.out_bias = nn.Parameter(torch.empty(num_heads, num_actions))
        self.reset_parameters()

    @torch.no_grad()
    def reset_parameters(self) -> None:
        """nn.Linear's default init, head by head in the order K Sequential(Linear, ReLU, Linear)
        would draw it, so a seed gives the same weights as separate layers."""
        for k in range(self.hidden_weight.shape[0]):
            for w, b in (
                (self.hidden_weight[k], self.hidden_bias[k]),
                (self.out_weight[k], self.out_bias[k]),
            ):
                nn.init.kaiming_uniform_(w, a=math.sqrt(5))
                bound = 1.0 / math.sqrt(w.shape[1])  # fan_in
                nn.init.uniform_(b, -bound, bound)

    def forward(self, x_BD: torch.Tensor) -> torch.Tensor:
        num_heads, hidden, _ = self.hidden_weight.shape
        # One matmul for all K hidden layers, then one batched matmul for the K output layers.
        w1, b1 = self.hidden_weight.flatten(0, 1), self.hidden_bias.flatten()  # (K*H, D), (K*H,)
        h_BKH = torch.relu(nn.functional.linear(x_BD, w1, b1)).view(-1, num_heads, hidden)
        return torch.einsum("bkh,kah->bka", h_BKH, self.out_weight) + self.out_bias


class EnsembleQNetwork(nn.Module):
    """Shared trunk and K heads (bootstrapped DQN's network; OB2I's, farsighter.agents.ob2i):
    forward gives Q (B, K, A)."""

    def __init__(
        self,
        obs_space: gym.spaces.Box,
        num_actions: int,
        num_heads: int,
        hidden_sizes: tuple[int, ...],
        separate_heads: bool = True,
    ) -> None:
        super().__init__()
        self.torso: nn.Module
        self.heads: nn.Module
        if separate_heads:  # authors' network: every head owns the last hidden layer
            trunk, hidden = make_trunk(obs_space, hidden_sizes)
            self.torso = trunk
            self.heads = EnsembleHeads(trunk.out_dim, hidden, num_actions, num_heads)
        else:
            self.torso = make_torso(obs_space, hidden_sizes)
            # One Linear with K*A rows initialises each head exactly as K separate Linear(d, A).
            self.heads = nn.Linear(self.torso.out_dim, num_heads * num_actions)
        self.num_heads, self.num_actions = num_heads, num_actions

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.heads(self.torso(obs)).view(-1, self.num_heads, self.num_actions)


class NAFNetwork(nn.Module):
    """NAF's network (Eq. 4; farsighter.agents.naf): phi (MLP), V and L heads (NAFHead) and the
    mu-layer (linear, or Bayesian for bnaf and farsighter-naf)."""

    def __init__(
        self,
        obs_dim: int,
        low_A: np.ndarray,
        high_A: np.ndarray,
        hidden_sizes: tuple[int, ...],
        *,
        bayesian: bool,
        prior_std: float = 0.1,
        init_sigma: float = 0.05,
    ) -> None:
        super().__init__()
        action_dim = len(low_A)
        self.torso = MLPTorso(obs_dim, hidden_sizes)
        d = self.torso.out_dim
        self.head = NAFHead(d, action_dim)
        self.mu_layer: nn.Linear | BayesianLinear = (
            BayesianLinear(d, action_dim, prior_std=prior_std, init_sigma=init_sigma)
            if bayesian
            else nn.Linear(d, action_dim)
        )
        self.low_A: torch.Tensor
        self.high_A: torch.Tensor
        self.register_buffer("low_A", torch.as_tensor(low_A, dtype=torch.float32))
        self.register_buffer("high_A", torch.as_tensor(high_A, dtype=torch.float32))

    def mu_from_out(self, out_BA: torch.Tensor) -> torch.Tensor:
        """The action mu from the mu-layer's output: tanh, then affine to the bounds."""
        return scale_action(torch.tanh(out_BA), self.low_A, self.high_A)

    def mu_out_mean(self, phi_BD: torch.Tensor, detach_weights: bool = False) -> torch.Tensor:
        """mu-layer output with the (posterior-mean) weights; ``detach_weights`` keeps theta^a
        out of the gradient while phi still receives it (section 4.3: theta^a fixed)."""
        layer = self.mu_layer
        w: torch.Tensor
        b: torch.Tensor | None
        if isinstance(layer, BayesianLinear):
            w, b = layer.weight_mu, layer.bias_mu
        else:
            w, b = layer.weight, layer.bias
        if detach_weights:
            w, b = w.detach(), None if b is None else b.detach()
        return F.linear(phi_BD, w, b)

    def value(self, obs_BO: torch.Tensor) -> torch.Tensor:
        """V(s) = max_a Q(s, a)."""
        return self.head.v(self.torso(obs_BO)).squeeze(-1)

    def q(
        self, obs_BO: torch.Tensor, action_BA: torch.Tensor, freeze_mu: bool
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Q(s, a) of Eq. 4 with mu at the posterior mean, and the mu-layer's pre-tanh output."""
        phi_BD = self.torso(obs_BO)
        v_B, l_BAA = self.head(phi_BD)
        out_BA = self.mu_out_mean(phi_BD, detach_weights=freeze_mu)
        return naf_q(v_B, self.mu_from_out(out_BA), l_BAA, action_BA), out_BA


class RNDNetwork(nn.Module):
    """RND's networks (farsighter.exploration.rnd): a torso (MLP or Nature CNN) and
    ``extra_layers`` hidden layers, then ``feature_dim`` outputs."""

    def __init__(
        self,
        obs_space: gym.spaces.Box,
        hidden_sizes: tuple[int, ...],
        feature_dim: int,
        extra_layers: int,
    ) -> None:
        super().__init__()
        self.torso = make_torso(obs_space, hidden_sizes)
        d = self.torso.out_dim
        layers: list[nn.Module] = []
        for _ in range(extra_layers):
            layers += [nn.Linear(d, d), nn.ReLU()]
        self.head = nn.Sequential(*layers, nn.Linear(d, feature_dim))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.torso(x))
