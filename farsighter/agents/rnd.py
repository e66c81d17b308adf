"""RND (Burda et al. 2018, "Exploration by random network distillation") on DDQN: ``rnd``
(1-step) and ``krnd`` (k-step returns), the RND and TD(K)+RND baselines of appendix 9.1.1.

* Acting: epsilon-greedy on Q, exactly as ddqn.py.
* The bonus: :class:`farsighter.exploration.rnd.RNDBonus` (the intrinsic reward, its
  normalisation, and the predictor's training).
* Targets (Eq. 2 with k-step returns): for a window starting at s_t with n <= k steps,
      R = sum_{j<n} gamma^j (r_{t+j} + lambda i(s_{t+j+1})),
      y = R + gamma^n Q_target(s_{t+n}, argmax_a Q(s_{t+n}, a))   (no bootstrap at a terminal).
  Our choice: the intrinsic rewards of the window's next states s_{t+1..t+n} are computed when the
  minibatch is sampled, with the current predictor, not stored at collection.
* The predictor takes one Adam step per update on the minibatch's observations s_t.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import torch

from farsighter.agents.common import (
    Counters,
    batch_tensors,
    build_seeded,
    greedy_actions,
    load_state,
    make_replay,
    obs_tensor,
    sample_minibatch,
    save_state,
    sync_target,
    updates_owed,
)
from farsighter.agents.ddqn import DoubleQLoss
from farsighter.agents.learner import Learner
from farsighter.agents.protocol import AgentFactory
from farsighter.config import Config
from farsighter.exploration import EpsilonGreedy
from farsighter.exploration.rnd import RNDBonus
from farsighter.networks import QNetwork, RNDNetwork
from farsighter.replay import VectorStep

BONUS_KEYS = ("rnd_target", "predictor", "rnd_opt", "obs_rms", "intrinsic_rms", "stats")


class RNDAgent:
    """DDQN with a random-network-distillation bonus added to the reward (module docstring)."""

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
        # DDQN's loss on the returns with the bonus added (module docstring)
        self.loss = DoubleQLoss(self.q, cfg.loss)
        self.learner = Learner(self.loss, self.q.parameters(), cfg, device)
        self.bonus = make_bonus(cfg, obs_space, device)
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
        """Q(s, .) for a batch of states; no posterior, so no variance."""
        return self.q(obs_tensor(obs_B, self.device)).cpu().numpy(), None

    def observe(self, step: VectorStep) -> None:
        self.replay.add_step(step)
        self.bonus.observe(step.obs_E)

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
        """One double-Q step on extrinsic + weighted intrinsic k-step returns, then one predictor
        step on the same minibatch; returns the TD loss."""
        cfg = self.cfg
        batch = sample_minibatch(self.replay, cfg, cfg.batch_size, self.counters.k)
        inputs = batch_tensors(batch, self.device).tensors()
        ri_B = torch.as_tensor(self.bonus.returns(batch, self.replay), device=self.device)
        inputs["returns_B"] = inputs["returns_B"] + cfg.rnd.intrinsic_weight * ri_B
        loss = self.learner(inputs)["loss"]
        self.bonus.train(inputs["obs_B"])
        return loss

    def diagnostics(self) -> dict[str, float]:
        return {
            "epsilon": self.explore.epsilon,
            "k": float(self.counters.k),
            "intrinsic_reward": self.bonus.stats["intrinsic_reward"],
            "intrinsic_std": float(self.bonus.intrinsic_rms.std),
            "predictor_loss": self.bonus.stats["predictor_loss"],
        }

    # ------------------------------------------------------------------ checkpoints
    SAVED = (
        "q",
        "q_target",
        "opt",
        "rnd_target",
        "predictor",
        "rnd_opt",
        "obs_rms",
        "intrinsic_rms",
        "rng",
        "epsilon",
        "stats",
        "counters",
    )

    SAVED_AT = {  # keys of the earlier layout
        "q_target": "loss.q_target",
        "opt": "learner",
        "epsilon": "explore.epsilon",
        **{key: f"bonus.{key}" for key in BONUS_KEYS},
    }

    def state_dict(self, include_replay: bool = True) -> dict[str, Any]:
        return save_state(self, self.SAVED, include_replay)

    def load_state_dict(self, state: dict[str, Any]) -> None:
        load_state(self, self.SAVED, state)


def make_bonus(cfg: Config, obs_space: gym.spaces.Box, device: torch.device) -> RNDBonus:
    """Seed ``cfg.seed``'s RND bonus: a fixed random target network (seeded seed + 4) and its
    predictor (seed + 5), which the RND paper gives the target's architecture with two more
    layers."""
    r = cfg.rnd
    return RNDBonus(
        cfg,
        build_seeded(
            cfg.seed + 4, lambda: RNDNetwork(obs_space, cfg.hidden_sizes, r.feature_dim, 0)
        ).to(device),
        build_seeded(
            cfg.seed + 5, lambda: RNDNetwork(obs_space, cfg.hidden_sizes, r.feature_dim, 2)
        ).to(device),
        tuple(obs_space.shape or ()),
        device,
    )


AGENT: AgentFactory = RNDAgent  # the class farsighter.algorithms names; mypy checks the protocol
