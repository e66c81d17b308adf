"""One seed of :class:`~farsighter.agents.farsighter.FarsighterAgent`: what it owns beside its
slice of the torsos (its posterior, target mean, counters, Thompson draws, recent features,
generators, target cache and the switch of ``blr.optimism``) and Eq. 8 under its posterior on
features it is handed (:class:`SeedParts`); and the seed seen as an agent
(:class:`FarsighterMember`), whose checkpoint is the one its run alone writes."""

from __future__ import annotations

import dataclasses
from functools import partial
from typing import Any

import numpy as np
import torch

from farsighter.agents.common import RecentRows, TensorBatch, obs_tensor, set_generator_state
from farsighter.agents.cuda_graph import Tensors
from farsighter.agents.farsighter_posterior import RECENT_FEATURES, FarsighterCounters
from farsighter.agents.farsighter_targets import (
    Targets,
    advantage,
    eq8_targets,
    k_or_one_step,
    target_draws,
)
from farsighter.agents.learner import make_target_cache
from farsighter.agents.seed_members import Member
from farsighter.config import Config
from farsighter.exploration import ThompsonExploration
from farsighter.exploration.optimism import calibrated, without_staying
from farsighter.ops.blr import BLRHead

Next = tuple[torch.Tensor, torch.Tensor]
"""phi(s') and phi_target(s') of one seed's rows, (B, D) each."""


class SeedParts:
    """One seed's own parts around its posterior ``head`` (``farsighter_posterior.make_head``),
    made and seeded from its config (numpy generator seed + 2, torch generator seed + 3), and
    its Eq. 8 on given features."""

    def __init__(self, cfg: Config, head: BLRHead, device: torch.device) -> None:
        self.cfg = cfg
        # the targets (blr.target, k_target), which blr.optimism until-reward switches
        self.blr, self.k_target = cfg.blr, cfg.k_target
        self.calibrated = False  # blr.optimism's switch
        self.head = head
        self.target_mean_AD = self.head.mean_AD.clone()  # moved by the target copy alone
        self.counters = FarsighterCounters(k=cfg.k)
        # Eq. 7: each environment's weight draw and when it is replaced (blr.redraw)
        self.exploration = ThompsonExploration(cfg, self.head, self.counters)
        # incremental mode: recent minibatch features, for the Q-variance of adaptive k
        self.recent_phi = RecentRows(RECENT_FEATURES)
        self.rng = np.random.default_rng(cfg.seed + 2)
        self.gen = torch.Generator(device=device)
        self.gen.manual_seed(cfg.seed + 3)
        # phi_target(s') of replay rows (keyed by this seed's streams) until the next copy
        self.cache = make_target_cache(cfg, device, head.dim)

    def calibrate(self) -> None:
        """``blr.optimism = until-reward``'s switch: from now on the posterior mean and the
        k-step target alone (no draw, no max with the one-step target; cut at exploratory
        actions where ``k_target = cut``)."""
        self.calibrated = True
        self.blr, self.k_target = calibrated(self.cfg.blr, self.cfg.k_target)

    def draws(self, rows: int, one_step: bool = False) -> Tensors:
        """What the targets of ``rows`` rows draw (:func:`target_draws`), from this seed's
        generator: drawn before the update, so that a captured step can take them."""
        acting = partial(self.exploration.acting_draw, self.gen)
        return target_draws(self.blr.target, self.head, rows, one_step, self.gen, acting)

    @torch.no_grad()
    def lookup(
        self, obs_B: torch.Tensor, e_B: np.ndarray, end_B: np.ndarray, forward: Any
    ) -> torch.Tensor:
        """phi_target(s') of rows ``end_B`` of streams ``e_B`` from this seed's cache, its
        misses through ``forward`` (its own target torso alone)."""
        assert self.cache is not None
        return self.cache.lookup(
            e_B, end_B, lambda i: forward(obs_B[torch.from_numpy(i).to(obs_B.device)])
        )

    @torch.no_grad()
    def y(self, t: TensorBatch, nxt: Next, draws: Tensors, kind: str | None = None) -> torch.Tensor:
        """y of Eq. 8 under this seed's posterior and target mean from the features of s'
        (``kind``: ``blr.target`` unless given; ``mean``: the target under the posterior mean)."""
        blr = self.blr
        if not blr.stay_optimism:  # no draw where the window ends where it began
            draws = without_staying(draws, t.obs_B, t.next_obs_B)
        return eq8_targets(
            self.head,
            self.target_mean_AD,
            blr.target if kind is None else kind,
            t,
            *nxt,
            draws,
            blr.center_sample,
            blr.target_noise_scale,
        )

    @torch.no_grad()
    def targets(
        self,
        t: TensorBatch,
        draws: Tensors,
        nxt: Next,
        one: tuple[TensorBatch, Tensors, Next] | None = None,
    ) -> torch.Tensor:
        """This seed's y of Eq. 8: on the k-step windows ``t`` (features of s' ``nxt``), and
        with ``one`` (``k_target`` max or max-mean: the one-step windows of the same starts,
        their draws and features) the larger of the two, or the one larger under the mean."""
        y_B = self.y(t, nxt, draws)
        if one is None:
            return y_B
        one_t, one_draws, one_nxt = one
        one_B = self.y(one_t, one_nxt, one_draws)
        if self.k_target == "max":
            return k_or_one_step(y_B, one_B)
        mean_B, one_mean_B = self.y(t, nxt, {}, "mean"), self.y(one_t, one_nxt, {}, "mean")
        return k_or_one_step(y_B, one_B, mean_B, one_mean_B)

    @property
    def advantage_alpha(self) -> float:
        """``blr.advantage_learning``'s alpha once calibrated, else 0."""
        return self.blr.advantage_learning if self.calibrated else 0.0

    def advantage(self, phi_target_BD: torch.Tensor | None, actions_B: torch.Tensor) -> Targets:
        """This seed's targets -> the same under ``blr.advantage_learning`` once calibrated,
        from the target features of the rows' start states."""
        return advantage(self.advantage_alpha, phi_target_BD, self.target_mean_AD, actions_B)


