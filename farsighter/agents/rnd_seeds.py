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

import dataclasses
from collections.abc import Sequence

import gymnasium as gym
import torch

from farsighter.agents.common import TensorBatch
from farsighter.agents.ddqn_seeds import SeedBatchDDQN, supports
from farsighter.agents.rnd import make_bonus
from farsighter.agents.seed_members import RNDSeedMember
from farsighter.config import Config
from farsighter.replay import Batch, VectorStep

ALGOS = ("rnd", "krnd")
"""The algorithms with a seed-batched form here."""

__all__ = ["ALGOS", "SeedBatch", "SeedBatchRND", "supports"]


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


SeedBatch = SeedBatchRND
"""The batch class :mod:`farsighter.seeds` builds for this module's algorithms."""
