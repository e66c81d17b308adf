"""DDQN and k-DDQN for S seeds at once: :class:`farsighter.agents.ddqn.DDQNAgent`'s math on
networks with a seed axis (:mod:`farsighter.stacked`), so that one forward pass acts for every
seed and one backward pass updates them all.

Each seed keeps what makes it that seed: its initial weights (built under its seed), its replay
and the replay's generator (seed + 1), its epsilon-greedy generator (seed + 2). Its losses,
gradients, gradient clipping and optimizer steps are its own, so on CPU each seed trains bit for
bit as ``DDQNAgent`` trains it alone (``tests/test_seeds.py``). :meth:`member` is one seed seen
as an agent (evaluation, diagnostics, checkpoints), and its checkpoint is the one the run alone
writes: a seed started in a batch can be resumed alone, and the other way round.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from farsighter.agents.common import (
    Counters,
    TensorBatch,
    batch_tensors,
    build_seeded,
    elementwise_td_loss,
    make_optimizer,
    minibatch_args,
    obs_tensor,
    sync_target,
    updates_owed,
)
from farsighter.agents.seed_members import Member, seed_replay, stack_refusal
from farsighter.config import Config
from farsighter.exploration.epsilon import epsilon_draws, epsilon_greedy, linear_schedule
from farsighter.networks import QNetwork
from farsighter.ops.targets import double_q_target
from farsighter.replay import Batch, VectorStep
from farsighter.stacked import (
    StackedQNetwork,
    clip_per_seed,
    load_member_optimizer_state,
    member_optimizer_state,
)


def supports(cfg: Config, obs_space: gym.Space | None, device: torch.device) -> str:
    """Why ``cfg`` cannot train as a seed batch here ('' when it can)."""
    return stack_refusal(cfg, obs_space)


class SeedBatchDDQN:
    """S DDQN agents of one config (``cfgs`` differ only in seed) as one computation."""

    def __init__(
        self,
        cfgs: Sequence[Config],
        obs_space: gym.spaces.Box,
        act_space: gym.spaces.Discrete,
        *,
        device: torch.device,
    ) -> None:
        cfg = self.cfg = cfgs[0]
        self.cfgs, self.device, self.num_actions = list(cfgs), device, int(act_space.n)
        nets = [
            build_seeded(c.seed, lambda: QNetwork(obs_space, self.num_actions, cfg.hidden_sizes))
            for c in cfgs
        ]
        self.q = StackedQNetwork(nets).to(device)  # refuses networks it cannot stack
        # built again rather than deep-copied: a copy would lose the seeds' aligned layout
        self.q_target = StackedQNetwork(nets).to(device)
        self.q_target.requires_grad_(False)
        self.params = list(self.q.parameters())
        self.opt = make_optimizer(self.params, cfg)
        self.replay = seed_replay(cfgs, obs_space, device)
        self.rngs = [np.random.default_rng(c.seed + 2) for c in cfgs]
        self.counters = Counters(k=cfg.k)  # one schedule: the seeds step together
        self.epsilon = cfg.eps_start

    @property
    def seeds(self) -> int:
        return len(self.cfgs)

    # ------------------------------------------------------------------ acting
    def greedy(self, obs_SE: np.ndarray) -> np.ndarray:
        """argmax_a Q(s, a) of every seed's networks on its own observations, (S, E)."""
        with torch.inference_mode():
            obs = torch.from_numpy(obs_SE)
            return (
                self.q(obs if self.device.type == "cpu" else obs.to(self.device))
                .argmax(dim=2)
                .cpu()
                .numpy()
            )

    def act(self, obs_S: Sequence[np.ndarray], global_step: int) -> np.ndarray:
        """Each seed's epsilon-greedy actions from its own generator, (S, E)."""
        cfg, obs_SE = self.cfg, np.stack(obs_S)
        self.epsilon = linear_schedule(cfg.eps_start, cfg.eps_end, cfg.eps_decay_steps, global_step)
        greedy_SE = self.greedy(obs_SE)  # draws nothing: the generators see what they see alone
        n = obs_SE.shape[1]
        # epsilon_greedy's draws, seed by seed from its own generator: the coins, then the actions
        draws = [epsilon_draws(rng, self.num_actions, n) for rng in self.rngs]
        random_SE = np.stack([coins for coins, _ in draws]) < self.epsilon
        return np.where(random_SE, np.stack([actions for _, actions in draws]), greedy_SE)

    def observe(self, steps: Sequence[VectorStep]) -> None:
        """One vector step of every seed, in seed order, into the seeds' streams."""
        self.replay.add_steps(steps)

    # ------------------------------------------------------------------ learning
    def learn(self, global_step: int) -> list[dict[str, torch.Tensor]]:
        """The updates owed at ``global_step``; each seed's metrics as ``DDQNAgent.learn`` gives
        them alone (its latest TD loss when it updated, else nothing)."""
        loss_SB = None
        for _ in range(updates_owed(self.counters, self.cfg, global_step)):
            loss_SB = self.update()
        sync_target(
            self.counters, global_step, self.cfg.target_update_every, (self.q, self.q_target)
        )
        if loss_SB is None:
            return [{} for _ in range(self.seeds)]
        # each seed's mean taken as td_loss takes it alone (a mean over a row of (S, B) may round
        # differently)
        return [{"td_loss": loss_SB[s].mean()} for s in range(self.seeds)]

    def update(self) -> torch.Tensor:
        """One gradient step of every seed on its own double-Q minibatch; the elementwise TD
        losses, (S, B)."""
        cfg, k, S = self.cfg, self.counters.k, self.seeds
        batch = self.replay.sample_seeds(cfg.batch_size, **minibatch_args(cfg, k))
        t = self.returns(batch, batch_tensors(batch, self.device))

        def by_seed(x: torch.Tensor) -> torch.Tensor:
            return x.view(S, cfg.batch_size, *x.shape[1:])

        q_SB = self.q(by_seed(t.obs_B)).gather(2, by_seed(t.actions_B).unsqueeze(2)).squeeze(2)
        with torch.no_grad():  # Eq. 2 with k-step returns, each seed's rows as its own
            next_obs = by_seed(t.next_obs_B)
            q_next_online, q_next_target = self.q(next_obs), self.q_target(next_obs)
            y_SB = double_q_target(
                t.returns_B, t.bootstrap_B, q_next_online.flatten(0, 1), q_next_target.flatten(0, 1)
            ).view(S, -1)
        loss_SB = elementwise_td_loss(q_SB, y_SB, cfg.loss)
        self.opt.zero_grad(set_to_none=True)
        # The sum of the seeds' mean losses: each seed's gradient is its own loss's, with the
        # 1/B of the mean applied where F.smooth_l1_loss / F.mse_loss apply it alone.
        loss_SB.mean(1).sum().backward()
        if cfg.max_grad_norm > 0:
            clip_per_seed(self.params, S, cfg.max_grad_norm)
        self.opt.step()
        self.after_update(t)
        return loss_SB.detach()

    def returns(self, batch: Batch, t: TensorBatch) -> TensorBatch:
        """The minibatch the loss learns from (RND adds its bonus to the returns here)."""
        return t

    def after_update(self, t: TensorBatch) -> None:
        """After every seed's step (RND trains its predictors here)."""

    # ------------------------------------------------------------------ one seed
    def member(self, s: int) -> SeedMember:
        return SeedMember(self, s)


