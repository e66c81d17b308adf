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
  ELBO of Eq. 10 for the Bayesian mu-layer alone, theta, theta_V, theta_P frozen (see
  :meth:`NAFAgent.elbo_update` for how the loss is read).

Q-variance (for adaptive k and ``q_estimate``): the posterior in the continuous case is over the
action (section 4.3), so we measure its spread there: the variance of the mu-layer's output
(pre-tanh) under q, sum_i phi_i^2 sigma_oi^2 + sigma_bo^2 (``BayesianLinear.output_mean_var``),
averaged over action dimensions and over the states of the last ELBO minibatch. It is the
continuous analogue of phi^T Cov_a phi of the discrete agent. Evaluation acts with the mean.

Keeping mu out of tanh's saturation matters for the Bayesian agents (benchmarks/results/
learning_pendulum.json): they explore only through weight draws of the mu-layer, and once its
pre-tanh output is large the draws no longer move the action, the stored actions all sit at mu,
NAF's curvature P is no longer identified and falls to its floor, and the ELBO's mu gradient
(proportional to P) vanishes with it. On Pendulum-v1 this took farsighter-naf (k = 2) in 2 of 3
seeds; the pre-tanh penalty ``naf.mu_penalty`` (0.1 by default for bnaf and farsighter-naf)
and the soft bounds on L's diagonal (:func:`farsighter.ops.naf.soft_clamp`; the former hard
clamp left P stuck at its floor once crossed) fixed it.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from functools import partial
from typing import Any

import gymnasium as gym
import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from farsighter import algorithms
from farsighter.agents.common import (
    Counters,
    TensorBatch,
    adapt_k,
    batch_tensors,
    build_seeded,
    clip_and_step,
    crossed,
    load_state,
    make_optimizer,
    make_replay,
    obs_tensor,
    sample_minibatch,
    save_state,
    td_loss,
    updates_owed,
)
from farsighter.agents.protocol import AgentFactory
from farsighter.config import Config
from farsighter.errors import ConfigError
from farsighter.networks import MLPTorso
from farsighter.ops.bayes_layer import BayesianLinear, elbo_terms
from farsighter.ops.naf import NAFHead, naf_q, naf_td_target, scale_action
from farsighter.replay import VectorStep


