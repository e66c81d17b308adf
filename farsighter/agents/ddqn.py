"""DDQN (paper section 3.2) and k-DDQN (section 5.2 baselines): epsilon-greedy exploration,
double-Q targets with one-step (k = 1) or k-step returns formed by the replay at sample time.

Written once over a seed axis: S seeds of one config (S = 1 for a run alone) act, record and
learn as one computation. Each seed keeps what makes it that seed: its initial weights (built
under its seed), its replay streams and their generator (seed + 1), its epsilon-greedy generator
(seed + 2), its own loss, gradient clipping and optimizer state; on CPU each seed of a batch
trains bit for bit as it trains alone (``tests/training/test_seeds.py``). Its networks are
:func:`farsighter.stacked.seed_network`'s: one network alone for S = 1 (any architecture,
precision, compiled or captured), stacked MLPs for S > 1. :meth:`DDQNAgent.member` is one seed
seen as an agent, whose checkpoint is the one its run alone writes.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Sequence
from functools import partial
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from farsighter.agents.common import (
    Counters,
    TensorBatch,
    batch_tensors,
    build_seeded,
    minibatch_args,
    obs_tensor,
    seed_td_losses,
    sync_target,
    updates_owed,
)
from farsighter.agents.cuda_graph import Tensors
from farsighter.agents.learner import Learner
from farsighter.agents.protocol import SeedAgentsFactory
from farsighter.agents.seed_members import Member, seed_replay, stack_refusal
from farsighter.config import Config
from farsighter.exploration.epsilon import epsilon_greedy, linear_schedule
from farsighter.networks import QNetwork
from farsighter.ops.targets import double_q_target
from farsighter.replay import Batch, VectorStep
from farsighter.stacked import SeedNetwork, online_and_target_seeds, seed_network


def supports(cfg: Config, obs_space: gym.Space | None, device: torch.device) -> str:
    """Why seeds of ``cfg`` cannot train as one batch here ('' when they can)."""
    return stack_refusal(cfg, obs_space)


class DoubleQLoss:
    """Eq. 3 on the double-Q target of Eq. 2 with k-step returns, each seed's mean over its own
    B rows (the minibatch holds seed 0's rows, then seed 1's, ...). The loss is the sum of the
    seeds' means: each seed's gradient is its own loss's. Owns the target network, built like
    ``q`` and moved only by the hard copy (:func:`sync_target`)."""

    def __init__(self, q: SeedNetwork, q_target: SeedNetwork, kind: str, seeds: int) -> None:
        self.q, self.q_target = q, q_target.requires_grad_(False)
        self.kind, self.seeds = kind, seeds

    @torch.no_grad()
    def targets(self, t: TensorBatch) -> torch.Tensor:
        """y = R + gamma^n Q_target(s_{t+n}, argmax_a Q(s_{t+n}, a)), no bootstrap at a terminal;
        (S * B,)."""
        q_next, q_next_target = online_and_target_seeds(self.q, self.q_target, t.next_obs_B)
        assert q_next_target is not None
        return double_q_target(
            t.returns_B, t.bootstrap_B, q_next.flatten(0, 1), q_next_target.flatten(0, 1)
        )

    def __call__(self, inputs: Tensors) -> Tensors:
        t = TensorBatch.of(inputs)
        q_B = self.q.rows(t.obs_B).gather(1, t.actions_B.unsqueeze(1)).squeeze(1)
        loss, loss_S = seed_td_losses(q_B, self.targets(t), self.kind, self.seeds)
        return {"loss": loss, "loss_S": loss_S}


class DDQNAgent:
    """Q(s, a) = W phi_theta(s) for S seeds; target network copied every N steps (Eq. 2-3)."""

    def __init__(
        self,
        cfgs: Sequence[Config],
        obs_space: gym.spaces.Box,
        act_space: gym.spaces.Discrete,
        *,
        frame_stack: int,
        device: torch.device,
    ) -> None:
        cfg = self.cfg = cfgs[0]
        self.cfgs, self.device, self.num_actions = list(cfgs), device, int(act_space.n)
        nets = [
            build_seeded(c.seed, lambda: QNetwork(obs_space, self.num_actions, cfg.hidden_sizes))
            for c in cfgs
        ]
        self.q = seed_network(nets).to(device)
        # the target: copies (a seed alone's network is the online one's own module)
        q_target = seed_network([copy.deepcopy(net) for net in nets]).to(device)
        self.loss = DoubleQLoss(self.q, q_target, cfg.loss, self.seeds)
        self.learner = Learner(self.loss, self.q.parameters(), cfg, device, seeds=self.seeds)
        self.replay = seed_replay(cfgs, obs_space, device, frame_stack)
        self.rngs = [np.random.default_rng(c.seed + 2) for c in cfgs]
        self.counters = Counters(k=cfg.k)  # one schedule: the seeds step together
        self.epsilon = cfg.eps_start

    @property
    def seeds(self) -> int:
        return len(self.cfgs)

    # ------------------------------------------------------------------ acting
    def greedy(self, obs_S: Sequence[np.ndarray]) -> np.ndarray:
        """argmax_a Q(s, a) of every seed's network on its own observations, (S, E)."""
        with torch.inference_mode():
            obs = obs_tensor(obs_S[0] if self.seeds == 1 else np.concatenate(obs_S), self.device)
            return self.q.greedy(obs).view(self.seeds, -1).cpu().numpy()

    def act(self, obs_S: Sequence[np.ndarray], global_step: int) -> np.ndarray:
        """Each seed's epsilon-greedy actions from its own generator (:func:`epsilon_greedy`),
        (S, E); one greedy forward for every seed, made only when some environment needs it."""
        cfg = self.cfg
        self.epsilon = linear_schedule(cfg.eps_start, cfg.eps_end, cfg.eps_decay_steps, global_step)
        greedy_SE: list[np.ndarray] = []

        def greedy(s: int) -> np.ndarray:
            if not greedy_SE:
                greedy_SE.extend(self.greedy(obs_S))
            return greedy_SE[s]

        n, A = len(obs_S[0]), self.num_actions
        return np.stack(
            [
                epsilon_greedy(rng, self.epsilon, A, partial(greedy, s), n)
                for s, rng in enumerate(self.rngs)
            ]
        )

    def observe(self, steps: Sequence[VectorStep]) -> None:
        """One vector step of every seed, in seed order, into the seeds' streams."""
        self.replay.add_steps(steps)

    # ------------------------------------------------------------------ learning
    def learn(self, global_step: int) -> list[dict[str, torch.Tensor]]:
        """The updates owed at ``global_step``; each seed's latest TD loss when it updated."""
        loss_S = None
        for _ in range(updates_owed(self.counters, self.cfg, global_step)):
            loss_S = self.update()
        every = self.cfg.target_update_every
        sync_target(self.counters, global_step, every, (self.q, self.loss.q_target))
        if loss_S is None:
            return [{} for _ in range(self.seeds)]
        return [{"td_loss": loss_S[s]} for s in range(self.seeds)]

    def update(self) -> torch.Tensor:
        """One gradient step of every seed on its own double-Q minibatch; the seeds' losses."""
        cfg = self.cfg
        batch = self.replay.sample_seeds(cfg.batch_size, **minibatch_args(cfg, self.counters.k))
        t = self.returns(batch, batch_tensors(batch, self.device))
        loss_S = self.learner(t.tensors())["loss_S"]
        self.after_update(t)
        return loss_S

    def returns(self, batch: Batch, t: TensorBatch) -> TensorBatch:
        """The minibatch the loss learns from (RND adds its bonus to the returns here)."""
        return t

    def after_update(self, t: TensorBatch) -> None:
        """After every seed's step (RND trains its predictors here)."""

    # ------------------------------------------------------------------ one seed
    def member(self, s: int) -> DDQNMember:
        return DDQNMember(self, s)