class SeedMember(Member):
    """A seed of :class:`~farsighter.agents.ddqn_seeds.SeedBatchDDQN`: ``DDQNAgent`` alone."""

    batch: SeedBatchDDQN

    def q_mean(self, obs_B: np.ndarray) -> torch.Tensor:
        """Q(s, .) of this seed's network, (B, A)."""
        b = self.batch
        return b.q.member_forward(obs_tensor(np.asarray(obs_B), b.device), self.s)

    def explore(self, obs_E: np.ndarray, global_step: int) -> np.ndarray:
        """Epsilon-greedy from this seed's generator (``DDQNAgent.act``)."""
        cfg, b = self.cfg, self.batch
        eps = linear_schedule(cfg.eps_start, cfg.eps_end, cfg.eps_decay_steps, global_step)
        greedy = lambda: self.greedy(obs_E)  # noqa: E731
        return epsilon_greedy(b.rngs[self.s], eps, b.num_actions, greedy, len(obs_E))

    @torch.no_grad()
    def q_estimate(self, obs_B: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        return self.q_mean(obs_B).cpu().numpy(), None

    def diagnostics(self) -> dict[str, float]:
        return {"epsilon": self.batch.epsilon, "k": float(self.batch.counters.k)}

    def state_dict(self, include_replay: bool = True) -> dict[str, Any]:
        """The checkpoint of ``DDQNAgent`` alone, for this seed."""
        b, s = self.batch, self.s
        return {
            "q": b.q.member_state(s),
            "q_target": b.q_target.member_state(s),
            "opt": member_optimizer_state(b.opt, s),
            "rng": b.rngs[s].bit_generator.state,
            "counters": dataclasses.asdict(b.counters),
            "replay": b.replay.member_state(s) if include_replay else None,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """A checkpoint of this seed (written alone or in a batch). Seeds resume together only
        from checkpoints with the same counters (:func:`farsighter.seeds.train_seeds` groups
        them so)."""
        b, s = self.batch, self.s
        b.q.load_member(s, state["q"])
        b.q_target.load_member(s, state["q_target"])
        load_member_optimizer_state(b.opt, s, state["opt"])
        b.rngs[s].bit_generator.state = state["rng"]
        for key, value in state["counters"].items():  # equal for every seed of a batch
            setattr(b.counters, key, value)
        if state.get("replay") is not None:
            b.replay.load_member(s, state["replay"])
        else:
            b.counters.hold_pending = True


SeedBatch = SeedBatchDDQN
"""The batch class :func:`farsighter.agents.build_seed_agents` builds (``Algorithm.seed_batch``)."""
