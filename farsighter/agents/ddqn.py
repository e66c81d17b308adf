"""DDQN (paper section 3.2) and k-DDQN (section 5.2 baselines): epsilon-greedy exploration,
double-Q targets with one-step (k = 1) or k-step returns formed by the replay at sample time."""

from __future__ import annotations

import copy
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from farsighter.agents.common import (
    Counters,
    TensorBatch,
    batch_tensors,
    build_seeded,
    greedy_actions,
    load_state,
    make_replay,
    obs_tensor,
    sample_minibatch,
    save_state,
    sync_target,
    td_loss,
    updates_owed,
)
from farsighter.agents.cuda_graph import Tensors
from farsighter.agents.learner import Learner
from farsighter.agents.protocol import AgentFactory
from farsighter.config import Config
from farsighter.exploration import EpsilonGreedy
from farsighter.networks import QNetwork, online_and_target
from farsighter.ops.targets import double_q_target
from farsighter.replay import VectorStep


class DoubleQLoss:
    """Eq. 3 on the double-Q target of Eq. 2 with k-step returns. The loss owns the target
    network, a copy of ``q`` made here and moved only by the hard copy (:func:`sync_target`)."""

    def __init__(self, q: QNetwork, kind: str) -> None:
        self.q = q
        self.q_target = copy.deepcopy(q).requires_grad_(False)
        self.kind = kind

    @torch.no_grad()
    def targets(self, t: TensorBatch) -> torch.Tensor:
        """y = R + gamma^n Q_target(s_{t+n}, argmax_a Q(s_{t+n}, a)), no bootstrap at a terminal."""
        q_next_online, q_next_target = online_and_target(self.q, self.q_target, t.next_obs_B)
        return double_q_target(t.returns_B, t.bootstrap_B, q_next_online, q_next_target)

    def __call__(self, inputs: Tensors) -> Tensors:
        t = TensorBatch.of(inputs)
        q_B = self.q(t.obs_B).gather(1, t.actions_B.unsqueeze(1)).squeeze(1)
        return {"loss": td_loss(q_B, self.targets(t), self.kind)}


class DDQNAgent:
    """Q(s, a) = W phi_theta(s); target network copied every N steps (Eq. 2-3)."""

    def __init__(
        self,
        cfg: Config,
        obs_space: gym.spaces.Box,
        act_space: gym.spaces.Discrete,
        *,
        frame_stack: int,
        device: torch.device,
    ) -> None:
        self.cfg = cfg
        self.device = device
        self.num_actions = int(act_space.n)
        self.q = build_seeded(
            cfg.seed, lambda: QNetwork(obs_space, self.num_actions, cfg.hidden_sizes)
        ).to(device)
        self.loss = DoubleQLoss(self.q, cfg.loss)
        self.learner = Learner(self.loss, self.q.parameters(), cfg, device)
        self.replay = make_replay(cfg, obs_space, frame_stack, seed=cfg.seed + 1, device=device)
        self.rng = np.random.default_rng(cfg.seed + 2)
        self.explore = EpsilonGreedy(cfg, self.num_actions, self.rng)
        self.counters = Counters(k=cfg.k)

    # ------------------------------------------------------------------ acting
    def act(self, obs_E: np.ndarray, global_step: int, explore: bool = True) -> np.ndarray:
        """Epsilon-greedy actions for a batch of environments (greedy when not exploring)."""
        if not explore:
            return self.greedy(obs_E)
        return self.explore(global_step, lambda: self.greedy(obs_E), obs_E.shape[0])

    def greedy(self, obs_E: np.ndarray) -> np.ndarray:
        return greedy_actions(self.q, obs_E, self.device)

    @torch.no_grad()
    def q_estimate(self, obs_B: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Q(s, .) for a batch of states; DDQN has no posterior, so no variance."""
        return self.q(obs_tensor(obs_B, self.device)).cpu().numpy(), None

    def observe(self, step: VectorStep) -> None:
        self.replay.add_step(step)

    # ------------------------------------------------------------------ learning
    def learn(self, global_step: int) -> dict[str, torch.Tensor]:
        metrics: dict[str, torch.Tensor] = {}
        for _ in range(updates_owed(self.counters, self.cfg, global_step)):
            metrics["td_loss"] = self.update()
        sync_target(
            self.counters, global_step, self.cfg.target_update_every, (self.q, self.loss.q_target)
        )
        return metrics

    def update(self) -> torch.Tensor:
        """One gradient step on the double-Q loss of a k-step minibatch; returns the loss."""
        cfg = self.cfg
        batch = sample_minibatch(self.replay, cfg, cfg.batch_size, self.counters.k)
        return self.learner(batch_tensors(batch, self.device).tensors())["loss"]

    def diagnostics(self) -> dict[str, float]:
        return {"epsilon": self.explore.epsilon, "k": float(self.counters.k)}

    # ------------------------------------------------------------------ checkpoints
    SAVED = ("q", "q_target", "opt", "rng", "counters")
    SAVED_AT = {"q_target": "loss.q_target", "opt": "learner"}  # keys of the earlier layout

    def state_dict(self, include_replay: bool = True) -> dict[str, Any]:
        return save_state(self, self.SAVED, include_replay)

    def load_state_dict(self, state: dict[str, Any]) -> None:
        load_state(self, self.SAVED, state)


AGENT: AgentFactory = DDQNAgent  # the class farsighter.algorithms names; mypy checks the protocol
