"""One seed of :class:`~farsighter.agents.farsighter_seeds.SeedBatchFarsighter`: what it owns
beside its slice of the stacked torsos (its posterior, target mean, counters, Thompson draws,
recent features, generators and target cache), made and seeded as ``FarsighterAgent`` makes its
own, and Eq. 8 on features it is handed (:class:`SeedParts`); and the seed seen as an agent
(:class:`FarsighterSeedMember`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np
import torch

from farsighter.agents.common import RecentRows, TensorBatch, obs_tensor
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
from farsighter.agents.seed_members import Member
from farsighter.config import Config
from farsighter.exploration import ThompsonExploration
from farsighter.exploration.optimism import calibrated, restart_at_switch, without_staying
from farsighter.stacked import load_member_optimizer_state, member_optimizer_state

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


class FarsighterSeedMember(Member):
    """A seed of :class:`~farsighter.agents.farsighter_seeds.SeedBatchFarsighter`:
    ``FarsighterAgent`` alone."""

    def __init__(self, batch: Any, s: int) -> None:
        super().__init__(batch, s)
        self.parts = batch.parts[s]

    def q_mean(self, obs_B: np.ndarray) -> torch.Tensor:
        """Q at the posterior mean, phi(s)^T mean_a, (B, A)."""
        return self._phi(obs_B) @ self.parts.head.mean_AD.T

    @torch.no_grad()
    def q_estimate(self, obs_B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        phi_BD = self._phi(obs_B)
        mean_BA = phi_BD @ self.parts.head.mean_AD.T
        return mean_BA.cpu().numpy(), self.parts.head.predictive_var(phi_BD).cpu().numpy()

    def explore(self, obs_E: np.ndarray, global_step: int) -> np.ndarray:
        """Uniform before ``learning_starts``, then a Thompson draw of this seed's
        (``FarsighterAgent.act``)."""
        p = self.parts
        if global_step < self.cfg.learning_starts:
            return np.asarray(p.rng.integers(0, self.batch.num_actions, size=len(obs_E)))
        with torch.no_grad():
            return p.exploration.actions(self._phi(obs_E), obs_E, p.gen).cpu().numpy()

    def _phi(self, obs_B: np.ndarray) -> torch.Tensor:
        """phi(s) of this seed's torso, (B, D)."""
        b = self.batch
        return b.torso.member_forward(obs_tensor(np.asarray(obs_B), b.device), self.s)

    def episode_diagnostics(self) -> dict[str, float]:
        """What an episode's metrics row reads (k), without the deferred Q-variance."""
        return {"k": float(self.parts.counters.k)}

    def diagnostics(self) -> dict[str, float]:
        head, c = self.parts.head, self.parts.counters
        return {
            "k": float(c.k),
            "q_variance": c.settle().q_variance,
            "posterior_refreshes": float(head.num_refreshes),
            "jitter_events": float(head.jitter_events),
            "noise_std": head.noise_std,
        }

    def state_dict(self, include_replay: bool = True) -> dict[str, Any]:
        """The checkpoint of ``FarsighterAgent`` alone, for this seed."""
        b, s, p = self.batch, self.s, self.parts
        return (
            {
                "torso": b.torso.member_state(s),
                "torso_target": b.torso_target.member_state(s),
                "head": p.head.state_dict(),
                "target_mean_AD": p.target_mean_AD.clone(),
                "opt": member_optimizer_state(b.opt, s),
                "rng": p.rng.bit_generator.state,
                "gen": p.gen.get_state(),
                "counters": dataclasses.asdict(p.counters.settle()),
                "replay": b.replay.member_state(s) if include_replay else None,
                "exploration": p.exploration.state_dict(),
                "recent_phi": p.recent_phi.state_dict(),
                "target_cache": p.cache.state_dict()
                if p.cache is not None and include_replay
                else None,
            }
            | ({"calibrated": p.calibrated} if self.cfg.blr.optimism != "always" else {})
            | ({"unpaid": p.unpaid} if self.cfg.blr.rearm_episodes else {})
        )

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """A checkpoint of this seed (written alone or in a batch). Seeds resume together only
        from checkpoints with the same counters (:func:`farsighter.seeds.train_seeds` groups
        them so)."""
        b, s, p = self.batch, self.s, self.parts
        b.torso.load_member(s, state["torso"])
        b.torso_target.load_member(s, state["torso_target"])
        p.head.load_state_dict(state["head"])
        p.target_mean_AD.copy_(state["target_mean_AD"])
        load_member_optimizer_state(b.opt, s, state["opt"])
        p.rng.bit_generator.state = state["rng"]
        p.gen.set_state(state["gen"])
        for key, value in state["counters"].items():
            setattr(p.counters, key, value)
        p.recent_phi.load_state_dict(state["recent_phi"])
        if state.get("calibrated", False) and not p.calibrated:
            b.calibrate(s, restart=False)
        p.unpaid = state.get("unpaid", 0)
        p.exploration.load_state_dict(state.get("exploration", state))
        if p.cache is not None:  # the rows it keeps, when the checkpoint has them
            p.cache.load_state_dict(state.get("target_cache"))
        if state.get("replay") is not None:
            b.replay.load_member(s, state["replay"])
        else:
            p.counters.hold_pending = True
