"""DDQN (paper section 3.2) and k-DDQN (section 5.2 baselines): epsilon-greedy exploration,
double-Q targets with one-step (k = 1) or k-step returns formed by the replay at sample time."""

from __future__ import annotations

import copy
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from farsighter.agents.common import (
    UpdateClock,
    batch_tensors,
    build_seeded,
    clip_and_step,
    epsilon_greedy,
    linear_schedule,
    make_optimizer,
    make_replay,
    obs_tensor,
    sample_minibatch,
    td_loss,
)
from farsighter.config import Config
from farsighter.networks import QNetwork
from farsighter.ops.targets import double_q_target


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
        self.q_target = copy.deepcopy(self.q)
        self.q_target.requires_grad_(False)
        self.opt = make_optimizer(self.q.parameters(), cfg)
        self.replay = make_replay(cfg, obs_space, frame_stack, seed=cfg.seed + 1)
        self.rng = np.random.default_rng(cfg.seed + 2)
        self.clock = UpdateClock(cfg)  # updates made; refill hold after resume
        self.target_syncs = 0
        self.epsilon = cfg.eps_start

    # ------------------------------------------------------------------ acting
    def act(self, obs_E: np.ndarray, global_step: int, explore: bool = True) -> np.ndarray:
        """Epsilon-greedy actions for a batch of environments (greedy when not exploring)."""
        if not explore:
            return self.greedy(obs_E)
        cfg = self.cfg
        self.epsilon = linear_schedule(cfg.eps_start, cfg.eps_end, cfg.eps_decay_steps, global_step)
        return epsilon_greedy(
            self.rng, self.epsilon, self.num_actions, lambda: self.greedy(obs_E), obs_E.shape[0]
        )

    @torch.no_grad()
    def greedy(self, obs_E: np.ndarray) -> np.ndarray:
        q_EA = self.q(obs_tensor(obs_E, self.device))
        return q_EA.argmax(dim=1).cpu().numpy()

    @torch.no_grad()
    def q_estimate(self, obs_B: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Q(s, .) for a batch of states; DDQN has no posterior, so no variance."""
        return self.q(obs_tensor(obs_B, self.device)).cpu().numpy(), None

    def observe(
        self,
        obs_E: np.ndarray,
        action_E: np.ndarray,
        reward_E: np.ndarray,
        terminated_E: np.ndarray,
        truncated_E: np.ndarray,
        final_obs_E: Any,
    ) -> None:
        self.replay.add(obs_E, action_E, reward_E, terminated_E, truncated_E, final_obs_E)

    # ------------------------------------------------------------------ learning
    def learn(self, global_step: int) -> dict[str, torch.Tensor]:
        metrics: dict[str, torch.Tensor] = {}
        for _ in range(self.clock.due(global_step)):
            metrics["td_loss"] = self.update()
        syncs = global_step // self.cfg.target_update_every
        if syncs > self.target_syncs:
            self.q_target.load_state_dict(self.q.state_dict())
            self.target_syncs = syncs
        return metrics

    def update(self) -> torch.Tensor:
        """One gradient step on the double-Q loss of a k-step minibatch; returns the loss."""
        cfg = self.cfg
        batch = sample_minibatch(self.replay, cfg, cfg.batch_size, cfg.k)
        t = batch_tensors(batch, self.device)
        q_B = self.q(t["obs"]).gather(1, t["actions"].unsqueeze(1)).squeeze(1)
        y_B = self.targets(t)
        loss = td_loss(q_B, y_B, self.cfg.loss)
        clip_and_step(loss, list(self.q.parameters()), self.opt, cfg.max_grad_norm)
        return loss.detach()

    @torch.no_grad()
    def targets(self, t: dict[str, torch.Tensor]) -> torch.Tensor:
        """Double-Q target (Eq. 2 with k-step returns): the online network picks the argmax at
        s_{t+n}, the target network evaluates it."""
        return double_q_target(
            t["returns"], t["bootstrap"], self.q(t["next_obs"]), self.q_target(t["next_obs"])
        )

    def diagnostics(self) -> dict[str, float]:
        return {"epsilon": self.epsilon, "k": float(self.cfg.k)}

    # ------------------------------------------------------------------ checkpoints
    def state_dict(self, include_replay: bool = True) -> dict[str, Any]:
        return {
            "q": self.q.state_dict(),
            "q_target": self.q_target.state_dict(),
            "opt": self.opt.state_dict(),
            "rng": self.rng.bit_generator.state,
            "counters": {"updates": self.clock.state_dict(), "target_syncs": self.target_syncs},
            "replay": self.replay.state_dict() if include_replay else None,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.q.load_state_dict(state["q"])
        self.q_target.load_state_dict(state["q_target"])
        self.opt.load_state_dict(state["opt"])
        self.rng.bit_generator.state = state["rng"]
        self.clock.load_state_dict(state["counters"]["updates"])
        self.target_syncs = state["counters"]["target_syncs"]
        if state.get("replay") is not None:
            self.replay.load_state_dict(state["replay"])
        else:  # saved without its replay: refill before updating again
            self.clock.hold()

    def load_policy(self, state: dict[str, Any]) -> None:
        """Weights only (for acting from a finished run)."""
        self.q.load_state_dict(state["q"])
