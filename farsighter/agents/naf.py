"""Continuous control: NAF, multi-step NAF, Bayesian NAF and Farsighter-NAF in one file.

Q(s, a) = V(s) - 1/2 (a - mu(s))^T P(s) (a - mu(s)),  P = L L^T   (paper Eq. 4, section 3.3)

on a shared representation phi(s) (MLP 64-32, appendix 9.1.2) with linear V and L heads and a
mu-layer, mu(s) = scale(tanh(mu_layer(phi(s)))) inside the action bounds. The four agents:

* ``naf``: plain ``nn.Linear`` mu-layer, Gaussian or Ornstein-Uhlenbeck action noise, 1-step.
* ``knaf``: the same with k-step returns (section 5.2's multi-step NAF baseline).
* ``bnaf``: the mu-layer is a :class:`~farsighter.ops.bayes_layer.BayesianLinear` (Bayes by
  backprop, appendix 8); one weight set is sampled per environment per step and the agent acts
  with the sampled mu (Algorithm 3 line 4), 1-step.
* ``farsighter-naf``: the same draws, re-made at every step, over k-step windows (section 4.4,
  the recursive Thompson sampling of Algorithm 2), with fixed or adaptive k (section 4.5).

Learning alternates as section 4.3 describes:

* every ``train_every`` steps, ``naf.updates_per_step`` TD steps on theta, theta_V, theta_P (and
  the plain mu-layer of naf/knaf) with the loss of Algorithm 3 line 9 and the target
  y = r^k + gamma^n (1 - terminal) V'(s') (Eq. 8 with argmax_a' Q = mu, so max Q' = V'); the
  Bayesian mu-layer enters at its posterior mean and is not changed; the target network moves
  by ``tau`` after each TD step (the convention of NAF's and DDPG's code), or once every N steps
  as Algorithm 3 line 11 reads (``naf.soft_update = every_n``);
* (bnaf, farsighter-naf) every M = ``naf.elbo_every`` steps, ``naf.elbo_steps`` steps on the
  ELBO of Eq. 10 for the Bayesian mu-layer alone, theta, theta_V, theta_P frozen.

Both losses, and how Eq. 10 is read: :mod:`farsighter.agents.naf_losses`.

Q-variance (for adaptive k and ``q_estimate``): the posterior in the continuous case is over the
action (section 4.3), so we measure its spread there: the variance of the mu-layer's output
(pre-tanh) under q, sum_i phi_i^2 sigma_oi^2 + sigma_bo^2 (``BayesianLinear.output_mean_var``),
averaged over action dimensions and over the states of the last ELBO minibatch. It is the
continuous analogue of phi^T Cov_a phi of the discrete agent. Evaluation acts with the mean.

Why mu is kept out of tanh's saturation (``naf.mu_penalty``, soft bounds on L's diagonal):
docs/design.md, "Continuous control".
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from farsighter import algorithms
from farsighter.agents.common import (
    Counters,
    TensorBatch,
    adapt_k,
    batch_tensors,
    build_seeded,
    crossed,
    load_state,
    make_replay,
    obs_tensor,
    sample_minibatch,
    save_state,
    updates_owed,
)
from farsighter.agents.learner import Learner
from farsighter.agents.naf_losses import ElboLoss, NAFLoss
from farsighter.agents.protocol import AgentFactory
from farsighter.config import Config
from farsighter.errors import ConfigError
from farsighter.exploration.noise import ActionNoise
from farsighter.networks import NAFNetwork
from farsighter.ops.bayes_layer import BayesianLinear
from farsighter.replay import VectorStep


@dataclass
class NAFCounters(Counters):
    td_steps: int = 0  # TD updates made
    elbo_rounds: int = 0  # ELBO updates of the mu-layer posterior (every M steps)
    draws: int = 0  # weight draws made for acting (one per step)
    q_variance: float = float("nan")  # mu-layer output variance at the latest ELBO update
    elbo_nll: float = float("nan")
    elbo_kl: float = float("nan")


class NAFAgent:
    """naf, knaf, bnaf and farsighter-naf (the module docstring says how they differ)."""

    def __init__(
        self,
        cfg: Config,
        obs_space: gym.spaces.Box,
        act_space: gym.spaces.Box,
        *,
        frame_stack: int,
        device: torch.device,
    ) -> None:
        if obs_space.shape is None or len(obs_space.shape) != 1:
            raise ConfigError(
                f"{cfg.algo} needs flat vector observations; got shape {obs_space.shape}"
            )
        self.cfg = cfg
        self.device = device
        self.bayesian = algorithms.get(cfg.algo).bayesian
        n = cfg.naf
        self.low_A = np.asarray(act_space.low, dtype=np.float32)
        self.high_A = np.asarray(act_space.high, dtype=np.float32)
        self.half_range_A = (self.high_A - self.low_A) / 2
        self.action_dim = len(self.low_A)
        self.net = build_seeded(
            cfg.seed,
            lambda: NAFNetwork(
                int(obs_space.shape[0]),
                self.low_A,
                self.high_A,
                n.hidden_sizes,
                bayesian=self.bayesian,
                prior_std=n.prior_std,
                init_sigma=n.init_sigma,
            ),
        ).to(device)
        self.loss = NAFLoss(self.net, cfg, self.bayesian)
        # The TD loss trains theta, theta_V, theta_P; the mu-layer too unless it is Bayesian.
        td_params = [*self.net.torso.parameters(), *self.net.head.parameters()]
        if not self.bayesian:
            td_params += list(self.net.mu_layer.parameters())
        # eager: NAF's update has not been captured or compiled (nor measured so)
        self.learner = Learner(self.loss, td_params, cfg, device, eager=True)
        self.gen = torch.Generator(device=device)
        self.elbo_learner: Learner | None = None
        if isinstance(self.net.mu_layer, BayesianLinear):
            layer = self.net.mu_layer
            elbo_opt = torch.optim.Adam(
                [
                    {"params": [layer.weight_mu, layer.bias_mu], "lr": n.elbo_lr},
                    {"params": [layer.weight_rho, layer.bias_rho], "lr": n.elbo_rho_lr},
                ],
                foreach=True,  # as make_optimizer: the same arithmetic in one call
            )
            self.elbo_loss = ElboLoss(self.loss, cfg, self.gen)
            self.elbo_learner = Learner(
                self.elbo_loss, layer.parameters(), cfg, device, optimizer=elbo_opt, eager=True
            )
        self.replay = make_replay(
            cfg, obs_space, frame_stack, seed=cfg.seed + 1, act_space=act_space
        )
        self.rng = np.random.default_rng(cfg.seed + 2)
        self.gen.manual_seed(cfg.seed + 3)
        self.her = None
        if n.her:
            from farsighter.envs.factory import goal_spec

            self.her = goal_spec(cfg)
        self.noise = ActionNoise(cfg, self.action_dim, self.rng)  # naf, knaf
        self.counters = NAFCounters(k=cfg.k)

    # ------------------------------------------------------------------ acting
    def act(self, obs_E: np.ndarray, global_step: int, explore: bool = True) -> np.ndarray:
        """Actions (E, A) within the bounds: uniform before ``learning_starts``; then mu plus
        noise (naf, knaf), mu under one fresh weight draw per environment (bnaf,
        farsighter-naf), or mu under the posterior mean (evaluation)."""
        n = obs_E.shape[0]
        if explore and global_step < self.cfg.learning_starts:
            return self.rng.uniform(self.low_A, self.high_A, size=(n, self.action_dim)).astype(
                np.float32
            )
        with torch.no_grad():
            phi_ED = self.net.torso(obs_tensor(obs_E, self.device))
            if explore and isinstance(self.net.mu_layer, BayesianLinear):
                # Algorithm 2 line 2 / Algorithm 3 line 4: a fresh theta^a ~ q every step.
                w_EOI, b_EO = self.net.mu_layer.sample_weights_batch(n, generator=self.gen)
                out_EA = BayesianLinear.forward_with_batch(phi_ED, w_EOI, b_EO)
                self.counters.draws += 1
            else:
                out_EA = self.net.mu_out_mean(phi_ED)
            action_EA = self.net.mu_from_out(out_EA).cpu().numpy()
        if explore and not self.bayesian:
            action_EA = action_EA + self.noise(n) * self.half_range_A
        return np.clip(action_EA, self.low_A, self.high_A).astype(np.float32)

    @torch.no_grad()
    def q_estimate(self, obs_B: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """max_a Q(s, a) = V(s) as (B, 1), and for the Bayesian agents the posterior variance of
        the mu-layer output averaged over action dimensions (B, 1); None for naf/knaf."""
        phi_BD = self.net.torso(obs_tensor(obs_B, self.device))
        v_B1 = self.net.head.v(phi_BD).cpu().numpy()
        if not isinstance(self.net.mu_layer, BayesianLinear):
            return v_B1, None
        _, var_BA = self.net.mu_layer.output_mean_var(phi_BD)
        return v_B1, var_BA.mean(dim=1, keepdim=True).cpu().numpy()

    def observe(self, step: VectorStep) -> None:
        self.replay.add_step(step)
        self.noise.ended(np.logical_or(step.terminated_E, step.truncated_E))

    # ------------------------------------------------------------------ learning
    def learn(self, global_step: int) -> dict[str, torch.Tensor]:
        cfg, c = self.cfg, self.counters
        metrics: dict[str, torch.Tensor] = {}
        for _ in range(updates_owed(c, cfg, global_step)):
            for _ in range(cfg.naf.updates_per_step):
                loss = self.update()
                if loss is not None:
                    metrics["td_loss"] = loss
        if cfg.naf.soft_update == "every_n" and crossed(
            c, "target_syncs", global_step, cfg.target_update_every
        ):
            self.loss.soft_update(cfg.naf.tau)  # Algorithm 3 line 11, literally
        if self.bayesian:
            if global_step >= cfg.learning_starts and crossed(
                c, "elbo_rounds", global_step, cfg.naf.elbo_every
            ):
                elbo = self.elbo_update()
                if elbo is not None:
                    metrics["elbo_loss"] = elbo
        return metrics

    def _sample(self, batch_size: int) -> TensorBatch | None:
        cfg = self.cfg
        try:
            batch = sample_minibatch(self.replay, cfg, batch_size, self.counters.k)
        except ValueError:  # not enough complete k-step windows yet (or the replay was emptied)
            return None
        if self.her is not None:
            from farsighter.replay.her import relabel_future

            batch = relabel_future(
                batch,
                self.replay,
                self.her,
                k=self.counters.k,
                gamma=cfg.gamma,
                ratio=cfg.naf.her_ratio,
                rng=self.rng,
            )
        return batch_tensors(batch, self.device)

    def update(self) -> torch.Tensor | None:
        """One TD step on theta, theta_V, theta_P (+ the plain mu-layer), then the soft target
        update. A Bayesian mu-layer is used at its posterior mean and left unchanged."""
        t = self._sample(self.cfg.batch_size)
        if t is None:
            return None
        loss = self.learner(t.tensors())["loss"]
        if self.cfg.naf.soft_update == "every_update":
            self.loss.soft_update(self.cfg.naf.tau)
        self.counters.td_steps += 1
        return loss

    def elbo_update(self) -> torch.Tensor | None:
        """Every M steps: ``naf.elbo_steps`` steps on the ELBO of Eq. 10 (:class:`ElboLoss`) for
        the Bayesian mu-layer's posterior q(theta^a); then adaptive k reads its output variance."""
        assert self.elbo_learner is not None
        c, naf = self.counters, self.cfg.naf
        self.elbo_loss.num_data = max(1, len(self.replay))
        loss: torch.Tensor | None = None
        phi_BD: torch.Tensor | None = None
        for _ in range(naf.elbo_steps):
            t = self._sample(naf.elbo_batch)
            if t is None:
                break
            out = self.elbo_learner(t.tensors())
            loss, phi_BD = out["elbo"].detach(), out["phi"]
            c.elbo_nll, c.elbo_kl = float(out["nll"].detach()), float(out["kl"].detach())
        if phi_BD is None:
            return None
        with torch.no_grad():
            c.q_variance = float(self.elbo_loss.layer.output_mean_var(phi_BD)[1].mean())
        adapt_k(c, c.q_variance, self.cfg.adaptive_k, self.replay)
        return loss

    def diagnostics(self) -> dict[str, float]:
        c = self.counters
        out = {"k": float(c.k)}
        if isinstance(self.net.mu_layer, BayesianLinear):
            out.update(
                q_variance=c.q_variance,
                mu_sigma=float(self.net.mu_layer.weight_sigma.detach().mean()),
                elbo_nll=c.elbo_nll,
                elbo_kl=c.elbo_kl,
                elbo_updates=float(c.elbo_rounds),
            )
        return out

    # ------------------------------------------------------------------ checkpoints
    SAVED = ("net", "net_target", "opt", "elbo_opt", "rng", "gen", "ou_EA", "counters")
    SAVED_AT = {  # keys of the earlier layout
        "net_target": "loss.net_target",
        "opt": "learner",
        "elbo_opt": "elbo_learner",
        "ou_EA": "noise.ou_EA",
    }

    def state_dict(self, include_replay: bool = True) -> dict[str, Any]:
        return save_state(self, self.SAVED, include_replay)

    def load_state_dict(self, state: dict[str, Any]) -> None:
        load_state(self, self.SAVED, state)


AGENT: AgentFactory = NAFAgent  # the class farsighter.algorithms names; mypy checks the protocol
