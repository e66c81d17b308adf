"""Agents: one readable file each, composed from shared pieces; built by name.

Every agent offers the same small surface the training loop drives:

* ``act(obs_E, global_step, explore=True) -> actions_E`` (batched over environments)
* ``observe(obs_E, action_E, reward_E, terminated_E, truncated_E, final_obs_E)``
* ``learn(global_step) -> dict[str, Tensor]`` (the agent keeps its own update cadences)
* ``diagnostics() -> dict[str, float]`` (epsilon, k, posterior variance, ...)
* ``state_dict(include_replay)`` / ``load_state_dict(state)``
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import torch

from farsighter.config import Config, unknown_algo_message
from farsighter.errors import ConfigError


def build_agent(
    cfg: Config,
    obs_space: gym.Space,
    act_space: gym.Space,
    *,
    frame_stack: int,
    device: torch.device,
) -> Any:
    """The agent named by ``cfg.algo``."""
    if cfg.algo in ("ddqn", "kddqn"):
        from farsighter.agents.ddqn import DDQNAgent

        return DDQNAgent(cfg, obs_space, act_space, frame_stack=frame_stack, device=device)  # type: ignore[arg-type]
    if cfg.algo in ("bdqn", "farsighter"):
        from farsighter.agents.farsighter import FarsighterAgent

        return FarsighterAgent(cfg, obs_space, act_space, frame_stack=frame_stack, device=device)  # type: ignore[arg-type]
    if cfg.algo == "ob2i":
        from farsighter.agents.ob2i import OB2IAgent

        return OB2IAgent(cfg, obs_space, act_space, frame_stack=frame_stack, device=device)  # type: ignore[arg-type]
    if cfg.algo in ("rnd", "krnd"):
        from farsighter.agents.rnd import RNDAgent

        return RNDAgent(cfg, obs_space, act_space, frame_stack=frame_stack, device=device)  # type: ignore[arg-type]
    if cfg.algo in ("naf", "knaf", "bnaf", "farsighter-naf"):
        from farsighter.agents.naf import NAFAgent

        return NAFAgent(cfg, obs_space, act_space, frame_stack=frame_stack, device=device)  # type: ignore[arg-type]
    raise ConfigError(unknown_algo_message(cfg.algo))
