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

Written once over a seed axis: S seeds of one config (S = 1 for a run alone) act, record and
learn as one computation: one forward of the torsos (:func:`farsighter.stacked.seed_network`: the
torso alone for S = 1, any architecture, precision, compiled or captured; stacked MLPs for
S > 1) and one optimizer step for every seed. The rest is each seed's own
(:class:`~farsighter.agents.farsighter_parts.SeedParts`: posterior, draws, counters, generators,
target cache), so on CPU each seed of a batch trains bit for bit as it trains alone
(``tests/training/test_seeds.py``). Adaptive k, which moves each seed's k on its own, trains its seeds one
at a time.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from functools import partial

import gymnasium as gym
import numpy as np
import torch

from farsighter.agents.common import (
    batch_tensors,
    crossed,
    minibatch_args,
    obs_tensor,
    updates_owed,
)
from farsighter.agents.cuda_graph import Tensors
from farsighter.agents.farsighter_loss import FarsighterLoss, seed_key
from farsighter.agents.farsighter_parts import FarsighterMember, SeedParts
from farsighter.agents.farsighter_posterior import (
    accumulate,
    fitted_dim,
    make_head,
    refresh_posterior,
    replay_rows,
    seeded_torso,
)
from farsighter.agents.farsighter_targets import one_step_inputs, uses_one_step
from farsighter.agents.learner import Learner
from farsighter.agents.protocol import SeedAgentsFactory
from farsighter.agents.seed_members import seed_replay, stack_refusal
from farsighter.config import Config
from farsighter.exploration import optimism
from farsighter.replay import VectorStep
from farsighter.stacked import seed_network


def supports(cfg: Config, obs_space: gym.Space | None, device: torch.device) -> str:
    """Why seeds of ``cfg`` cannot train as one batch here ('' when they can)."""
    if cfg.adaptive_k.enabled:
        return "adaptive k moves each seed's k on its own"
    return stack_refusal(cfg, obs_space)


