"""Agents: one readable file each, composed from shared pieces; built by name.

Every agent satisfies :class:`farsighter.agents.protocol.Agent`, the surface the training loop
drives. Which module trains which algorithm is in :mod:`farsighter.algorithms`.
"""

from __future__ import annotations

import importlib

import gymnasium as gym
import torch

from farsighter import algorithms
from farsighter.agents.protocol import Agent, AgentFactory
from farsighter.config import Config
from farsighter.networks import set_precision

__all__ = ["Agent", "AgentFactory", "build_agent"]


def build_agent(
    cfg: Config,
    obs_space: gym.Space,
    act_space: gym.Space,
    *,
    frame_stack: int,
    device: torch.device,
) -> Agent:
    """The agent of ``cfg.algo`` (its module of the algorithm table is imported on first use)."""
    spec = algorithms.get(cfg.algo)
    if not isinstance(obs_space, gym.spaces.Box):  # farsighter.envs.check_spaces says why
        raise TypeError(f"{cfg.algo} needs a Box observation space, got {obs_space}")
    factory: AgentFactory = importlib.import_module(f"farsighter.agents.{spec.agent}").AGENT
    agent = factory(cfg, obs_space, act_space, frame_stack=frame_stack, device=device)
    for value in vars(agent).values():  # every network the agent holds, targets included
        if isinstance(value, torch.nn.Module):
            set_precision(value, cfg.precision)
    return agent
