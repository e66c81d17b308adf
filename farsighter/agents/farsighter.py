"""Farsighter (paper sections 4.2, 4.4, 4.5; Algorithms 1 and 2) and BDQN, its k = 1 case.

Q(s, a) = phi_theta(s)^T w_a with a Bayesian linear regression posterior over each w_a (Eq. 9).

* Acting (Algorithm 2): a Thompson draw w_a = mean_a + chol(Cov_a) z (Eq. 7), one independent z
  per action and per environment; Farsighter draws afresh at every step, BDQN every T steps;
  ``blr.redraw`` also holds a draw for k steps, for a whole episode, or until the episode
  revisits a state (farsighter.exploration). Before ``learning_starts`` actions are uniform.
* Learning theta (Eq. 8): :class:`~farsighter.agents.farsighter_loss.FarsighterLoss`, on k-step
  minibatches from the latest N transitions (Algorithm 1 line 4) when ``sample_recent``. Target
  torso and target mean are copied every N steps, after the posterior refresh when both fall on
  one step (Algorithm 1 lines 6 then 8).
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

from functools import partial
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from farsighter.agents.common import (
    RecentRows,
    batch_tensors,
    crossed,
    load_state,
    make_replay,
    obs_tensor,
    sample_minibatch,
    save_state,
    updates_owed,
)
from farsighter.agents.cuda_graph import Tensors
from farsighter.agents.farsighter_loss import FarsighterLoss
from farsighter.agents.farsighter_posterior import (
    RECENT_FEATURES,
    FarsighterCounters,
    accumulate,
    make_head,
    refresh_posterior,
    replay_rows,
    seeded_torso,
)
from farsighter.agents.farsighter_targets import one_step_inputs, uses_one_step
from farsighter.agents.learner import Learner, make_target_cache
from farsighter.agents.protocol import AgentFactory
from farsighter.config import Config
from farsighter.exploration import ThompsonExploration
from farsighter.exploration.optimism import (
    cut_relative,
    exploratory_actions,
    records_exploratory,
    restart_at_switch,
    switch_at,
)
from farsighter.replay import VectorStep


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

        torso, init_AD = seeded_torso(cfg, obs_space, self.num_actions)
        self.torso = torso.to(device)
        self.head = make_head(cfg, self.num_actions, self.torso.out_dim, init_AD, device)
        # Eq. 8, with the target features of sampled next states kept until the next copy
        cache = make_target_cache(cfg, device, self.torso.out_dim)
        self.loss = FarsighterLoss(self.torso, self.head, cfg, cache)
        capture = not cfg.blr.switches_update  # compiled where asked, not captured
        self.learner = Learner(self.loss, self.torso.parameters(), cfg, device, capture=capture)
        self.replay = make_replay(cfg, obs_space, frame_stack, seed=cfg.seed + 1, device=device)
        self.rng = np.random.default_rng(cfg.seed + 2)
        self.gen = torch.Generator(device=device)
        self.gen.manual_seed(cfg.seed + 3)

        self.counters = FarsighterCounters(k=cfg.k)
        # Incremental mode: recent minibatch features, for the Q-variance of adaptive k.
        self.recent_phi = RecentRows(RECENT_FEATURES)
        # Eq. 7: each environment's weight draw and when it is replaced (blr.redraw).
        self.exploration = ThompsonExploration(cfg, self.head, self.counters)
        # k_target cut: whether each environment's latest training action was exploratory
        self.cut = records_exploratory(cfg)
        self.exploratory_E: np.ndarray | None = None
        self.unpaid = 0  # blr.rearm_episodes: episodes ended in a row without a reward

    # ------------------------------------------------------------------ acting
    def act(self, obs_E: np.ndarray, global_step: int, explore: bool = True) -> np.ndarray:
        n = obs_E.shape[0]
        if explore and global_step < self.cfg.learning_starts:
            if self.cut:  # uniform actions are all exploratory
                self.exploratory_E = np.ones(n, dtype=bool)
            return np.asarray(self.rng.integers(0, self.num_actions, size=n))
        with torch.no_grad():
            phi_ED = self.torso(obs_tensor(obs_E, self.device))
            if explore:  # Algorithm 2: Thompson sampling under each environment's draw
                actions_E = self.exploration.actions(phi_ED, obs_E, self.gen)
            else:  # evaluation: greedy under the posterior mean
                actions_E = (phi_ED @ self.head.mean_AD.T).argmax(dim=1)
            if explore and self.cut:  # the draw chose otherwise than the mean would
                self.exploratory_E = exploratory_actions(
                    self.head, phi_ED, actions_E, self.cfg.blr.cut_margin, cut_relative(self.cfg)
                )
        return actions_E.cpu().numpy()

    @torch.no_grad()
    def q_estimate(self, obs_B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Posterior mean of Q(s, .) and its predictive variance phi^T Cov_a phi (Eq. 7, 9)."""
        phi_BD = self.torso(obs_tensor(obs_B, self.device))
        mean_BA = phi_BD @ self.head.mean_AD.T
        return mean_BA.cpu().numpy(), self.head.predictive_var(phi_BD).cpu().numpy()

    def observe(self, step: VectorStep) -> None:
        self.replay.add_step(step, self.exploratory_E if self.cut else None)
        done_E = np.logical_or(step.terminated_E, step.truncated_E)
        turn, self.unpaid = switch_at(
            self.cfg, self.loss.calibrated, self.unpaid, step.reward_E, done_E
        )
        if turn is not None:
            self.calibrate(on=turn)
        self.exploration.observe(done_E, step.reward_E, step.truncated_E)

    def calibrate(self, restart: bool = True, on: bool = True) -> None:
        """``blr.optimism = until-reward``'s switch (:meth:`FarsighterLoss.calibrate`); the
        replay cuts its windows from now on where the calibrated target is cut, and the
        posterior restarts (``blr.switch_restart``; ``restart = False``: a checkpoint's
        statistics, loaded, are kept). ``on = False``: back to the optimism (rearmed)."""
        self.loss.calibrate(on)
        self.learner.forget_graphs()  # the calibrated loss branches (blr.advantage_learning)
        self.replay.cut_exploratory = self.loss.k_target == "cut"
        if restart and on:  # a refit reads features trained on the replay, else the prior
            args = (self.replay, self.cfg, self.counters.k, self.device, self.torso)
            rows = partial(replay_rows, *args) if self.counters.updates else None
            restart_at_switch(self.cfg, self.head, self.loss.target_mean_AD, rows)

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
        if crossed(c, "target_syncs", global_step, cfg.target_update_every):
            self.loss.copy_target()  # Algorithm 1 line 8
        return metrics

    def update(self) -> torch.Tensor | None:
        """One step on theta with w at the posterior mean (Eq. 8); the BLR weights stay fixed."""
        cfg = self.cfg
        try:
            batch = sample_minibatch(self.replay, cfg, cfg.batch_size, self.counters.k)
        except ValueError:  # not enough complete k-step windows yet
            return None
        inputs = batch_tensors(batch, self.device).tensors()
        if uses_one_step(self.loss.k_target) and self.counters.k > 1:
            # The larger of the k-step and the one-step target of the same start (lower-bound
            # Q-learning, Tang 2020): see Config.k_target. Same s and a, so only s', r, gamma.
            one_inputs, one = one_step_inputs(self.replay, batch, self.cfg.gamma, self.device)
            inputs.update(one_inputs)
            inputs.update(
                self.loss.target_features(
                    batch.env_index, batch.index + one.steps, inputs["one_next_obs_B"], "one_"
                )
            )
        inputs.update(
            self.loss.target_features(
                batch.env_index, batch.index + batch.steps, inputs["next_obs_B"]
            )
        )
        out = self.learner(
            {**inputs, **self._draws(len(batch.actions), "one_next_obs_B" in inputs)}
        )
        if self.cfg.blr.mode == "incremental":
            accumulate(
                self.cfg,
                self.head,
                self.recent_phi,
                out["phi_BD"],
                inputs["actions_B"],
                out["y_post_B"],
            )
        return out["loss"]

    def _draws(self, rows: int, one_step: bool = False) -> Tensors:
        """The draws of the targets of ``rows`` rows (:meth:`FarsighterLoss.draws`)."""
        return self.loss.draws(
            rows, one_step, self.gen, lambda: self.exploration.acting_draw(self.gen)
        )

    def refresh_posterior(self) -> None:
        """Algorithm 1 line 6 (and line 7 with adaptive k): :func:`refresh_posterior`."""
        double = self.cfg.blr.posterior_target == "double"  # Eq. 8's target draws
        refresh_posterior(
            self.cfg,
            self.head,
            self.counters,
            self.recent_phi,
            self.replay,
            self.rng,
            self.device,
            self.torso,
            lambda t: self.loss.posterior_targets(
                t, self._draws(len(t.actions_B)) if double else {}
            ),
        )

    def episode_diagnostics(self) -> dict[str, float]:
        """What an episode's metrics row reads (k), without the deferred Q-variance."""
        return {"k": float(self.counters.k)}

    def diagnostics(self) -> dict[str, float]:
        return {
            "k": float(self.counters.k),
            "q_variance": self.counters.settle().q_variance,
            "posterior_refreshes": float(self.head.num_refreshes),
            "jitter_events": float(self.head.jitter_events),
            "noise_std": self.head.noise_std,
            **({"act_scale": self.head.act_scale} if self.cfg.blr.act_width != "posterior" else {}),
        }

    # ------------------------------------------------------------------ checkpoints
    SAVED = ("torso", "torso_target", "head", "target_mean_AD", "opt", "rng", "gen", "counters")
    SAVED_AT = {  # keys of the earlier layout
        "torso_target": "loss.torso_target",
        "target_mean_AD": "loss.target_mean_AD",
        "opt": "learner",
    }

    def state_dict(self, include_replay: bool = True) -> dict[str, Any]:
        self.counters.settle()
        state = save_state(self, self.SAVED, include_replay)
        state["exploration"] = self.exploration.state_dict()
        state["recent_phi"] = self.recent_phi.state_dict()
        if self.cfg.blr.optimism != "always":  # the switch; a default run's keys as before
            state["calibrated"] = self.loss.calibrated
        if self.cfg.blr.rearm_episodes:
            state["unpaid"] = self.unpaid
        cache = self.loss.target.cache  # keyed by replay rows: of no use without them
        state["target_cache"] = None if cache is None or not include_replay else cache.state_dict()
        return state

    def load_state_dict(self, state: dict[str, Any]) -> None:
        load_state(self, self.SAVED, state)
        self.recent_phi.load_state_dict(state["recent_phi"])
        if state.get("calibrated", False) and not self.loss.calibrated:
            self.calibrate(restart=False)
        self.unpaid = state.get("unpaid", 0)
        # a checkpoint from before the exploration object holds its pieces under our own keys
        self.exploration.load_state_dict(state.get("exploration", state))
        # the target cache (cleared by the target's load) is kept when the checkpoint has it
        if self.loss.target.cache is not None:
            self.loss.target.cache.load_state_dict(state.get("target_cache"))


AGENT: AgentFactory = FarsighterAgent  # the class algorithms.py names; mypy checks the protocol
