"""Farsighter and BDQN for S seeds at once: ``FarsighterAgent``'s math with the torsos stacked
along a seed axis (:mod:`farsighter.stacked`): one forward pass gives every seed's features, one
backward pass and one optimizer step update every seed's torso.

The rest is per seed, and the agent alone's own code (:mod:`farsighter_loss`'s and
:mod:`farsighter_posterior`'s functions): its posterior, Thompson draws, redraw rule, target cache
(over its own streams), generators (replay seed + 1, numpy seed + 2, torch seed + 3) and
counters, and Eq. 8 on its slice of the features. On CPU each seed trains bit for bit as it
trains alone (``tests/test_seeds.py``); :meth:`member` is one seed seen as an agent, with the
checkpoint of the run alone. Adaptive k, which moves each seed's k on its own, trains in turn.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import partial

import gymnasium as gym
import numpy as np
import torch

from farsighter.agents.common import (
    TensorBatch,
    batch_tensors,
    crossed,
    make_optimizer,
    minibatch_args,
    obs_tensor,
    td_loss,
    updates_owed,
)
from farsighter.agents.cuda_graph import Tensors
from farsighter.agents.farsighter_parts import FarsighterSeedMember, NextFeatures, SeedParts
from farsighter.agents.farsighter_posterior import (
    accumulate,
    refresh_posterior,
    replay_rows,
    seeded_torso,
)
from farsighter.agents.farsighter_targets import (
    Targets,
    max_targets,
    one_step_inputs,
    q_taken,
    uses_one_step,
)
from farsighter.agents.seed_members import seed_replay, stack_refusal
from farsighter.config import Config
from farsighter.exploration import optimism
from farsighter.replay import Batch, VectorStep
from farsighter.stacked import (
    StackedQNetwork,
    clip_per_seed,
)

Features = dict[str, tuple[torch.Tensor, NextFeatures]]
"""phi(s') and phi_target(s') of every seed, (S, B, D) each (phi_target a list of S from the
target caches), of the k-step windows ('') and the one-step windows ('one_') of k_target max."""


def supports(cfg: Config, obs_space: gym.Space | None, device: torch.device) -> str:
    """Why ``cfg`` cannot train as a seed batch here ('' when it can)."""
    if cfg.adaptive_k.enabled:
        return "adaptive k trains its seeds one at a time (each seed's k moves on its own)"
    return stack_refusal(cfg, obs_space)


class SeedBatchFarsighter:
    """S Farsighter (or BDQN) agents of one config (``cfgs`` differ only in seed) as one
    computation."""

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

        built = [seeded_torso(c, obs_space, self.num_actions) for c in cfgs]  # as alone
        torsos = [torso for torso, _ in built]
        self.dim = int(torsos[0].out_dim)
        self.torso = StackedQNetwork(torsos).to(device)  # refuses torsos it cannot stack
        self.torso_target = StackedQNetwork(torsos).to(device)
        self.torso_target.requires_grad_(False)
        self.params = list(self.torso.parameters())
        self.opt = make_optimizer(self.params, cfg)
        self.parts = [
            SeedParts(c, self.num_actions, self.dim, init_AD, device)
            for c, (_, init_AD) in zip(cfgs, built, strict=True)
        ]
        for cache in (p.cache for p in self.parts if p.cache is not None):
            # a copy into the target torsos empties every seed's cache (as CachedTarget's does)
            self.torso_target.register_load_state_dict_post_hook(lambda m, k, c=cache: c.clear())
        self.replay = seed_replay(cfgs, obs_space, device)
        # k_target cut (now or after blr.optimism's switch): each seed's exploratory actions
        self.records = optimism.records_exploratory(cfg)
        self.exploratory_SE: np.ndarray | None = None

    @property
    def seeds(self) -> int:
        return len(self.cfgs)

    # ------------------------------------------------------------------ acting
    def act(self, obs_S: Sequence[np.ndarray], global_step: int) -> np.ndarray:
        """Each seed's actions, (S, E): uniform from its generator before ``learning_starts``,
        then Thompson sampling under its own draws (Algorithm 2)."""
        obs_SE = np.stack(obs_S)
        n = obs_SE.shape[1]
        if global_step < self.cfg.learning_starts:
            if self.records:  # uniform actions are all exploratory
                self.exploratory_SE = np.ones((self.seeds, n), dtype=bool)
            return np.stack([p.rng.integers(0, self.num_actions, size=n) for p in self.parts])
        with torch.no_grad():
            phi_SED = self.torso(obs_tensor(obs_SE, self.device))
            parts = list(enumerate(self.parts))
            actions = [p.exploration.actions(phi_SED[s], obs_SE[s], p.gen) for s, p in parts]
            if self.records:  # where a seed's draw chose otherwise than its mean would
                m, rel = self.cfg.blr.cut_margin, optimism.cut_relative(self.cfg)
                mark = optimism.exploratory_actions
                self.exploratory_SE = np.stack(
                    [mark(p.head, phi_SED[s], actions[s], m, rel) for s, p in parts]
                )
        return torch.stack(actions).cpu().numpy()

    def observe(self, steps: Sequence[VectorStep]) -> None:
        """One vector step of every seed, in seed order."""
        self.replay.add_steps(steps, self.exploratory_SE if self.records else None)
        for s, (p, st) in enumerate(zip(self.parts, steps, strict=True)):
            done = np.logical_or(st.terminated_E, st.truncated_E)
            turn, p.unpaid = optimism.switch_at(self.cfg, p.calibrated, p.unpaid, st.reward_E, done)
            if turn is not None:
                self.calibrate(s, on=turn)
            p.exploration.observe(done, st.reward_E, st.truncated_E)

    def calibrate(self, s: int, restart: bool = True, on: bool = True) -> None:
        """Seed ``s``'s switch (``FarsighterAgent.calibrate``): its targets, its streams' windows
        cut where its calibrated target is cut, and its posterior's restart."""
        p, streams = self.parts[s], self.replay.seed_streams(s)
        p.calibrate(restart=False, on=on)  # its targets; the windows cut before a refit reads them
        self.replay.cut_E[streams] = p.k_target == "cut"
        if restart and on:
            own = partial(self.torso.member_forward, s=s)
            args = (self.replay, self.cfg, p.counters.k, self.device, own, streams)
            rows = partial(replay_rows, *args) if p.counters.updates else None
            optimism.restart_at_switch(self.cfg, p.head, p.target_mean_AD, rows)

    # ------------------------------------------------------------------ learning
    def learn(self, global_step: int) -> list[dict[str, torch.Tensor]]:
        """The updates owed at ``global_step``, then each seed's posterior refresh and target
        copy in ``FarsighterAgent.learn``'s order; each seed's metrics as it gives them alone."""
        cfg = self.cfg
        owed = {updates_owed(p.counters, cfg, global_step) for p in self.parts}
        assert len(owed) == 1, "the seeds of a batch update together"
        metrics: list[dict[str, torch.Tensor]] = [{} for _ in self.parts]
        for _ in range(owed.pop()):
            losses = self.update()
            if losses is not None:
                metrics = [{"td_loss": loss} for loss in losses]
        # Algorithm 1's order for each seed: its refresh (line 6), then its target copy (line
        # 8). Every refresh first: one copy moves every seed's target torso at once.
        for s, p in enumerate(self.parts):
            if global_step >= cfg.learning_starts and crossed(
                p.counters, "refreshes", global_step, cfg.blr.posterior_every
            ):
                self._refresh(s, p)
        every = cfg.target_update_every  # (a list: every seed's counter moves)
        if any([crossed(p.counters, "target_syncs", global_step, every) for p in self.parts]):
            self.torso_target.load_state_dict(self.torso.state_dict())  # the seeds step together
            for p in self.parts:
                p.target_mean_AD.copy_(p.head.mean_AD)
        return metrics

    def update(self) -> list[torch.Tensor] | None:
        """One step on every seed's theta with its w at its posterior mean (Eq. 8); each seed's
        loss (``FarsighterAgent.update``'s, seed by seed)."""
        cfg, S, B = self.cfg, self.seeds, self.cfg.batch_size
        k = self.parts[0].counters.k
        try:
            batch = self.replay.sample_seeds(B, **minibatch_args(cfg, k))
        except ValueError:  # not enough complete k-step windows yet
            return None
        t = batch_tensors(batch, self.device)
        inputs: Tensors = t.tensors()
        # each seed's targets as alone (blr.optimism switches them seed by seed)
        one_step_S = [uses_one_step(p.k_target) and k > 1 for p in self.parts]
        one_step = any(one_step_S)
        ends = {"": batch.index + batch.steps}  # the logical rows of s', for the target caches
        if one_step:  # the larger of the k-step and the one-step target (FarsighterAgent.update)
            one_inputs, one = one_step_inputs(self.replay, batch, cfg.gamma, self.device)
            inputs.update(one_inputs)
            ends["one_"] = batch.index + one.steps

        def by_seed(x: torch.Tensor) -> torch.Tensor:
            return x.view(S, B, *x.shape[1:])

        with torch.no_grad():  # every seed's features of s' at once; each seed's targets
            features: Features = {}
            for prefix, end_B in ends.items():
                next_SB = by_seed(inputs[prefix + "next_obs_B"])
                psi = self.torso.psi(next_SB)  # online and target share the random layer
                features[prefix] = (
                    self.torso(next_SB, psi),
                    self._target_features(next_SB, end_B, batch, psi),
                )
        seeded = [{key: by_seed(x)[s] for key, x in inputs.items()} for s in range(S)]
        gaps = self._advantage(by_seed(t.obs_B), seeded)  # blr.advantage_learning
        ys = [
            gaps[s](p.targets(mine, features[""], features.get("one_"), s, one_step_S[s]))
            for s, (p, mine) in enumerate(zip(self.parts, seeded, strict=True))
        ]
        phi_SBD = self.torso(by_seed(t.obs_B))
        # each seed's slice by unbind: its backward stacks the S gradients once, where indexing
        # phi_SBD[s] S times would give each seed's gradient as a zero-filled (S, B, D) tensor
        # and add the S of them (S^2 B D of memory traffic; the same values)
        phi_S = phi_SBD.unbind(0)
        losses = [
            td_loss(q_taken(phi_S[s], p.head.mean_AD, mine["actions_B"]), y_B, cfg.loss)
            for s, (p, mine, y_B) in enumerate(zip(self.parts, seeded, ys, strict=True))
        ]
        self.opt.zero_grad(set_to_none=True)
        # each seed's gradient is its own loss's: d(sum)/d(loss_s) = 1 exactly
        torch.stack(losses).sum().backward()
        if cfg.max_grad_norm > 0:
            clip_per_seed(self.params, S, cfg.max_grad_norm)
        self.opt.step()
        if cfg.blr.mode == "incremental":  # FarsighterAgent.update's statistics, seed by seed
            for s, (p, mine, y_B) in enumerate(zip(self.parts, seeded, ys, strict=True)):
                if cfg.blr.posterior_target != "double":
                    y_B = max_targets(TensorBatch.of(mine), features[""][1][s], p.target_mean_AD)
                    y_B = gaps[s](y_B)
                accumulate(cfg, p.head, p.recent_phi, phi_S[s].detach(), mine["actions_B"], y_B)
        return [loss.detach() for loss in losses]

    @torch.no_grad()
    def _advantage(self, obs_SB: torch.Tensor, seeded: list[Tensors]) -> list[Targets]:
        """Each seed's :meth:`SeedParts.advantage`, from one forward of the target torsos."""
        on = self.cfg.blr.advantage_learning and any(p.calibrated for p in self.parts)
        phi_SBD = self.torso_target(obs_SB) if on else None
        return [
            p.advantage(None if phi_SBD is None else phi_SBD[s], mine["actions_B"])
            for s, (p, mine) in enumerate(zip(self.parts, seeded, strict=True))
        ]

    def _target_features(
        self,
        next_SB: torch.Tensor,
        end_B: np.ndarray,
        batch: Batch,
        psi: torch.Tensor | None = None,
    ) -> torch.Tensor | list[torch.Tensor]:
        """phi_target(s') of every seed: one batched forward (over the online torso's random
        features ``psi`` of s'), or each seed's target cache (``CachedTarget``'s lookup, the
        misses through its own target torso alone)."""
        if self.parts[0].cache is None:
            return self.torso_target(next_SB, psi)
        B, E = self.cfg.batch_size, self.cfg.num_envs
        return [  # each seed's own streams, numbered as alone
            p.target_features(
                next_SB[s],
                batch.env_index[s * B : (s + 1) * B] - s * E,
                end_B[s * B : (s + 1) * B],
                partial(self.torso_target.member_forward, s=s),
            )
            for s, p in enumerate(self.parts)
        ]

    def _refresh(self, s: int, p: SeedParts) -> None:
        """Algorithm 1 line 6 for one seed (``FarsighterAgent.refresh_posterior``): a batch-mode
        fit runs the seed's own networks over its own streams' rows."""
        cfg = self.cfg
        double = cfg.blr.posterior_target == "double"

        def targets(t: TensorBatch) -> torch.Tensor:  # FarsighterLoss.posterior_targets
            phi_next_target = self.torso_target.member_forward(t.next_obs_B, s)
            if not double:
                return max_targets(t, phi_next_target, p.target_mean_AD)
            draws = p.draws(len(t.actions_B), False)
            return p.y(t, self.torso.member_forward(t.next_obs_B, s), phi_next_target, draws)

        own = partial(self.torso.member_forward, s=s)
        args = (p.head, p.counters, p.recent_phi, self.replay, p.rng, self.device, own, targets)
        refresh_posterior(cfg, *args, self.replay.seed_streams(s))

    # ------------------------------------------------------------------ one seed
    def member(self, s: int) -> FarsighterSeedMember:
        return FarsighterSeedMember(self, s)


SEED_AGENTS = SeedBatchFarsighter
"""The class :func:`farsighter.agents.build_seed_agents` builds for seeds (``Algorithm.seed_batch``)."""