class DDQNMember(Member):
    """One seed of a :class:`DDQNAgent`, as an agent."""

    batch: DDQNAgent

    def q_mean(self, obs_B: np.ndarray) -> torch.Tensor:
        """Q(s, .) of this seed's network, (B, A)."""
        b = self.batch
        return b.q.member_forward(obs_tensor(np.asarray(obs_B), b.device), self.s)

    def explore(self, obs_E: np.ndarray, global_step: int) -> np.ndarray:
        """Epsilon-greedy from this seed's generator."""
        cfg, b = self.cfg, self.batch
        eps = linear_schedule(cfg.eps_start, cfg.eps_end, cfg.eps_decay_steps, global_step)
        greedy = lambda: self.greedy(obs_E)  # noqa: E731
        return epsilon_greedy(b.rngs[self.s], eps, b.num_actions, greedy, len(obs_E))

    @torch.no_grad()
    def q_estimate(self, obs_B: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Q(s, .) for a batch of states; DDQN has no posterior, so no variance."""
        return self.q_mean(obs_B).cpu().numpy(), None

    def diagnostics(self) -> dict[str, float]:
        return {"epsilon": self.batch.epsilon, "k": float(self.batch.counters.k)}

    def state_dict(self, include_replay: bool = True) -> dict[str, Any]:
        """This seed's checkpoint, the one its run alone writes."""
        b, s = self.batch, self.s
        return {
            "q": b.q.member_state(s),
            "q_target": b.loss.q_target.member_state(s),
            "opt": b.learner.member_state(s),
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
        b.loss.q_target.load_member(s, state["q_target"])
        b.learner.load_member(s, state["opt"])
        b.rngs[s].bit_generator.state = state["rng"]
        for key, value in state["counters"].items():  # equal for every seed of a batch
            setattr(b.counters, key, value)
        if state.get("replay") is not None:
            b.replay.load_member(s, state["replay"])
        else:
            b.counters.hold_pending = True


SEED_AGENTS: SeedAgentsFactory = DDQNAgent  # the class farsighter.algorithms names
