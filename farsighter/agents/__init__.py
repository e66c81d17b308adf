"""Agents: one readable file each, composed from shared pieces; built by name.

Every agent satisfies :class:`farsighter.agents.protocol.Agent`, the surface the training loop
drives. Which module trains which algorithm is in :mod:`farsighter.algorithms`.
"""

from __future__ import annotations

import importlib
from collections.abc import Sequence

import gymnasium as gym
import torch

from farsighter import algorithms
from farsighter.agents.protocol import Agent, AgentFactory, Alone, LearningAgent, SeedAgents
from farsighter.config import Config
from farsighter.networks import set_precision

__all__ = [
    "Agent",
    "AgentFactory",
    "Alone",
    "LearningAgent",
    "SeedAgents",
    "build_agent",
    "build_seed_agents",
]


def build_agent(
    cfg: Config,
    obs_space: gym.Space,
    act_space: gym.Space,
    *,
    frame_stack: int,
    device: torch.device,
) -> LearningAgent:
    """The agent of ``cfg.algo`` (its module of the algorithm table is imported on first use)."""
    spec = algorithms.get(cfg.algo)
    if not isinstance(obs_space, gym.spaces.Box):  # farsighter.envs.check_spaces says why
        raise TypeError(f"{cfg.algo} needs a Box observation space, got {obs_space}")
    factory: AgentFactory = importlib.import_module(f"farsighter.agents.{spec.agent}").AGENT
    agent = factory(cfg, obs_space, act_space, frame_stack=frame_stack, device=device)
    for net in networks(agent):
        set_precision(net, cfg.runtime.precision)
    return agent


def build_seed_agents(
    cfgs: Sequence[Config],
    obs_space: gym.Space,
    act_space: gym.Space,
    *,
    frame_stack: int,
    device: torch.device,
) -> SeedAgents:
    """The seeds of ``cfgs`` (one config but for seed and run directory) as the loop drives
    them: one agent alone (:class:`Alone`) for one config, else the algorithm's seed-batched
    form (``Algorithm.seed_batch``; :func:`farsighter.seeds.train_seeds` checks it applies)."""
    if len(cfgs) == 1:
        return Alone(
            build_agent(cfgs[0], obs_space, act_space, frame_stack=frame_stack, device=device)
        )
    module = algorithms.get(cfgs[0].algo).seed_batch
    if not module:
        raise ValueError(f"{cfgs[0].algo} has no seed-batched form")
    batch = importlib.import_module(f"farsighter.agents.{module}").SeedBatch
    return batch(cfgs, obs_space, act_space, device=device)  # type: ignore[no-any-return]


def networks(agent: object) -> list[torch.nn.Module]:
    """Every network an agent holds: its own attributes, and those of the objects it holds (its
    loss owns the target networks)."""
    found: list[torch.nn.Module] = []
    for value in vars(agent).values():
        inner = [] if isinstance(value, torch.nn.Module) else getattr(value, "__dict__", {})
        for net in [value, *(inner.values() if isinstance(inner, dict) else [])]:
            if isinstance(net, torch.nn.Module) and all(net is not f for f in found):
                found.append(net)
    return found