class FarsighterAgent:
    """BLR-headed DQN with Thompson exploration over k steps (``bdqn`` is the k = 1 case), for
    S seeds of one config (``cfgs`` differ only in seed)."""

    def __init__(
        self,
        cfgs: Sequence[Config],
        obs_space: gym.spaces.Box,
        act_space: gym.spaces.Discrete,
        *,
        frame_stack: int = 1,
        device: torch.device,
    ) -> None:
        cfg = self.cfg = cfgs[0]
        self.cfgs, self.device, self.num_actions = list(cfgs), device, int(act_space.n)
        built = [seeded_torso(c, obs_space, self.num_actions) for c in cfgs]  # each seed's own
        torsos = [torso for torso, _ in built]
        dim, fit_dim = int(torsos[0].out_dim), fitted_dim(cfg, torsos[0])
        self.torso = seed_network(torsos).to(device)
        torso_target = seed_network([copy.deepcopy(torso) for torso in torsos]).to(device)
        self.parts = [
            SeedParts(c, make_head(c, self.num_actions, dim, init_AD, device, fit_dim), device)
            for c, (_, init_AD) in zip(cfgs, built, strict=True)
        ]
        # Eq. 8, with the target features of sampled next states kept until the next copy
        self.loss = FarsighterLoss(self.torso, torso_target, self.parts, cfg)
        capture = not cfg.blr.switches_update  # compiled where asked, not captured
        self.learner = Learner(
            self.loss, self.torso.parameters(), cfg, device, capture=capture, seeds=self.seeds
        )
        self.replay = seed_replay(cfgs, obs_space, device, frame_stack)
        # k_target cut (now or after blr.optimism's switch): each seed's exploratory actions
        self.cut = optimism.records_exploratory(cfg)
        self.exploratory_SE: np.ndarray | None = None

    @property
    def seeds(self) -> int:
        return len(self.cfgs)

    # ------------------------------------------------------------------ acting
    def act(self, obs_S: Sequence[np.ndarray], global_step: int) -> np.ndarray:
        """Each seed's actions, (S, E): uniform from its generator before ``learning_starts``,
        then Thompson sampling under its own draws (Algorithm 2)."""
        n = len(obs_S[0])
        if global_step < self.cfg.learning_starts:
            if self.cut:  # uniform actions are all exploratory
                self.exploratory_SE = np.ones((self.seeds, n), dtype=bool)
            return np.stack([p.rng.integers(0, self.num_actions, size=n) for p in self.parts])
        with torch.no_grad():
            obs = obs_S[0] if self.seeds == 1 else np.concatenate(obs_S)
            phi_S = self.torso.each_seed(obs_tensor(obs, self.device))
            parts = list(enumerate(self.parts))
            actions = [p.exploration.actions(phi_S[s], obs_S[s], p.gen) for s, p in parts]
            if self.cut:  # where a seed's draw chose otherwise than its mean would
                rel, mark = optimism.cut_relative(self.cfg), optimism.exploratory_actions
                self.exploratory_SE = np.stack(
                    [mark(p.head, phi_S[s], actions[s], rel) for s, p in parts]
                )
        return torch.stack(actions).cpu().numpy()

    def observe(self, steps: Sequence[VectorStep]) -> None:
        """One vector step of every seed, in seed order."""
        self.replay.add_steps(steps, self.exploratory_SE if self.cut else None)
        for s, (p, st) in enumerate(zip(self.parts, steps, strict=True)):
            if optimism.switch_at(self.cfg, p.calibrated, st.reward_E):
                self.calibrate(s)
            done = np.logical_or(st.terminated_E, st.truncated_E)
            p.exploration.observe(done, st.reward_E, st.truncated_E)

    def calibrate(self, s: int = 0, restart: bool = True) -> None:
        """Seed ``s``'s ``blr.optimism = until-reward`` switch (:meth:`SeedParts.calibrate`):
        its streams cut their windows from now on where its calibrated target is cut, and its
        posterior restarts (``blr.switch_restart``; ``restart = False``: a checkpoint's
        statistics, loaded, are kept)."""
        p, streams = self.parts[s], self.replay.seed_streams(s)
        p.calibrate()
        self.learner.forget_graphs()  # the calibrated loss branches (blr.advantage_learning)
        self.replay.cut_E[streams] = p.k_target == "cut"
        if restart:  # a refit reads features trained on the replay, else the prior
            own = partial(self.torso.member_forward, s=s)
            args = (self.replay, self.cfg, p.counters.k, self.device, own, streams)
            rows = partial(replay_rows, *args) if p.counters.updates else None
            optimism.restart_at_switch(self.cfg, p.head, p.target_mean_AD, rows)

    # ------------------------------------------------------------------ learning
    def learn(self, global_step: int) -> list[dict[str, torch.Tensor]]:
        """The updates owed at ``global_step``, then each seed's posterior refresh and target
        copy; each seed's latest TD loss when it updated."""
        cfg = self.cfg
        owed = {updates_owed(p.counters, cfg, global_step) for p in self.parts}
        assert len(owed) == 1, "the seeds of a batch update together"
        metrics: list[dict[str, torch.Tensor]] = [{} for _ in self.parts]
        for _ in range(owed.pop()):
            loss_S = self.update()
            if loss_S is not None:
                metrics = [{"td_loss": loss_S[s]} for s in range(self.seeds)]
        # Algorithm 1's order: the posterior refresh (line 6) comes before the target copy
        # (line 8), so on a step where both fall the target mean is the fresh posterior mean
        # (the BDQN code also sets E_W_target = E_W right after its regression).
        for s, p in enumerate(self.parts):
            if global_step >= cfg.learning_starts and crossed(
                p.counters, "refreshes", global_step, cfg.blr.posterior_every
            ):
                self.refresh_posterior(s)
        every = cfg.target_update_every  # (a list: every seed's counter moves)
        if any([crossed(p.counters, "target_syncs", global_step, every) for p in self.parts]):
            self.loss.copy_target()  # Algorithm 1 line 8, every seed at once
        return metrics

    def update(self) -> torch.Tensor | None:
        """One step on every seed's theta with its w at its posterior mean (Eq. 8; the BLR
        weights stay fixed); each seed's loss, (S,), or None before a complete window."""
        cfg, S, B = self.cfg, self.seeds, self.cfg.batch_size
        k = self.parts[0].counters.k
        try:
            batch = self.replay.sample_seeds(B, **minibatch_args(cfg, k))
        except ValueError:  # not enough complete k-step windows yet
            return None
        inputs = batch_tensors(batch, self.device).tensors()
        one_step_S = [uses_one_step(p.k_target) and k > 1 for p in self.parts]
        ends = {"": batch.index + batch.steps}  # the logical rows of s', for the target caches
        if any(one_step_S):
            # The larger of the k-step and the one-step target of the same start (lower-bound
            # Q-learning, Tang 2020): see Config.k_target. Same s and a, so only s', r, gamma.
            one_inputs, one = one_step_inputs(self.replay, batch, cfg.gamma, self.device)
            inputs.update(one_inputs)
            ends = {"one_": batch.index + one.steps, **ends}
        if self.parts[0].cache is not None:  # each seed's cache over its own streams
            E = cfg.num_envs
            for prefix, end_B in ends.items():
                obs = inputs[prefix + "next_obs_B"]
                found = [
                    p.lookup(
                        self.torso.by_seed(obs)[s],
                        batch.env_index[s * B : (s + 1) * B] - s * E,
                        end_B[s * B : (s + 1) * B],
                        partial(self.loss.torso_target.member_forward, s=s),
                    )
                    for s, p in enumerate(self.parts)
                ]
                inputs[prefix + "phi_next_target_BD"] = found[0] if S == 1 else torch.cat(found)
        for s, p in enumerate(self.parts):
            for name, x in p.draws(B, one_step_S[s]).items():
                inputs[seed_key(name, s)] = x
        out = self.learner(inputs)
        if cfg.blr.mode == "incremental":
            actions_S = self.torso.by_seed(inputs["actions_B"])
            for s, p in enumerate(self.parts):
                phi_BD, y_B = out[seed_key("phi_BD", s)], out[seed_key("y_post_B", s)]
                accumulate(cfg, p.head, p.recent_phi, phi_BD, actions_S[s], y_B)
        return out["loss_S"]

    def refresh_posterior(self, s: int = 0) -> None:
        """Algorithm 1 line 6 (and line 7 with adaptive k) for seed ``s``:
        :func:`refresh_posterior` with its own networks over its own streams' rows."""
        p = self.parts[s]
        double = self.cfg.blr.posterior_target == "double"  # Eq. 8's target draws

        def targets(t: object) -> torch.Tensor:
            rows = len(t.actions_B)  # type: ignore[attr-defined]
            draws: Tensors = p.draws(rows, False) if double else {}
            return self.loss.posterior_targets(t, draws, s)  # type: ignore[arg-type]

        own = partial(self.torso.member_forward, s=s)
        args = (p.head, p.counters, p.recent_phi, self.replay, p.rng, self.device, own, targets)
        refresh_posterior(self.cfg, *args, self.replay.seed_streams(s))

    # ------------------------------------------------------------------ one seed
    def member(self, s: int) -> FarsighterMember:
        return FarsighterMember(self, s)


SEED_AGENTS: SeedAgentsFactory = FarsighterAgent  # the class farsighter.algorithms names