class FarsighterMember(Member):
    """One seed of a :class:`~farsighter.agents.farsighter.FarsighterAgent`, as an agent."""

    def __init__(self, batch: Any, s: int) -> None:
        super().__init__(batch, s)
        self.parts: SeedParts = batch.parts[s]

    def q_mean(self, obs_B: np.ndarray) -> torch.Tensor:
        """Q at the posterior mean, phi(s)^T mean_a, (B, A)."""
        return self._phi(obs_B) @ self.parts.head.mean_AD.T

    @torch.no_grad()
    def q_estimate(self, obs_B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Posterior mean of Q(s, .) and its predictive variance phi^T Cov_a phi (Eq. 7, 9)."""
        phi_BD = self._phi(obs_B)
        mean_BA = phi_BD @ self.parts.head.mean_AD.T
        return mean_BA.cpu().numpy(), self.parts.head.predictive_var(phi_BD).cpu().numpy()

    def explore(self, obs_E: np.ndarray, global_step: int) -> np.ndarray:
        """Uniform before ``learning_starts``, then a Thompson draw of this seed's."""
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
            **({"act_scale": head.act_scale} if self.cfg.blr.act_width != "posterior" else {}),
        }

    def state_dict(self, include_replay: bool = True) -> dict[str, Any]:
        """This seed's checkpoint, the one its run alone writes."""
        b, s, p = self.batch, self.s, self.parts
        cache = p.cache.state_dict() if p.cache is not None and include_replay else None
        state = {
            "torso": b.torso.member_state(s),
            "torso_target": b.loss.torso_target.member_state(s),
            "head": p.head.state_dict(),
            "target_mean_AD": p.target_mean_AD.clone(),
            "opt": b.learner.member_state(s),
            "rng": p.rng.bit_generator.state,
            "gen": p.gen.get_state(),
            "counters": dataclasses.asdict(p.counters.settle()),
            "replay": b.replay.member_state(s) if include_replay else None,
            "exploration": p.exploration.state_dict(),
            "recent_phi": p.recent_phi.state_dict(),
            "target_cache": cache,  # keyed by replay rows: of no use without them
        }
        if self.cfg.blr.optimism != "always":  # the switch
            state["calibrated"] = p.calibrated
        return state

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """A checkpoint of this seed (written alone or in a batch). Seeds resume together only
        from checkpoints with the same counters (:mod:`farsighter.seeds` groups them so)."""
        b, s, p = self.batch, self.s, self.parts
        b.torso.load_member(s, state["torso"])
        b.loss.torso_target.load_member(s, state["torso_target"])
        p.head.load_state_dict(state["head"])
        p.target_mean_AD.copy_(state["target_mean_AD"])
        b.learner.load_member(s, state["opt"])
        p.rng.bit_generator.state = state["rng"]
        set_generator_state(p.gen, state["gen"])
        for key, value in state["counters"].items():
            setattr(p.counters, key, value)
        p.recent_phi.load_state_dict(state["recent_phi"])
        if state.get("calibrated", False) and not p.calibrated:
            b.calibrate(s, restart=False)
        # a checkpoint from before the exploration object holds its pieces under our own keys
        p.exploration.load_state_dict(state.get("exploration", state))
        if p.cache is not None:  # the rows it keeps, when the checkpoint has them
            p.cache.load_state_dict(state.get("target_cache"))
        if state.get("replay") is not None:
            b.replay.load_member(s, state["replay"])
        else:
            p.counters.hold_pending = True
