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

Written once over a seed axis, on :class:`~farsighter.agents.ddqn.DDQNAgent`: each seed has its
own bonus (target and predictor seeded seed + 4 and seed + 5, its Adam, its observation and
intrinsic-reward statistics), computed and trained on that seed's rows in this order: the
intrinsic returns of its minibatch (which update its reward statistics), the double-Q step on the
returns with the bonus added (every seed at once), then one predictor step on its start
observations. On CPU each seed of a batch trains bit for bit as it trains alone.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import torch

from farsighter.agents.common import TensorBatch, build_seeded
from farsighter.agents.ddqn import DDQNAgent, DDQNMember, supports
from farsighter.agents.protocol import SeedAgentsFactory
from farsighter.config import Config
from farsighter.exploration.rnd import RNDBonus
from farsighter.networks import RNDNetwork
from farsighter.replay import Batch, VectorStep

__all__ = ["RNDAgent", "RNDMember", "make_bonus", "supports"]

RND_STATEFUL = ("rnd_target", "predictor", "rnd_opt", "obs_rms", "intrinsic_rms")
"""The pieces of an RND bonus saved by their ``state_dict`` (a seed's checkpoint keys)."""


class RNDAgent(DDQNAgent):
    """DDQN with a random-network-distillation bonus added to the reward (module docstring)."""

    def __init__(
        self,
        cfgs: Sequence[Config],
        obs_space: gym.spaces.Box,
        act_space: gym.spaces.Discrete,
        *,
        frame_stack: int,
        device: torch.device,
    ) -> None:
        super().__init__(cfgs, obs_space, act_space, frame_stack=frame_stack, device=device)
        self.bonuses = [make_bonus(c, obs_space, device) for c in cfgs]

    def observe(self, steps: Sequence[VectorStep]) -> None:
        super().observe(steps)
        for bonus, st in zip(self.bonuses, steps, strict=True):
            bonus.observe(st.obs_E)

    def returns(self, batch: Batch, t: TensorBatch) -> TensorBatch:
        """Each seed's returns plus its weighted intrinsic k-step returns, from its own rows."""
        B, w = self.cfg.batch_size, self.cfg.rnd.intrinsic_weight
        returns_SB = t.returns_B.view(self.seeds, B)
        with_bonus = []
        for s, bonus in enumerate(self.bonuses):
            rows = slice(s * B, (s + 1) * B)
            mine = dataclasses.replace(
                batch,
                steps=batch.steps[rows],
                env_index=batch.env_index[rows],
                index=batch.index[rows],
            )
            ri_B = torch.as_tensor(bonus.returns(mine, self.replay), device=self.device)
            with_bonus.append(returns_SB[s] + w * ri_B)
        return dataclasses.replace(t, returns_B=torch.cat(with_bonus))

    def after_update(self, t: TensorBatch) -> None:
        """One predictor step of each seed on its start observations: seed 0's rows start where
        the minibatch starts, the others' are copied so that they start where a tensor alone
        starts (as a seed alone's do)."""
        obs_SB = t.obs_B.view(self.seeds, self.cfg.batch_size, *t.obs_B.shape[1:])
        for s, bonus in enumerate(self.bonuses):
            bonus.train(obs_SB[s].clone() if s else obs_SB[s])

    def member(self, s: int) -> RNDMember:
        return RNDMember(self, s)


class RNDMember(DDQNMember):
    """One seed of an :class:`RNDAgent`, as an agent."""

    batch: RNDAgent

    def diagnostics(self) -> dict[str, float]:
        bonus = self.batch.bonuses[self.s]
        return {
            **super().diagnostics(),
            "intrinsic_reward": bonus.stats["intrinsic_reward"],
            "intrinsic_std": float(bonus.intrinsic_rms.std),
            "predictor_loss": bonus.stats["predictor_loss"],
        }

    def state_dict(self, include_replay: bool = True) -> dict[str, Any]:
        """This seed's checkpoint, the one its run alone writes."""
        bonus = self.batch.bonuses[self.s]
        return {
            **super().state_dict(include_replay),
            **{key: getattr(bonus, key).state_dict() for key in RND_STATEFUL},
            "epsilon": self.batch.epsilon,
            "stats": dict(bonus.stats),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        super().load_state_dict(state)
        bonus = self.batch.bonuses[self.s]
        for key in RND_STATEFUL:  # copies: never the caller's tensors
            getattr(bonus, key).load_state_dict(copy.deepcopy(state[key]))
        bonus.stats = dict(state["stats"])
        self.batch.epsilon = state["epsilon"]


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


SEED_AGENTS: SeedAgentsFactory = RNDAgent  # the class farsighter.algorithms names
