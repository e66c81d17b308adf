"""Farsighter (paper sections 4.2, 4.4, 4.5; Algorithms 1 and 2) and BDQN, its k = 1 case.

Q(s, a) = phi_theta(s)^T w_a with a Bayesian linear regression posterior over each w_a (Eq. 9).

* Acting (Algorithm 2): a Thompson draw w_a = mean_a + chol(Cov_a) z (Eq. 7), one independent z
  per action and per environment; Farsighter draws afresh at every step, BDQN every T steps
  (``blr.redraw``). Before ``learning_starts`` actions are uniform, as for the epsilon agents.
* Learning theta (Eq. 8): the double-Q loss with w fixed at the posterior mean, on k-step
  returns with gamma^k bootstraps (section 4.4), from the latest N transitions (Algorithm 1
  line 4) when ``sample_recent``. Target network and target mean are copied every N steps.
* Posterior (Algorithm 1 line 6): every M steps, from up to D recent tuples with features of the
  current theta and targets y from the target network exactly as in Eq. 8 (batch mode), or from
  running sufficient statistics fed with each new transition once (incremental mode).
* Adaptive k (Algorithm 1 line 7): after each refresh, the Q-variance (mean of
  phi^T Cov_a phi at the greedy action over the refresh states) moves k by one towards the
  variance target; the replay is emptied when k changes (optional).
"""

from __future__ import annotations

import copy
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import nn

from farsighter.adaptive_k import adapt_k
from farsighter.agents.common import (
    batch_tensors,
    build_seeded,
    clip_and_step,
    make_optimizer,
    make_replay,
    obs_tensor,
    td_loss,
    updates_due,
)
from farsighter.blr import BLRHead, greedy_predictive_variance
from farsighter.config import Config
from farsighter.networks import make_torso
from farsighter.ops.targets import double_q_target
from farsighter.replay import Batch

FEATURE_CHUNK = 4_096  # rows per forward pass when computing features for a posterior refresh


