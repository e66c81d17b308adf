"""RND and k-RND for S seeds at once: :class:`farsighter.agents.ddqn_seeds.SeedBatchDDQN`'s
stacked Q-networks, with each seed's own random-network-distillation bonus
(:class:`~farsighter.exploration.rnd.RNDBonus`: its target and predictor networks, seeded seed + 4
and seed + 5 as :class:`~farsighter.agents.rnd.RNDAgent` seeds them, its Adam, its observation
and intrinsic-reward statistics).

A seed's bonus is computed and trained by the bonus alone's code on that seed's rows, in
``RNDAgent.update``'s order: the intrinsic returns of its minibatch (which update its reward
statistics), the double-Q step on the returns with the bonus added (every seed at once), then one
predictor step on its start observations. On CPU each seed trains bit for bit as ``RNDAgent``
trains it alone (``tests/test_seeds.py``).
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import torch

from farsighter.agents.common import TensorBatch
from farsighter.agents.ddqn_seeds import SeedBatchDDQN, SeedMember, supports
from farsighter.agents.rnd import make_bonus
from farsighter.config import Config
from farsighter.replay import Batch, VectorStep

__all__ = ["SeedBatch", "SeedBatchRND", "supports"]


class SeedBatchRND(SeedBatchDDQN):
    """S RND agents of one config (``cfgs`` differ only in seed) as one computation."""

    def __init__(
        self,
        cfgs: Sequence[Config],
        obs_space: gym.spaces.Box,
        act_space: gym.spaces.Discrete,
        *,
        device: torch.device,
    ) -> None:
        super().__init__(cfgs, obs_space, act_space, device=device)
        self.bonuses = [make_bonus(c, obs_space, device) for c in cfgs]  # as RNDAgent's

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
        """One predictor step of each seed on its start observations (a copy: its rows start
        where a tensor alone starts)."""
        obs_SB = t.obs_B.view(self.seeds, self.cfg.batch_size, *t.obs_B.shape[1:])
        for s, bonus in enumerate(self.bonuses):
            bonus.train(obs_SB[s].clone())

    def member(self, s: int) -> RNDSeedMember:
        return RNDSeedMember(self, s)


class RNDSeedMember(SeedMember):
    """A seed of :class:`~farsighter.agents.rnd_seeds.SeedBatchRND`: ``RNDAgent`` alone."""

    batch: SeedBatchRND

    def diagnostics(self) -> dict[str, float]:
        bonus = self.batch.bonuses[self.s]
        return {
            **super().diagnostics(),
            "intrinsic_reward": bonus.stats["intrinsic_reward"],
            "intrinsic_std": float(bonus.intrinsic_rms.std),
            "predictor_loss": bonus.stats["predictor_loss"],
        }

    def state_dict(self, include_replay: bool = True) -> dict[str, Any]:
        """The checkpoint of ``RNDAgent`` alone, for this seed."""
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
        for key in RND_STATEFUL:  # copies: never the caller's tensors (as load_state does)
            getattr(bonus, key).load_state_dict(copy.deepcopy(state[key]))
        bonus.stats = dict(state["stats"])
        self.batch.epsilon = state["epsilon"]


RND_STATEFUL = ("rnd_target", "predictor", "rnd_opt", "obs_rms", "intrinsic_rms")
"""The pieces of an RND bonus saved by their ``state_dict`` (``RNDAgent``'s keys)."""


SeedBatch = SeedBatchRND
"""The batch class :func:`farsighter.agents.build_seed_agents` builds (``Algorithm.seed_batch``)."""
