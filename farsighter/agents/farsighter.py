"""Farsighter (paper sections 4.2, 4.4, 4.5; Algorithms 1 and 2) and BDQN, its k = 1 case.

Q(s, a) = phi_theta(s)^T w_a with a Bayesian linear regression posterior over each w_a (Eq. 9).

* Acting (Algorithm 2): a Thompson draw w_a = mean_a + chol(Cov_a) z (Eq. 7), one independent z
  per action and per environment; Farsighter draws afresh at every step, BDQN every T steps;
  ``blr.redraw`` also holds a draw for k steps, for a whole episode, or until the episode
  revisits a state (farsighter.exploration). Before
  ``learning_starts`` actions are uniform, as for the epsilon agents.
* Learning theta (Eq. 8): the double-Q loss with w fixed at the posterior mean, on k-step
  returns with gamma^k bootstraps (section 4.4), from the latest N transitions (Algorithm 1
  line 4) when ``sample_recent``. With ``blr.target = sample`` a posterior draw per row is added
  to the next state's Q in the target (optimism that propagates), and with ``k_target = max``
  the target is never below the one-step target (both our extensions). Target network and
  target mean are copied every N steps, after the posterior refresh when both fall on one step
  (Algorithm 1 lines 6 then 8).
* Posterior (Algorithm 1 line 6): every M steps, from up to D recent tuples with features of the
  current theta and targets y from the target network exactly as in Eq. 8 (batch mode), or from
  running sufficient statistics (incremental mode, the online update the paper's appendix 10
  names as the remedy for the rescan): every representation update adds its minibatch's
  features and Eq. 8 targets, which it computes anyway, weighted train_every / batch_size so that
  one environment step contributes unit weight on average; a refresh then costs O(|A| d^3).
* Adaptive k (Algorithm 1 line 7): after each refresh, the Q-variance (mean of
  phi^T Cov_a phi at the greedy action over the refresh states) moves k by one towards the
  variance target; the replay is emptied when k changes (optional).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import nn

from farsighter.agents.common import (
    Counters,
    RecentRows,
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
    sync_target,
    td_loss,
    to_device,
    updates_owed,
)
from farsighter.agents.cuda_graph import (
    Tensors,
    graphs_enabled,
    reset_step,
    set_capturable,
    wrap_step,
)
from farsighter.agents.protocol import AgentFactory
from farsighter.config import Config
from farsighter.exploration import ThompsonExploration
from farsighter.networks import make_torso, online_and_target
from farsighter.ops.blr import BLRHead, greedy_predictive_variance
from farsighter.ops.targets import double_q_target
from farsighter.replay import Batch, VectorStep
from farsighter.replay.target_cache import TargetCache, target_cache_rows

FEATURE_CHUNK = 4_096  # rows per forward pass when computing features for a posterior refresh
RECENT_FEATURES = 2_048  # incremental mode: minibatch features kept for adaptive k's Q-variance


@dataclass
class FarsighterCounters(Counters):
    refreshes: int = 0  # posterior refreshes made (every M steps)
    draws: int = 0  # Thompson draws made (one per environment and acting step with redraw=step)
    steps_since_draw: int = 0  # acting steps since the held draw (redraw = every, k)
    q_variance: float = float("nan")  # at the latest refresh (adaptive k's signal)


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
            scale=b.scale,
            device=device,
        )
        self.head.set_mean(init_AD.to(device))
        self.target_mean_AD = self.head.mean_AD.clone()
        self.opt = make_optimizer(self.torso.parameters(), cfg)
        # The update as a CUDA graph on a GPU (cfg.cuda_graph), or compiled (cfg.compile):
        # farsighter.agents.cuda_graph.
        # What it reads between updates changes in place: torso parameters, the target torso
        # (load_state_dict copies), head.mean_AD and target_mean_AD (copied into).
        self.graphs = graphs_enabled(cfg.cuda_graph, device, supported=not cfg.compile)
        set_capturable(self.opt, self.graphs)
        self.step = wrap_step(self._step, self.graphs, cfg.compile)
        self.replay = make_replay(cfg, obs_space, frame_stack, seed=cfg.seed + 1, device=device)
        # target features of sampled next states, kept until the next target copy (eager only:
        # a captured or compiled step runs the target network inside it)
        cached = (
            cfg.target_cache == "auto" and cfg.sample_recent and not (self.graphs or cfg.compile)
        )
        self.target_cache = (
            TargetCache(cfg.num_envs, target_cache_rows(cfg), self.torso.out_dim, device)
            if cached
            else None
        )
        self.rng = np.random.default_rng(cfg.seed + 2)
        self.gen = torch.Generator(device=device)
        self.gen.manual_seed(cfg.seed + 3)

        self.counters = FarsighterCounters(k=cfg.k)
        # Incremental mode: recent minibatch features, for the Q-variance of adaptive k.
        self.recent_phi = RecentRows(RECENT_FEATURES)
        # Eq. 7: each environment's weight draw and when it is replaced (blr.redraw).
        self.exploration = ThompsonExploration(cfg, self.head, self.counters)

    # ------------------------------------------------------------------ acting
    def act(self, obs_E: np.ndarray, global_step: int, explore: bool = True) -> np.ndarray:
        n = obs_E.shape[0]
        if explore and global_step < self.cfg.learning_starts:
            return np.asarray(self.rng.integers(0, self.num_actions, size=n))
        with torch.no_grad():
            phi_ED = self.torso(obs_tensor(obs_E, self.device))
            if explore:  # Algorithm 2: Thompson sampling under each environment's draw
                q_EA = self.exploration.q(phi_ED, obs_E, self.gen)
            else:  # evaluation: greedy under the posterior mean
                q_EA = phi_ED @ self.head.mean_AD.T
        return q_EA.argmax(dim=1).cpu().numpy()

    @torch.no_grad()
    def q_estimate(self, obs_B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Posterior mean of Q(s, .) and its predictive variance phi^T Cov_a phi (Eq. 7, 9)."""
        phi_BD = self.torso(obs_tensor(obs_B, self.device))
        mean_BA = phi_BD @ self.head.mean_AD.T
        return mean_BA.cpu().numpy(), self.head.predictive_var(phi_BD).cpu().numpy()

    def observe(self, step: VectorStep) -> None:
        self.replay.add_step(step)
        self.exploration.observe(np.logical_or(step.terminated_E, step.truncated_E))

    # ------------------------------------------------------------------ learning
    def learn(self, global_step: int) -> dict[str, torch.Tensor]:
        cfg, c = self.cfg, self.counters
        metrics: dict[str, torch.Tensor] = {}
        for _ in range(updates_owed(c, cfg, global_step)):
            loss = self.update()
            if loss is not None:
                metrics["td_loss"] = loss
        # Algorithm 1's order: the posterior refresh (line 6) comes before the target copy
        # (line 8), so on a step where both fall the target mean is the fresh posterior mean
        # (the BDQN code also sets E_W_target = E_W right after its regression).
        if global_step >= cfg.learning_starts and crossed(
            c, "refreshes", global_step, cfg.blr.posterior_every
        ):
            self.refresh_posterior()
        if sync_target(c, global_step, cfg.target_update_every, (self.torso, self.torso_target)):
            self.target_mean_AD.copy_(self.head.mean_AD)  # Algorithm 1 line 8
            if self.target_cache is not None:
                self.target_cache.clear()
        return metrics

    def _sample(self) -> Batch | None:
        cfg = self.cfg
        try:
            return sample_minibatch(self.replay, cfg, cfg.batch_size, self.counters.k)
        except ValueError:  # not enough complete k-step windows yet
            return None

    @torch.no_grad()
    def _targets(
        self,
        t: TensorBatch,
        w_online_AD: torch.Tensor | None = None,
        z_BAD: torch.Tensor | None = None,
        phi_next_target: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """y = r^k + gamma^k phi_target(s')^T mean_target[a*] (Eq. 8 with k-step returns).

        a* is the argmax under the online features and the posterior mean (Eq. 8), or under the
        latest acting Thompson draw when ``blr.target = thompson`` (the BDQN authors' code).
        ``w_online_AD`` (that draw) and ``z_BAD`` (the normals of ``blr.target = sample``) are
        drawn here unless given (:meth:`_draws`, for the captured update); ``phi_next_target``
        (the target features of s', from the target cache) likewise."""
        if phi_next_target is None:
            phi_next, phi_next_target = online_and_target(
                self.torso, self.torso_target, t.next_obs_B
            )
        else:
            phi_next = self.torso(t.next_obs_B)
        if w_online_AD is None:
            thompson = self.cfg.blr.target == "thompson"
            w_online_AD = self.exploration.acting_draw(self.gen) if thompson else self.head.mean_AD
        q_next_online = phi_next @ w_online_AD.T
        q_next_target = phi_next_target @ self.target_mean_AD.T
        if self.cfg.blr.target == "sample":
            noise_BA = self.head.q_noise(phi_next_target, generator=self.gen, z_BAD=z_BAD)
            q_next_online = q_next_online + noise_BA
            q_next_target = q_next_target + noise_BA
        return double_q_target(t.returns_B, t.bootstrap_B, q_next_online, q_next_target)

    @torch.no_grad()
    def _posterior_targets(self, t: TensorBatch) -> torch.Tensor:
        """Regression targets of a posterior refresh: Eq. 8's (``blr.posterior_target = double``)
        or y = r^k + gamma^k max_a phi_target(s')^T mean_target_a (``max``, the BDQN code)."""
        if self.cfg.blr.posterior_target == "double":
            return self._targets(t)
        q_next_target = self.torso_target(t.next_obs_B) @ self.target_mean_AD.T
        return t.returns_B + t.bootstrap_B * q_next_target.max(dim=1).values

    def update(self) -> torch.Tensor | None:
        """One step on theta with w at the posterior mean (Eq. 8); the BLR weights stay fixed."""
        batch = self._sample()
        if batch is None:
            return None
        t = batch_tensors(batch, self.device)
        inputs = t.tensors()
        if self.cfg.k_target == "max" and self.counters.k > 1:
            # The larger of the k-step and the one-step target of the same start (lower-bound
            # Q-learning, Tang 2020): see Config.k_target. Same s and a, so only s', r, gamma.
            one = self.replay.gather(batch.env_index, batch.index, 1, self.cfg.gamma)
            inputs.update(
                one_next_obs_B=obs_tensor(one.next_obs, self.device),
                one_returns_B=to_device(one.returns, self.device),
                one_bootstrap_B=to_device(one.bootstrap, self.device),
            )
            if self.target_cache is not None:
                inputs["one_phi_next_target_BD"] = self._target_features(
                    batch.env_index, batch.index + one.steps, inputs["one_next_obs_B"]
                )
        if self.target_cache is not None:
            inputs["phi_next_target_BD"] = self._target_features(
                batch.env_index, batch.index + batch.steps, inputs["next_obs_B"]
            )
        out = self.step({**inputs, **self._draws(len(batch.actions), "one_next_obs_B" in inputs)})
        if self.cfg.blr.mode == "incremental":
            self._accumulate(out["phi_BD"], t.actions_B, out["y_post_B"])
        return out["loss"]

    @torch.no_grad()
    def _target_features(
        self, e_B: np.ndarray, next_B: np.ndarray, next_obs_B: torch.Tensor
    ) -> torch.Tensor:
        """phi_target(s') of a minibatch's next states (logical rows ``next_B``), through the
        target cache: the target network runs over the rows not stored since the last copy."""
        assert self.target_cache is not None
        return self.target_cache.lookup(
            e_B, next_B, lambda i: self.torso_target(next_obs_B[torch.from_numpy(i)])
        )

    def _draws(self, rows: int, one_step: bool) -> Tensors:
        """What a target draws, drawn before the update so a captured step takes it as input: the
        acting draw (``blr.target = thompson``), or the normals of the k-step target and then of
        the one-step target (``sample``), in the order the eager targets draw them."""
        target = self.cfg.blr.target
        if target == "thompson":
            return {"w_online_AD": self.exploration.acting_draw(self.gen)}
        if target != "sample":
            return {}
        draws = {"z_BAD": self.head.noise_z(rows, self.gen)}
        if one_step:
            draws["one_z_BAD"] = self.head.noise_z(rows, self.gen)
        return draws

    def _step(self, inputs: Tensors) -> Tensors:
        """The update on a minibatch already on the device (captured whole on a GPU): the
        target, the loss at the posterior mean, and the optimizer step on theta."""
        t = TensorBatch.of(inputs)
        w = inputs.get("w_online_AD")
        y_B = self._targets(t, w, inputs.get("z_BAD"), inputs.get("phi_next_target_BD"))
        if "one_next_obs_B" in inputs:  # k_target = max
            one = TensorBatch(
                obs_B=t.obs_B,
                next_obs_B=inputs["one_next_obs_B"],
                actions_B=t.actions_B,
                returns_B=inputs["one_returns_B"],
                bootstrap_B=inputs["one_bootstrap_B"],
            )
            y_B = torch.maximum(
                y_B,
                self._targets(
                    one, w, inputs.get("one_z_BAD"), inputs.get("one_phi_next_target_BD")
                ),
            )
        phi_BD = self.torso(t.obs_B)
        q_B = (phi_BD @ self.head.mean_AD.T).gather(1, t.actions_B[:, None])[:, 0]
        loss = td_loss(q_B, y_B, self.cfg.loss)
        clip_and_step(loss, list(self.torso.parameters()), self.opt, self.cfg.max_grad_norm)
        out = {"loss": loss.detach()}
        if self.cfg.blr.mode == "incremental":  # the statistics are added outside the step
            double = self.cfg.blr.posterior_target == "double"
            out["phi_BD"] = phi_BD.detach()
            out["y_post_B"] = y_B if double else self._posterior_targets(t)
        return out

    def _accumulate(self, phi_BD: torch.Tensor, a_B: torch.Tensor, y_B: torch.Tensor) -> None:
        """Add a minibatch to the running statistics with weight w = train_every / batch_size
        (scaling phi and y by sqrt(w) scales Phi Phi^T and Phi y by w)."""
        root_w = (self.cfg.train_every / self.cfg.batch_size) ** 0.5
        self.head.accumulate(phi_BD * root_w, a_B, y_B * root_w)
        self.recent_phi.add(phi_BD)

    @torch.no_grad()
    def _features_and_targets(
        self, e_N: np.ndarray, l_N: np.ndarray
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Features of the current theta and Eq. 8 targets of the valid k-step tuples starting at
        the given rows, gathered chunk by chunk (stacked frames are never all in memory)."""
        phis, actions, ys = [], [], []
        for lo in range(0, len(e_N), FEATURE_CHUNK):
            part = self.replay.sample_indices(
                e_N[lo : lo + FEATURE_CHUNK],
                l_N[lo : lo + FEATURE_CHUNK],
                self.counters.k,
                self.cfg.gamma,
                stride=self.counters.k if self.cfg.stride else 1,  # Algorithm 1: one tuple per k
                on_device=True,  # from the device mirror when the replay keeps one
            )
            if len(part.actions) == 0:
                continue
            t = batch_tensors(part, self.device)
            phis.append(self.torso(t.obs_B))
            actions.append(t.actions_B)
            ys.append(self._posterior_targets(t))
        if not phis:
            empty = torch.zeros(0, device=self.device)
            return empty, empty.long(), empty
        return torch.cat(phis), torch.cat(actions), torch.cat(ys)

    def refresh_posterior(self) -> None:
        """Algorithm 1 line 6 (and line 7 with adaptive k)."""
        cfg = self.cfg
        if cfg.blr.mode == "batch":
            d = cfg.blr.posterior_samples
            if cfg.blr.posterior_sampling == "uniform":  # the BDQN code: whole buffer, replaced
                e_N, l_N = self.replay.uniform_indices(d, self.rng)
            else:  # the latest D tuples; with stride one is stored per k steps, so k D rows
                e_N, l_N = self.replay.recent_indices(d * (self.counters.k if cfg.stride else 1))
            phi_ND, a_N, y_N = self._features_and_targets(e_N, l_N)
            if len(a_N) == 0:
                return
            self.head.fit(phi_ND, a_N, y_N)  # statistics reset each refresh, as in BDQN's code
        else:  # the statistics are already up to date: no features are recomputed
            recent = self.recent_phi.rows()
            if recent is None:
                return
            self.head.refresh()
            phi_ND = recent
        self.counters.q_variance = greedy_predictive_variance(self.head, phi_ND)
        adapt_k(self.counters, self.counters.q_variance, cfg.adaptive_k, self.replay)

    def diagnostics(self) -> dict[str, float]:
        return {
            "k": float(self.counters.k),
            "q_variance": self.counters.q_variance,
            "posterior_refreshes": float(self.head.num_refreshes),
            "jitter_events": float(self.head.jitter_events),
            "noise_std": self.head.noise_std,
        }

    # ------------------------------------------------------------------ checkpoints
    SAVED = (
        "torso",
        "torso_target",
        "head",
        "target_mean_AD",
        "opt",
        "rng",
        "gen",
        "exploration",
        "target_cache",
        "recent_phi",
        "counters",
    )

    def state_dict(self, include_replay: bool = True) -> dict[str, Any]:
        state = save_state(self, self.SAVED, include_replay)
        if not include_replay:
            state["target_cache"] = None  # keyed by replay rows: of no use without them
        return state

    def load_state_dict(self, state: dict[str, Any]) -> None:
        # The draws and the target cache are kept when they can be: a checkpoint from before
        # them, or saved with another target_cache or compile setting, starts them afresh.
        own = ("exploration", "target_cache")
        load_state(self, [n for n in self.SAVED if n not in own], state)
        # a checkpoint from before the exploration object holds its pieces under our own keys
        self.exploration.load_state_dict(state.get("exploration", state))
        if self.target_cache is not None:  # saved without the replay: None (see state_dict)
            self.target_cache.load_state_dict(state.get("target_cache"))
        set_capturable(self.opt, self.graphs)
        reset_step(self.step)  # the optimizer's state tensors are new ones


AGENT: AgentFactory = (
    FarsighterAgent  # the class farsighter.algorithms names; mypy checks the protocol
)
