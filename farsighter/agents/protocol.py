"""The contract between the training loop and every agent, checked by mypy.

The loop drives :class:`SeedAgents`: S seeds of one config (S = 1 for a run alone) that act,
record steps and learn together. One seed of them is an :class:`Agent`, the surface the run log,
evaluation, callbacks, checkpoints and a loaded policy use. An agent class that trains one seed
is a :class:`LearningAgent` (an Agent that also records steps and learns); each such module ends
with ``AGENT: AgentFactory = ItsClass``, and an agent written over the seed axis with
``SEED_AGENTS: SeedAgentsFactory = ItsClass``; mypy checks the class's constructor against the
factory and its instances against the protocol. Arrays carry their shape in a
suffix: S seeds, E environments, B rows, A actions.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

import gymnasium as gym
import numpy as np
import torch

from farsighter.config import Config
from farsighter.replay import VectorStep


class Agent(Protocol):
    """One seed: what the run log, evaluation, callbacks and the studies use of an agent."""

    def act(self, obs_E: np.ndarray, global_step: int, explore: bool = True) -> np.ndarray:
        """Actions for a batch of environments; ``explore=False`` is the evaluation policy
        (greedy, or greedy under the posterior mean)."""
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


class LearningAgent(Agent, Protocol):
    """An agent of one seed that trains: it also records steps and learns."""

    def observe(self, step: VectorStep) -> None:
        """Record one step of every environment."""
        ...

    def learn(self, global_step: int) -> dict[str, torch.Tensor]:
        """Make the updates owed at ``global_step`` (the agent keeps its own cadences); returns
        the latest losses as tensors (the loop reads them once per log interval)."""
        ...


class SeedAgents(Protocol):
    """S seeds of one config as the training loop drives them (:func:`farsighter.train.train`,
    :func:`farsighter.seeds.train_seeds`)."""

    @property
    def seeds(self) -> int: ...

    def act(self, obs_S: Sequence[np.ndarray], global_step: int) -> np.ndarray:
        """Each seed's exploring actions for its own environments' observations, (S, E)."""
        ...

    def observe(self, steps: Sequence[VectorStep]) -> None:
        """One vector step of every seed, in seed order."""
        ...

    def learn(self, global_step: int) -> list[dict[str, torch.Tensor]]:
        """The updates owed at ``global_step``; each seed's latest losses."""
        ...

    def member(self, s: int) -> Agent:
        """Seed ``s`` as an agent (its checkpoint is the one its run alone writes)."""
        ...


class Each:
    """S :class:`LearningAgent` s, one per seed, as :class:`SeedAgents`: how a run alone of an
    agent without a seed-axis form is trained, and the generic form for seeds that cannot share
    one computation (OB2I, NAF, image observations, bf16, compile, CUDA graphs, adaptive k):
    the loop steps them together, each agent acting and learning on its own."""

    def __init__(self, agents: Sequence[LearningAgent]) -> None:
        self.agents = list(agents)

    @property
    def seeds(self) -> int:
        return len(self.agents)

    def act(self, obs_S: Sequence[np.ndarray], global_step: int) -> np.ndarray:
        return np.stack(
            [agent.act(obs_E, global_step) for agent, obs_E in zip(self.agents, obs_S, strict=True)]
        )

    def observe(self, steps: Sequence[VectorStep]) -> None:
        for agent, step in zip(self.agents, steps, strict=True):
            agent.observe(step)

    def learn(self, global_step: int) -> list[dict[str, torch.Tensor]]:
        return [agent.learn(global_step) for agent in self.agents]

    def member(self, s: int) -> LearningAgent:
        return self.agents[s]


class Sole:
    """One seed of an agent written over the seed axis (:class:`SeedAgents` of one seed) as a
    :class:`LearningAgent`: what :func:`farsighter.agents.build_agent` gives for one config (a
    loaded policy, a probe). ``agents``: the seed-axis agent itself."""

    def __init__(self, agents: SeedAgents) -> None:
        self.agents = agents
        self.seed = agents.member(0)

    def act(self, obs_E: np.ndarray, global_step: int, explore: bool = True) -> np.ndarray:
        if not explore:
            return self.seed.act(obs_E, global_step, explore=False)
        return self.agents.act([obs_E], global_step)[0]

    def observe(self, step: VectorStep) -> None:
        self.agents.observe([step])

    def learn(self, global_step: int) -> dict[str, torch.Tensor]:
        return self.agents.learn(global_step)[0]

    def diagnostics(self) -> dict[str, float]:
        return self.seed.diagnostics()

    def episode_diagnostics(self) -> dict[str, float]:
        """The seed's ``episode_diagnostics()`` where it has one, else its diagnostics."""
        cheap = getattr(self.seed, "episode_diagnostics", None)
        return cheap() if callable(cheap) else self.seed.diagnostics()

    def q_estimate(self, obs_B: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        return self.seed.q_estimate(obs_B)

    def state_dict(self, include_replay: bool = True) -> dict[str, Any]:
        return self.seed.state_dict(include_replay)

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.seed.load_state_dict(state)


class SeedAgentsFactory(Protocol):
    """An agent class written over the seed axis: S configs that differ only in seed."""

    def __call__(
        self,
        cfgs: Sequence[Config],
        obs_space: gym.spaces.Box,
        act_space: Any,
        *,
        frame_stack: int,
        device: torch.device,
    ) -> SeedAgents: ...


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
    ) -> LearningAgent: ...