class FarsighterAgent:
    """BLR-headed DQN with Thompson exploration over k steps (``bdqn`` is the k = 1 case)."""

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

        def build() -> tuple[nn.Module, torch.Tensor]:
            torso = make_torso(obs_space, cfg.hidden_sizes)
            # The posterior mean starts where a linear Q head would (no bias: Q = phi^T w_a).
            init_AD = nn.Linear(torso.out_dim, self.num_actions, bias=False).weight.detach()
            return torso, init_AD

        torso, init_AD = build_seeded(cfg.seed, build)
        self.torso = torso.to(device)
        self.torso_target = copy.deepcopy(self.torso).requires_grad_(False)
        b = cfg.blr
        self.head = BLRHead(
            num_actions=self.num_actions,
            dim=self.torso.out_dim,
            prior_std=b.prior_std,
            noise_std=b.noise_std,
            cov_scale=b.cov_scale,
            forgetting=b.forgetting,
            device=device,
        )
        self.head.set_mean(init_AD.to(device))
        self.target_mean_AD = self.head.mean_AD.clone()
        self.opt = make_optimizer(self.torso.parameters(), cfg)
        self.replay = make_replay(cfg, obs_space, frame_stack, seed=cfg.seed + 1)
        self.rng = np.random.default_rng(cfg.seed + 2)
        self.gen = torch.Generator(device=device)
        self.gen.manual_seed(cfg.seed + 3)

        self.k = cfg.k
        self.updates = 0
        self.target_syncs = 0
        self.refreshes = 0
        self.draws = 0  # Thompson draws made (one per acting step with redraw=step)
        self.q_variance = float("nan")
        self.accumulated_to = np.zeros(cfg.num_envs, dtype=np.int64)  # incremental mode cursor
        # Per-environment weight draws for redraw = every / episode.
        self.w_EAD: torch.Tensor | None = None
        self.redraw_E = np.ones(cfg.num_envs, dtype=bool)
        self.steps_since_draw = 0

    # ------------------------------------------------------------------ acting
    def act(self, obs_E: np.ndarray, global_step: int, explore: bool = True) -> np.ndarray:
        n = obs_E.shape[0]
        if explore and global_step < self.cfg.learning_starts:
            return np.asarray(self.rng.integers(0, self.num_actions, size=n))
        with torch.no_grad():
            phi_ED = self.torso(obs_tensor(obs_E, self.device))
            if not explore:  # evaluation: greedy under the posterior mean
                q_EA = phi_ED @ self.head.mean_AD.T
            else:
                q_EA = self._thompson_q(phi_ED)
        return q_EA.argmax(dim=1).cpu().numpy()

    def _thompson_q(self, phi_ED: torch.Tensor) -> torch.Tensor:
        blr = self.cfg.blr
        self.draws += 1
        if blr.redraw == "step":  # Algorithm 2 line 2: a fresh z at every step
            return self.head.q_sample(phi_ED, generator=self.gen)
        n = phi_ED.shape[0]
        if blr.redraw == "every":
            if self.w_EAD is None or self.steps_since_draw >= blr.redraw_every:
                self.redraw_E[:] = True
                self.steps_since_draw = 0
            self.steps_since_draw += 1
        if self.w_EAD is None or self.w_EAD.shape[0] != n:
            self.w_EAD = self.head.sample_weights(n, generator=self.gen)
            self.redraw_E[:] = False
        elif self.redraw_E.any():
            idx = np.flatnonzero(self.redraw_E)
            self.w_EAD[idx] = self.head.sample_weights(len(idx), generator=self.gen)
            self.redraw_E[:] = False
        return torch.einsum("ed,ead->ea", phi_ED, self.w_EAD)

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
        if self.cfg.blr.redraw == "episode":
            self.redraw_E |= np.logical_or(terminated_E, truncated_E)

    # ------------------------------------------------------------------ learning
    def learn(self, global_step: int) -> dict[str, torch.Tensor]:
        cfg = self.cfg
        metrics: dict[str, torch.Tensor] = {}
        for _ in range(updates_due(global_step, cfg, self.updates)):
            self.updates += 1  # an update the replay cannot serve yet (after emptying) is skipped
            loss = self.update()
            if loss is not None:
                metrics["td_loss"] = loss
        syncs = global_step // cfg.target_update_every
        if syncs > self.target_syncs:  # Algorithm 1 line 8
            self.torso_target.load_state_dict(self.torso.state_dict())
            self.target_mean_AD = self.head.mean_AD.clone()
            self.target_syncs = syncs
        refreshes = global_step // cfg.blr.posterior_every
        if refreshes > self.refreshes and global_step >= cfg.learning_starts:
            self.refreshes = refreshes
            self.refresh_posterior()
        return metrics

    def _sample(self) -> Batch | None:
        cfg = self.cfg
        try:
            return self.replay.sample(
                cfg.batch_size,
                k=self.k,
                gamma=cfg.gamma,
                recent=cfg.effective_recent_window if cfg.sample_recent else None,
                stride=self.k if cfg.stride else 1,
            )
        except ValueError:  # not enough complete k-step windows yet
            return None

    @torch.no_grad()
    def _targets(self, t: dict[str, torch.Tensor]) -> torch.Tensor:
        """y = r^k + gamma^k phi_target(s')^T mean_target[a*] (Eq. 8 with k-step returns).

        a* is the argmax under the online features and the posterior mean (Eq. 8), or under a
        Thompson draw when ``blr.target = thompson`` (the BDQN authors' code)."""
        phi_next = self.torso(t["next_obs"])
        if self.cfg.blr.target == "thompson":
            q_next_online = self.head.q_sample(phi_next, generator=self.gen)
        else:
            q_next_online = phi_next @ self.head.mean_AD.T
        q_next_target = self.torso_target(t["next_obs"]) @ self.target_mean_AD.T
        return double_q_target(t["returns"], t["bootstrap"], q_next_online, q_next_target)

    def update(self) -> torch.Tensor | None:
        """One step on theta with w at the posterior mean (Eq. 8); the BLR weights stay fixed."""
        batch = self._sample()
        if batch is None:
            return None
        t = batch_tensors(batch, self.device)
        y_B = self._targets(t)
        q_B = (self.torso(t["obs"]) @ self.head.mean_AD.T).gather(1, t["actions"][:, None])[:, 0]
        loss = td_loss(q_B, y_B, self.cfg.loss)
        clip_and_step(loss, list(self.torso.parameters()), self.opt, self.cfg.max_grad_norm)
        return loss.detach()

    @torch.no_grad()
    def _features_and_targets(
        self, batch: Batch
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        phis, ys = [], []
        n = len(batch.actions)
        for lo in range(0, n, FEATURE_CHUNK):
            sl = slice(lo, lo + FEATURE_CHUNK)
            part = Batch(
                obs=batch.obs[sl],
                actions=batch.actions[sl],
                returns=batch.returns[sl],
                bootstrap=batch.bootstrap[sl],
                next_obs=batch.next_obs[sl],
                steps=batch.steps[sl],
                env_index=batch.env_index[sl],
                index=batch.index[sl],
            )
            t = batch_tensors(part, self.device)
            phis.append(self.torso(t["obs"]))
            ys.append(self._targets(t))
        actions = torch.as_tensor(batch.actions, device=self.device, dtype=torch.int64)
        return torch.cat(phis), actions, torch.cat(ys)

    def refresh_posterior(self) -> None:
        """Algorithm 1 line 6 (and line 7 with adaptive k)."""
        cfg = self.cfg
        if cfg.blr.mode == "batch":
            e_N, l_N = self.replay.recent_indices(cfg.blr.posterior_samples)
            batch = self.replay.sample_indices(e_N, l_N, self.k, cfg.gamma)
            if len(batch.actions) == 0:
                return
            phi_ND, a_N, y_N = self._features_and_targets(batch)
            self.head.fit(phi_ND, a_N, y_N)  # statistics reset each refresh, as in BDQN's code
        else:
            batch = self._new_transitions()
            if len(batch.actions) == 0:
                return
            phi_ND, a_N, y_N = self._features_and_targets(batch)
            self.head.accumulate(phi_ND, a_N, y_N)
            self.head.refresh()
        self.q_variance = greedy_predictive_variance(self.head, phi_ND)
        ak = cfg.adaptive_k
        if ak.enabled:
            new_k = adapt_k(self.k, self.q_variance, ak.variance_target, ak.k_min, ak.k_max)
            if new_k != self.k:
                self.k = new_k
                if ak.empty_buffer:
                    self.replay.clear()
                    self.accumulated_to = self.replay.count.copy()

    def _new_transitions(self) -> Batch:
        """Incremental mode: every transition enters the statistics once, when its k-step window
        is complete (no rescan of the buffer)."""
        es, ls = [], []
        low_E = np.maximum(self.accumulated_to, self.replay.count - self.replay.capacity)
        low_E = np.maximum(low_E, self.replay.floor)
        for e in range(self.replay.num_envs):
            hi = int(self.replay.count[e]) - self.k  # windows starting here are complete
            logical = np.arange(low_E[e], max(hi, low_E[e]), dtype=np.int64)
            es.append(np.full(logical.shape, e, dtype=np.int64))
            ls.append(logical)
            self.accumulated_to[e] = max(hi, low_E[e])
        return self.replay.sample_indices(
            np.concatenate(es), np.concatenate(ls), self.k, self.cfg.gamma
        )

    def diagnostics(self) -> dict[str, float]:
        return {
            "k": float(self.k),
            "q_variance": self.q_variance,
            "posterior_refreshes": float(self.head.num_refreshes),
            "jitter_events": float(self.head.jitter_events),
        }

    # ------------------------------------------------------------------ checkpoints
    def state_dict(self, include_replay: bool = True) -> dict[str, Any]:
        return {
            "torso": self.torso.state_dict(),
            "torso_target": self.torso_target.state_dict(),
            "head": self.head.state_dict(),
            "target_mean": self.target_mean_AD,
            "opt": self.opt.state_dict(),
            "rng": self.rng.bit_generator.state,
            "gen": self.gen.get_state(),
            "w": self.w_EAD,
            "counters": {
                "k": self.k,
                "updates": self.updates,
                "target_syncs": self.target_syncs,
                "refreshes": self.refreshes,
                "draws": self.draws,
                "q_variance": self.q_variance,
                "steps_since_draw": self.steps_since_draw,
                "redraw": self.redraw_E.copy(),
                "accumulated_to": self.accumulated_to.copy(),
            },
            "replay": self.replay.state_dict() if include_replay else None,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.torso.load_state_dict(state["torso"])
        self.torso_target.load_state_dict(state["torso_target"])
        self.head.load_state_dict(state["head"])
        self.target_mean_AD = state["target_mean"].to(self.device)
        self.opt.load_state_dict(state["opt"])
        self.rng.bit_generator.state = state["rng"]
        self.gen.set_state(state["gen"])
        self.w_EAD = state["w"]
        c = state["counters"]
        self.k, self.updates, self.target_syncs = c["k"], c["updates"], c["target_syncs"]
        self.refreshes, self.draws, self.q_variance = c["refreshes"], c["draws"], c["q_variance"]
        self.steps_since_draw = c["steps_since_draw"]
        self.redraw_E[...] = c["redraw"]
        self.accumulated_to[...] = c["accumulated_to"]
        if state.get("replay") is not None:
            self.replay.load_state_dict(state["replay"])
