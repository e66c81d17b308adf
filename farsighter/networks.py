"""Representation networks phi_theta(s): an MLP for flat observations, the Nature CNN for images."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import torch
from torch import nn


class MLPTorso(nn.Module):
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

    def forward(self, obs_BO: torch.Tensor) -> torch.Tensor:
        return self.net(obs_BO.float().flatten(1))


class NatureCNN(nn.Module):
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
        self.fc = nn.Sequential(nn.Linear(n_flat, 512), nn.ReLU())
        self.n_flat = int(n_flat)  # width of the convolutions' output (3136 on 84x84 frames)
        self.out_dim = 512

    def forward(self, obs_BCHW: torch.Tensor) -> torch.Tensor:
        # uint8 frames are scaled here, so the replay and the acting path keep bytes.
        return self.fc(self.conv(obs_BCHW.float() / 255.0))


def make_torso(obs_space: gym.spaces.Box, hidden_sizes: tuple[int, ...]) -> MLPTorso | NatureCNN:
    """Images (C, H, W) get the Nature CNN; flat vectors get the MLP."""
    shape = obs_space.shape
    assert shape is not None
    if len(shape) == 3:
        return NatureCNN(shape[0], shape[1])
    return MLPTorso(int(np.prod(shape)), hidden_sizes)


class QNetwork(nn.Module):
    """Q(s, .) = W phi_theta(s) + b: a torso and a linear head (DDQN, k-DDQN)."""

    def __init__(self, obs_space: gym.spaces.Box, num_actions: int, hidden_sizes: tuple[int, ...]):
        super().__init__()
        self.torso = make_torso(obs_space, hidden_sizes)
        self.head = nn.Linear(self.torso.out_dim, num_actions)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.head(self.torso(obs))


class NatureConvTrunk(nn.Module):
    """The Nature CNN without its 512-unit layer: conv layers and flatten, ``out_dim`` = n_flat
    (3136 on 84x84 frames), for networks whose heads each own that layer (OB2I)."""

    def __init__(self, in_channels: int, screen: int = 84) -> None:
        super().__init__()
        cnn = NatureCNN(in_channels, screen)
        self.conv = cnn.conv  # NatureCNN's layers, so the two stay identical; its fc is dropped
        self.out_dim = cnn.n_flat

    def forward(self, obs_BCHW: torch.Tensor) -> torch.Tensor:
        return self.conv(obs_BCHW.float() / 255.0)


def make_trunk(
    obs_space: gym.spaces.Box, hidden_sizes: tuple[int, ...]
) -> tuple[MLPTorso | NatureConvTrunk, int]:
    """``make_torso`` without its last hidden layer, and that layer's width (512 for images), for
    heads that each get their own copy of it. A one-layer MLP leaves the flattened observation."""
    shape = obs_space.shape
    assert shape is not None
    if len(shape) == 3:
        return NatureConvTrunk(shape[0], shape[1]), 512
    if not hidden_sizes:
        raise ValueError("per-head hidden layers need hidden_sizes with at least one layer")
    return MLPTorso(int(np.prod(shape)), hidden_sizes[:-1]), hidden_sizes[-1]
