"""The contract between the training loop and every agent, checked by mypy.

Each agent module ends with ``AGENT: AgentFactory = ItsClass``; mypy then checks the class's
constructor against :class:`AgentFactory` and its instances against :class:`Agent`. Arrays
carry their shape in a suffix: E environments, B rows, A actions.
"""

from __future__ import annotations

from typing import Any, Protocol

import gymnasium as gym
import numpy as np
import torch

from farsighter.config import Config
from farsighter.replay import VectorStep


class Agent(Protocol):
    """What the loop, evaluation and the studies use of an agent."""

    def act(self, obs_E: np.ndarray, global_step: int, explore: bool = True) -> np.ndarray:
        """Actions for a batch of environments; ``explore=False`` is the evaluation policy
        (greedy, or greedy under the posterior mean)."""
        ...

    def observe(self, step: VectorStep) -> None:
        """Record one step of every environment."""
        ...

    def learn(self, global_step: int) -> dict[str, torch.Tensor]:
        """Make the updates owed at ``global_step`` (the agent keeps its own cadences); returns
        the latest losses as tensors (the loop reads them once per log interval)."""
        ...

    def diagnostics(self) -> dict[str, float]:
        """Scalars worth logging (epsilon, k, posterior variance, ...). An agent may also have
        ``episode_diagnostics()``, the part of them an episode's metrics row reads (epsilon,
        k) when the rest costs work (:func:`farsighter.session.episode_diagnostics`)."""
        ...

    def q_estimate(self, obs_B: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Q(s, .) for a batch of states, and its variance where the agent has a posterior."""
        ...

    def state_dict(self, include_replay: bool = True) -> dict[str, Any]:
        """Everything needed to continue training (the replay only when asked)."""
        ...

    def load_state_dict(self, state: dict[str, Any]) -> None: ...


class AgentFactory(Protocol):
    """An agent class: how :func:`farsighter.agents.build_agent` constructs every agent."""

    def __call__(
        self,
        cfg: Config,
        obs_space: gym.spaces.Box,
        act_space: Any,
        *,
        frame_stack: int,
        device: torch.device,
    ) -> Agent: ...
