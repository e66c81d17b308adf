"""Agents: one readable file each, composed from shared pieces; built by name.

Every agent satisfies :class:`farsighter.agents.protocol.Agent`, the surface the training loop
drives. Which module trains which algorithm is in :mod:`farsighter.algorithms`.
"""

from __future__ import annotations

import importlib
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import torch

from farsighter import algorithms
from farsighter.agents.protocol import (
    Agent,
    AgentFactory,
    Each,
    LearningAgent,
    SeedAgents,
    SeedAgentsFactory,
    Sole,
)
from farsighter.config import Config
from farsighter.networks import set_precision

__all__ = [
    "Agent",
    "AgentFactory",
    "Each",
    "LearningAgent",
    "SeedAgents",
    "build_agent",
    "build_seed_agents",
    "loop_class",
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
    if not isinstance(obs_space, gym.spaces.Box):  # farsighter.envs.check_spaces says why
        raise TypeError(f"{cfg.algo} needs a Box observation space, got {obs_space}")
    module = _module(cfg.algo)
    if hasattr(module, "SEED_AGENTS"):  # written over the seed axis: its one seed
        agents = build_seed_agents(
            [cfg], obs_space, act_space, frame_stack=frame_stack, device=device
        )
        return Sole(agents)
    factory: AgentFactory = module.AGENT
    agent = factory(cfg, obs_space, act_space, frame_stack=frame_stack, device=device)
    for net in networks(agent):
        set_precision(net, cfg.runtime.precision)
    return agent


def loop_class(algo: str) -> type:
    """The class whose ``act``, ``observe`` and ``learn`` the training loop calls for a run of
    ``algo`` alone: its agent written over the seed axis (``SEED_AGENTS``), else its ``AGENT``
    (driven through :class:`Each`)."""
    module = _module(algo)
    return getattr(module, "SEED_AGENTS", None) or module.AGENT  # type: ignore[no-any-return]


def _module(algo: str) -> Any:
    """The module of ``farsighter.agents`` that trains ``algo`` (imported on first use)."""
    return importlib.import_module(f"farsighter.agents.{algorithms.get(algo).agent}")


def build_seed_agents(
    cfgs: Sequence[Config],
    obs_space: gym.Space,
    act_space: gym.Space,
    *,
    frame_stack: int,
    device: torch.device,
) -> SeedAgents:
    """The seeds of ``cfgs`` (one config but for seed and run directory) as the loop drives
    them: the agent written over the seed axis where its module has one (``SEED_AGENTS``) and
    its ``supports`` takes these seeds' settings; else one agent per seed, stepped together
    (:class:`Each`)."""
    spec = algorithms.get(cfgs[0].algo)
    if not isinstance(obs_space, gym.spaces.Box):  # farsighter.envs.check_spaces says why
        raise TypeError(f"{spec.name} needs a Box observation space, got {obs_space}")
    module = _module(spec.name)
    factory: SeedAgentsFactory | None = getattr(module, "SEED_AGENTS", None)
    if factory is None or (len(cfgs) > 1 and module.supports(cfgs[0], obs_space, device)):
        return Each(
            [
                build_agent(c, obs_space, act_space, frame_stack=frame_stack, device=device)
                for c in cfgs
            ]
        )
    agents = factory(cfgs, obs_space, act_space, frame_stack=frame_stack, device=device)
    for net in networks(agents):
        set_precision(net, cfgs[0].runtime.precision)
    return agents


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
