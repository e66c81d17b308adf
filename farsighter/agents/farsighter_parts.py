"""One seed of :class:`~farsighter.agents.farsighter_seeds.SeedBatchFarsighter`: what it owns
beside its slice of the stacked torsos (its posterior, target mean, counters, Thompson draws,
recent features, generators and target cache), made and seeded as ``FarsighterAgent`` makes its
own, and Eq. 8 on features it is handed."""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

import numpy as np
import torch

from farsighter.agents.common import RecentRows, TensorBatch
from farsighter.agents.cuda_graph import Tensors
from farsighter.agents.farsighter_posterior import RECENT_FEATURES, FarsighterCounters, make_head
from farsighter.agents.farsighter_targets import (
    Targets,
    advantage,
    eq8_targets,
    k_or_one_step,
    one_step_batch,
    one_step_draws,
    target_draws,
)
from farsighter.agents.learner import make_target_cache
from farsighter.config import Config
from farsighter.exploration import ThompsonExploration
from farsighter.exploration.optimism import calibrated, restart_at_switch, without_staying

NextFeatures = torch.Tensor | list[torch.Tensor]
"""Every seed's features of s', (S, B, D), or a list of S (the target caches')."""


class SeedParts:
    """One seed's own parts, made and seeded as ``FarsighterAgent`` makes them alone, and its
    Eq. 8 on given features."""

    def __init__(
        self, cfg: Config, num_actions: int, dim: int, init_AD: torch.Tensor, device: torch.device
    ) -> None:
        self.cfg = cfg
        # the targets (blr.target, k_target), which blr.optimism until-reward switches
        self.blr, self.k_target = cfg.blr, cfg.k_target
        self.calibrated, self.unpaid = False, 0  # blr.optimism's switch, blr.rearm_episodes
        self.head = make_head(cfg, num_actions, dim, init_AD, device)
        self.target_mean_AD = self.head.mean_AD.clone()
        self.counters = FarsighterCounters(k=cfg.k)
        self.exploration = ThompsonExploration(cfg, self.head, self.counters)
        self.recent_phi = RecentRows(RECENT_FEATURES)
        self.rng = np.random.default_rng(cfg.seed + 2)
        self.gen = torch.Generator(device=device)
        self.gen.manual_seed(cfg.seed + 3)
        self.cache = make_target_cache(cfg, device, dim)  # FarsighterLoss's, keyed by its streams

    def calibrate(self, restart: bool = True, on: bool = True) -> None:
        """``blr.optimism = until-reward``'s switch (``FarsighterAgent.calibrate``)."""
        self.calibrated = on
        self.blr, self.k_target = calibrated(self.cfg.blr, self.cfg.k_target, on)
        if restart and on:
            restart_at_switch(self.cfg, self.head, self.target_mean_AD)

    def draws(self, rows: int, one_step: bool) -> Tensors:
        """The targets' draws (``FarsighterAgent._draws``), from this seed's generator."""
        acting = partial(self.exploration.acting_draw, self.gen)
        return target_draws(self.blr.target, self.head, rows, one_step, self.gen, acting)

    def target_features(
        self,
        obs_B: torch.Tensor,
        e_B: np.ndarray,
        end_B: np.ndarray,
        forward: Callable[[torch.Tensor], torch.Tensor],
    ) -> torch.Tensor:
        """phi_target(s') from this seed's cache (``CachedTarget``'s lookup), its misses
        through ``forward``, its own target torso alone."""
        assert self.cache is not None
        return self.cache.lookup(
            e_B, end_B, lambda i: forward(obs_B[torch.from_numpy(i).to(obs_B.device)])
        )

    @torch.no_grad()
    def y(
        self,
        t: TensorBatch,
        phi_next: torch.Tensor,
        phi_next_target: torch.Tensor,
        draws: Tensors,
        kind: str | None = None,
    ) -> torch.Tensor:
        """y of Eq. 8 under this seed's posterior and target mean (``kind``: ``blr.target``
        unless given; ``mean`` for the target under the posterior mean)."""
        head, blr = self.head, self.blr
        if not blr.stay_optimism:  # no draw where the window ends where it began
            draws = without_staying(draws, t.obs_B, t.next_obs_B)
        return eq8_targets(
            head,
            self.target_mean_AD,
            blr.target if kind is None else kind,
            t,
            phi_next,
            phi_next_target,
            draws,
            blr.center_sample,
            blr.target_noise_scale,
        )

    def targets(
        self,
        mine: Tensors,
        k_step: tuple[torch.Tensor, NextFeatures],
        one_step: tuple[torch.Tensor, NextFeatures] | None,
        s: int,
        with_one_step: bool,
    ) -> torch.Tensor:
        """This seed's (``s``) y of Eq. 8 on its rows ``mine`` and the batch's features of s'
        (``k_step``: phi and phi_target of the k-step windows; ``one_step``: of the one-step
        windows of ``k_target = max``): ``FarsighterLoss.__call__``'s targets."""
        t, draws = TensorBatch.of(mine), self.draws(len(mine["actions_B"]), with_one_step)
        nxt, nxt_target = k_step
        y_B = self.y(t, nxt[s], nxt_target[s], draws)
        if not with_one_step:
            return y_B
        assert one_step is not None
        one, (one_next, one_next_target) = one_step_batch(t, mine), one_step
        one_B = self.y(one, one_next[s], one_next_target[s], one_step_draws(draws))
        if self.k_target == "max":
            return k_or_one_step(y_B, one_B)
        mean_B = self.y(t, nxt[s], nxt_target[s], {}, "mean")
        return k_or_one_step(
            y_B, one_B, mean_B, self.y(one, one_next[s], one_next_target[s], {}, "mean")
        )

    def advantage(self, phi_target_BD: torch.Tensor | None, actions_B: torch.Tensor) -> Targets:
        """This seed's targets -> the same under ``blr.advantage_learning`` once it is calibrated
        (``FarsighterLoss.advantage``), from the target features of the rows' start states."""
        alpha = self.blr.advantage_learning if self.calibrated else 0.0
        return advantage(alpha, phi_target_BD, self.target_mean_AD, actions_B)