class NAFNetwork(nn.Module):
    """phi (MLP), V and L heads (NAFHead) and the mu-layer (linear or Bayesian)."""

    def __init__(
        self,
        obs_dim: int,
        low_A: np.ndarray,
        high_A: np.ndarray,
        hidden_sizes: tuple[int, ...],
        *,
        bayesian: bool,
        prior_std: float = 0.1,
        init_sigma: float = 0.05,
    ) -> None:
        super().__init__()
        action_dim = len(low_A)
        self.torso = MLPTorso(obs_dim, hidden_sizes)
        d = self.torso.out_dim
        self.head = NAFHead(d, action_dim)
        self.mu_layer: nn.Linear | BayesianLinear = (
            BayesianLinear(d, action_dim, prior_std=prior_std, init_sigma=init_sigma)
            if bayesian
            else nn.Linear(d, action_dim)
        )
        self.low_A: torch.Tensor
        self.high_A: torch.Tensor
        self.register_buffer("low_A", torch.as_tensor(low_A, dtype=torch.float32))
        self.register_buffer("high_A", torch.as_tensor(high_A, dtype=torch.float32))

    def mu_from_out(self, out_BA: torch.Tensor) -> torch.Tensor:
        """The action mu from the mu-layer's output: tanh, then affine to the bounds."""
        return scale_action(torch.tanh(out_BA), self.low_A, self.high_A)

    def mu_out_mean(self, phi_BD: torch.Tensor, detach_weights: bool = False) -> torch.Tensor:
        """mu-layer output with the (posterior-mean) weights; ``detach_weights`` keeps theta^a
        out of the gradient while phi still receives it (section 4.3: theta^a fixed)."""
        layer = self.mu_layer
        w: torch.Tensor
        b: torch.Tensor | None
        if isinstance(layer, BayesianLinear):
            w, b = layer.weight_mu, layer.bias_mu
        else:
            w, b = layer.weight, layer.bias
        if detach_weights:
            w, b = w.detach(), None if b is None else b.detach()
        return F.linear(phi_BD, w, b)

    def value(self, obs_BO: torch.Tensor) -> torch.Tensor:
        """V(s) = max_a Q(s, a)."""
        return self.head.v(self.torso(obs_BO)).squeeze(-1)

    def q(
        self, obs_BO: torch.Tensor, action_BA: torch.Tensor, freeze_mu: bool
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Q(s, a) of Eq. 4 with mu at the posterior mean, and the mu-layer's pre-tanh output."""
        phi_BD = self.torso(obs_BO)
        v_B, l_BAA = self.head(phi_BD)
        out_BA = self.mu_out_mean(phi_BD, detach_weights=freeze_mu)
        return naf_q(v_B, self.mu_from_out(out_BA), l_BAA, action_BA), out_BA


@dataclass
class NAFCounters(Counters):
    td_steps: int = 0  # TD updates made
    elbo_rounds: int = 0  # ELBO updates of the mu-layer posterior (every M steps)
    draws: int = 0  # weight draws made for acting (one per step)
    q_variance: float = float("nan")  # mu-layer output variance at the latest ELBO update
    elbo_nll: float = float("nan")
    elbo_kl: float = float("nan")


@torch.no_grad()
def soft_update(target: nn.Module, online: nn.Module, tau: float) -> None:
    """theta' <- tau theta + (1 - tau) theta' (Algorithm 3 line 11)."""
    for p_target, p in zip(target.parameters(), online.parameters(), strict=True):
        p_target.lerp_(p, tau)


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
        self.net_target = copy.deepcopy(self.net).requires_grad_(False)
        # The TD loss trains theta, theta_V, theta_P; the mu-layer too unless it is Bayesian.
        self.td_params = [*self.net.torso.parameters(), *self.net.head.parameters()]
        if not self.bayesian:
            self.td_params += list(self.net.mu_layer.parameters())
        self.opt = make_optimizer(self.td_params, cfg)
        self.elbo_opt: torch.optim.Optimizer | None = None
        if isinstance(self.net.mu_layer, BayesianLinear):
            layer = self.net.mu_layer
            self.elbo_opt = torch.optim.Adam(
                [
                    {"params": [layer.weight_mu, layer.bias_mu], "lr": n.elbo_lr},
                    {"params": [layer.weight_rho, layer.bias_rho], "lr": n.elbo_rho_lr},
                ],
                foreach=True,  # as make_optimizer: the same arithmetic in one call
            )
        self.replay = make_replay(
            cfg, obs_space, frame_stack, seed=cfg.seed + 1, act_space=act_space
        )
        self.rng = np.random.default_rng(cfg.seed + 2)
        self.gen = torch.Generator(device=device)
        self.gen.manual_seed(cfg.seed + 3)
        self.her = None
        if n.her:
            from farsighter.envs.factory import goal_spec

            self.her = goal_spec(cfg)
        self.ou_EA = np.zeros((cfg.num_envs, self.action_dim), dtype=np.float64)

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
            action_EA = action_EA + self._noise(n) * self.half_range_A
        return np.clip(action_EA, self.low_A, self.high_A).astype(np.float32)

    def _noise(self, n: int) -> np.ndarray:
        naf = self.cfg.naf
        if naf.noise == "gaussian":
            return self.rng.normal(0.0, naf.noise_std, size=(n, self.action_dim))
        if self.ou_EA.shape[0] != n:
            self.ou_EA = np.zeros((n, self.action_dim))
        self.ou_EA += -naf.ou_theta * self.ou_EA + naf.noise_std * self.rng.normal(
            size=self.ou_EA.shape
        )
        return self.ou_EA.copy()

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
        done_E = np.logical_or(step.terminated_E, step.truncated_E)
        if self.ou_EA.shape[0] == len(done_E):
            self.ou_EA[done_E] = 0.0  # a new episode starts the OU process afresh

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
            soft_update(self.net_target, self.net, cfg.naf.tau)  # Algorithm 3 line 11, literally
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

    @torch.no_grad()
    def td_targets(self, t: TensorBatch) -> torch.Tensor:
        """y = r^k + gamma^n (1 - terminal) V'(s_{t+n}) from the target network."""
        return naf_td_target(t.returns_B, t.bootstrap_B, self.net_target.value(t.next_obs_B))

    def update(self) -> torch.Tensor | None:
        """One TD step on theta, theta_V, theta_P (+ the plain mu-layer), then the soft target
        update. A Bayesian mu-layer is used at its posterior mean and left unchanged."""
        t = self._sample(self.cfg.batch_size)
        if t is None:
            return None
        y_B = self.td_targets(t)
        q_B, out_BA = self.net.q(t.obs_B, t.actions_B, freeze_mu=self.bayesian)
        loss = td_loss(q_B, y_B, self.cfg.loss)
        if not self.bayesian:  # keep tanh(mu) out of saturation (NAFConfig.mu_penalty)
            loss = loss + self.cfg.naf.mu_penalty * out_BA.pow(2).mean()
        clip_and_step(loss, self.td_params, self.opt, self.cfg.max_grad_norm)
        if self.cfg.naf.soft_update == "every_update":
            soft_update(self.net_target, self.net, self.cfg.naf.tau)
        self.counters.td_steps += 1
        return loss.detach()

    def elbo_update(self) -> torch.Tensor | None:
        """Every M steps: fit the Bayesian mu-layer's posterior q(theta^a) on the ELBO of Eq. 10.

        Reading of Eq. 10 (SPEC 2.2): loss = KL(q || prior) - E_q[log p(y | theta^a)], where the
        data are the TD targets y_i = r^k + gamma^n (1 - terminal) V'(s') of a replay minibatch
        (the same targets as the TD update) and the likelihood is Gaussian,
        y_i ~ N(Q(s_i, a_i | theta^a), sigma_eps^2), with Q of Eq. 4 evaluated at the STORED
        action a_i, with the frozen representation, V and P, and with mu = scale(tanh(output))
        of the mu-layer under weights drawn from q (local reparameterisation, one draw per row).
        phi, V, L and y are computed without gradient and only the mu-layer is in the
        optimiser, so theta, theta_V, theta_P cannot move. The KL is divided by the number of
        replay rows (``elbo_loss``'s per-datum form). The mu-layer's means thereby follow the NAF
        TD gradient, and its variances shrink only where the targets pin mu down.
        """
        assert isinstance(self.net.mu_layer, BayesianLinear) and self.elbo_opt is not None
        cfg, naf = self.cfg, self.cfg.naf
        layer = self.net.mu_layer
        num_data = max(1, len(self.replay))
        loss: torch.Tensor | None = None
        phi_BD: torch.Tensor | None = None
        for _ in range(naf.elbo_steps):
            t = self._sample(naf.elbo_batch)
            if t is None:
                break
            with torch.no_grad():
                y_B = self.td_targets(t)
                phi_BD = self.net.torso(t.obs_B)
                v_B, l_BAA = self.net.head(phi_BD)
            # predict_fn(out) = Q(s_i, a_i | mu = scale(tanh(out))) with V and P frozen.
            terms = elbo_terms(
                layer,
                phi_BD,
                partial(self._q_at, v_B, l_BAA, t.actions_B),
                y_B,
                naf.noise_std_eps,
                num_data,
                kl_weight=naf.kl_weight,
                generator=self.gen,
            )
            # The same pre-tanh penalty as naf's TD loss, on the posterior mean's output.
            mean_out_BA = F.linear(phi_BD, layer.weight_mu, layer.bias_mu)
            total = terms.loss + naf.mu_penalty * mean_out_BA.pow(2).mean()
            clip_and_step(total, list(layer.parameters()), self.elbo_opt, cfg.max_grad_norm)
            loss = terms.loss.detach()
            self.counters.elbo_nll = float(terms.nll.detach())
            self.counters.elbo_kl = float(terms.kl.detach())
        if phi_BD is None:
            return None
        with torch.no_grad():
            self.counters.q_variance = float(layer.output_mean_var(phi_BD)[1].mean())
        adapt_k(self.counters, self.counters.q_variance, cfg.adaptive_k, self.replay)
        return loss

    def _q_at(
        self, v_B: torch.Tensor, l_BAA: torch.Tensor, action_BA: torch.Tensor, out_BA: torch.Tensor
    ) -> torch.Tensor:
        """Q(s, a) of Eq. 4 for a given mu-layer output (V and L given)."""
        return naf_q(v_B, self.net.mu_from_out(out_BA), l_BAA, action_BA)

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

    def state_dict(self, include_replay: bool = True) -> dict[str, Any]:
        return save_state(self, self.SAVED, include_replay)

    def load_state_dict(self, state: dict[str, Any]) -> None:
        load_state(self, self.SAVED, state)


AGENT: AgentFactory = NAFAgent  # the class farsighter.algorithms names; mypy checks the protocol
