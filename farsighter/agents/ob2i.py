"""OB2I (Bai et al. 2021, "Principled exploration via optimistic bootstrapping and backward
induction"), as the authors' code runs it (Baichenjia/OB2I, ``--ebu --reward-type ucb``; SPEC 2.3).

Network (authors' models.py, BootQNetwork/HeadNN): a shared trunk phi(s) (the Nature CNN's
conv layers for images, or the MLP without its last hidden layer) and K heads, each with its own
hidden layer, Q_k(s, .) = W2_k relu(W1_k phi(s) + b1_k) + b2_k (512 units per head for images).
With ``ob2i.separate_heads=False``, K linear heads on the whole torso, Q_k(s, .) = W_k phi(s) + b_k.
Every head learns from every sample (no bootstrap masks).

Acting: one head k_e drawn uniformly per episode and environment; epsilon-greedy on Q_{k_e} with
epsilon annealed linearly from eps_start to eps_end (1.0 -> 0.1). Evaluation: majority vote of
the heads (the authors' evaluation), ties broken by the heads' mean Q.

Formulas (OB2I section 3): :mod:`farsighter.ops.ob2i` (the UCB-bonus, the next-state bonus and
the backward induction of an episode's targets).

* Loss on a minibatch of the episode: L = mean_{b,k} huber(Q_k(s_b, a_b) - y_{b,k}) / K (the
  authors' ``gradient_norm``: the loss divided by K). As in EBU, the targets of an episode are
  computed once and consumed one minibatch per update, in chunks of batch_size going backward
  from the episode end; only Q~ (T x K x A floats) is held, frames are gathered per chunk.
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
    build_seeded,
    load_state,
    make_replay,
    obs_tensor,
    save_state,
    sync_target,
    td_loss,
    updates_owed,
)
from farsighter.agents.cuda_graph import Tensors
from farsighter.agents.learner import Learner
from farsighter.agents.protocol import AgentFactory
from farsighter.config import Config
from farsighter.exploration.epsilon import EpisodeHeads
from farsighter.networks import EnsembleQNetwork
from farsighter.ops.ob2i import backward_targets, next_state_bonus, ucb_bonus
from farsighter.ops.running import RunningMeanStd
from farsighter.replay import Episode, VectorStep

BONUS_EPS = 1e-8  # keeps the running-std division finite when every bonus is zero


def ensemble_td_loss(q_BK: torch.Tensor, y_BK: torch.Tensor, kind: str) -> torch.Tensor:
    """Every head on every sample, mean TD loss divided by K (authors' ``gradient_norm``)."""
    return td_loss(q_BK, y_BK, kind) / q_BK.shape[1]


class EnsembleLoss:
    """Every head's TD loss on the backward-induction targets ``y_BK`` of a minibatch of one
    episode. The loss owns the target network (a copy of ``q``), which the targets read."""

    def __init__(self, q: nn.Module, kind: str) -> None:
        self.q = q
        self.q_target = copy.deepcopy(q).requires_grad_(False)
        self.kind = kind

    def __call__(self, inputs: Tensors) -> Tensors:
        q_BKA, a_B = self.q(inputs["obs_B"]), inputs["actions_B"]
        q_BK = q_BKA.gather(2, a_B[:, None, None].expand(-1, q_BKA.shape[1], 1))[:, :, 0]
        return {"loss": ensemble_td_loss(q_BK, inputs["y_BK"], self.kind)}


@dataclass
class OB2ICounters(Counters):
    episodes_learned: int = 0  # episodes whose backward targets were computed


class OB2IAgent:
    """Bootstrapped heads with UCB-bonus and episodic backward update (module docstring)."""

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
        self.num_heads = cfg.ob2i.num_heads
        self.q = build_seeded(
            cfg.seed,
            lambda: EnsembleQNetwork(
                obs_space,
                self.num_actions,
                self.num_heads,
                cfg.hidden_sizes,
                separate_heads=cfg.ob2i.separate_heads,
            ),
        ).to(device)
        self.loss = EnsembleLoss(self.q, cfg.loss)
        # eager: an episode's last minibatch has its own size (a graph or compilation per size)
        self.learner = Learner(self.loss, self.q.parameters(), cfg, device, eager=True)
        self.replay = make_replay(cfg, obs_space, frame_stack, seed=cfg.seed + 1)
        self.rng = np.random.default_rng(cfg.seed + 2)
        self.explore = EpisodeHeads(cfg, self.num_actions, self.num_heads, self.rng)
        self.next_bonus_rms = RunningMeanStd()
        self.reward_bonus_rms = RunningMeanStd()
        self.counters = OB2ICounters(k=cfg.k)
        # The episode being learned from: targets y (T, K), consumed backward from ``cursor``.
        self.episode: Episode | None = None
        self.y_TK = np.zeros((0, self.num_heads), dtype=np.float32)
        self.cursor = 0
        self.stats = {"bonus_reward": float("nan"), "bonus_next": float("nan")}
        self.stats["q_variance"] = float("nan")

    # ------------------------------------------------------------------ acting
    def act(self, obs_E: np.ndarray, global_step: int, explore: bool = True) -> np.ndarray:
        """Epsilon-greedy on each environment's head of the episode (vote when not exploring)."""
        n = obs_E.shape[0]
        if not explore:
            return self.greedy(obs_E)
        heads_E = self.explore.heads(n)

        @torch.no_grad()
        def head_greedy() -> np.ndarray:
            q_EKA = self.q(obs_tensor(obs_E, self.device))
            q_EA = q_EKA.cpu()[torch.arange(n), torch.as_tensor(heads_E)]
            return q_EA.argmax(dim=1).cpu().numpy()

        return self.explore(global_step, head_greedy, n)

    @torch.no_grad()
    def greedy(self, obs_E: np.ndarray) -> np.ndarray:
        q_EKA = self.q(obs_tensor(obs_E, self.device))
        mean_EA = q_EKA.mean(dim=1)
        if self.cfg.ob2i.eval_policy == "mean":
            return mean_EA.argmax(dim=1).cpu().numpy()
        votes_EA = nn.functional.one_hot(q_EKA.argmax(dim=2), self.num_actions).sum(dim=1)
        top_EA = votes_EA == votes_EA.max(dim=1, keepdim=True).values
        return mean_EA.masked_fill(~top_EA, float("-inf")).argmax(dim=1).cpu().numpy()

    @torch.no_grad()
    def q_estimate(self, obs_B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mean of Q(s, .) over the heads and its variance over the heads (OB2I's posterior)."""
        q_BKA = self.q(obs_tensor(obs_B, self.device))
        return (
            q_BKA.mean(dim=1).cpu().numpy(),
            q_BKA.var(dim=1, unbiased=False).cpu().numpy(),
        )

    def observe(self, step: VectorStep) -> None:
        self.replay.add_step(step)
        self.explore.ended(np.logical_or(step.terminated_E, step.truncated_E))

    # ------------------------------------------------------------------ learning
    def learn(self, global_step: int) -> dict[str, torch.Tensor]:
        metrics: dict[str, torch.Tensor] = {}
        # skipped while no episode is complete
        for _ in range(updates_owed(self.counters, self.cfg, global_step)):
            loss = self.update()
            if loss is not None:
                metrics["td_loss"] = loss
        sync_target(
            self.counters, global_step, self.cfg.target_update_every, (self.q, self.loss.q_target)
        )
        return metrics

    def _obs(self, env: int, rows: np.ndarray) -> torch.Tensor:
        e_B = np.full(len(rows), env, dtype=np.int64)
        return obs_tensor(self.replay.stacked_obs(e_B, rows), self.device)

    @torch.no_grad()
    def episode_targets(self, ep: Episode) -> np.ndarray:
        """Bonuses and backward-induction targets y (T, K) of an episode (module docstring)."""
        cfg, o = self.cfg, self.cfg.ob2i
        length, chunk = ep.length, cfg.batch_size
        q_next_TKA = np.empty((length, self.num_heads, self.num_actions), dtype=np.float32)
        rb_T = np.empty(length, dtype=np.float32)
        for lo in range(0, length, chunk):  # frames of one minibatch at a time
            hi = min(length, lo + chunk)
            rows = ep.start + np.arange(lo, hi, dtype=np.int64)
            a_B = torch.as_tensor(ep.actions[lo:hi], device=self.device, dtype=torch.int64)
            bonus_BA = ucb_bonus(self.q(self._obs(ep.env, rows)))  # online heads at (s_t, a_t)
            rb_T[lo:hi] = bonus_BA.gather(1, a_B[:, None])[:, 0].cpu().numpy()
            q_next_TKA[lo:hi] = self.loss.q_target(self._obs(ep.env, rows + 1)).cpu().numpy()
        self.stats["q_variance"] = float(np.mean(rb_T.astype(np.float64) ** 2))
        if o.normalize_reward_bonus:
            self.reward_bonus_rms.update(rb_T)
            rb_T = rb_T / (float(self.reward_bonus_rms.std) + BONUS_EPS)
        rb_T = o.bonus_reward_weight * rb_T
        taken_next_T = np.append(ep.actions[1:], -1)  # a_{t+1}; none after the last step
        nb_TK, keep_TK = next_state_bonus(q_next_TKA, taken_next_T)
        if o.normalize_next_bonus:
            self.next_bonus_rms.update(nb_TK.ravel())
            nb_TK = nb_TK / (float(self.next_bonus_rms.std) + BONUS_EPS)
        nb_TK = o.bonus_next_weight * nb_TK * keep_TK
        self.stats["bonus_reward"] = float(rb_T.mean())
        self.stats["bonus_next"] = float(nb_TK.mean())
        return backward_targets(
            ep.rewards + rb_T, ep.actions, q_next_TKA, nb_TK, ep.terminated, cfg.gamma, o.beta
        )

    def update(self) -> torch.Tensor | None:
        """One gradient step on the next minibatch of the current episode (going backward)."""
        ep = self.episode
        if ep is None or self.cursor == 0 or not self.replay.is_live(ep.env, ep.start):
            try:
                ep = self.replay.sample_episode()
            except ValueError:  # no complete episode yet
                return None
            self.episode, self.y_TK, self.cursor = ep, self.episode_targets(ep), ep.length
            self.counters.episodes_learned += 1
        hi = self.cursor
        lo = max(0, hi - self.cfg.batch_size)
        rows = ep.start + np.arange(lo, hi, dtype=np.int64)
        inputs = {
            "obs_B": self._obs(ep.env, rows),
            "actions_B": torch.as_tensor(ep.actions[lo:hi], device=self.device, dtype=torch.int64),
            "y_BK": torch.as_tensor(self.y_TK[lo:hi], device=self.device),
        }
        self.cursor = lo
        return self.learner(inputs)["loss"]

    def diagnostics(self) -> dict[str, float]:
        return {
            "epsilon": self.explore.epsilon,
            "bonus": self.stats["bonus_reward"] + self.stats["bonus_next"],
            "bonus_reward": self.stats["bonus_reward"],
            "bonus_next": self.stats["bonus_next"],
            "q_variance": self.stats["q_variance"],
            "episodes_learned": float(self.counters.episodes_learned),
        }

    # ------------------------------------------------------------------ checkpoints
    SAVED = (
        "q",
        "q_target",
        "opt",
        "rng",
        "head_E",
        "next_bonus_rms",
        "reward_bonus_rms",
        "epsilon",
        "stats",
        "counters",
    )

    SAVED_AT = {  # keys of the earlier layout
        "q_target": "loss.q_target",
        "opt": "learner",
        "head_E": "explore.head_E",
        "epsilon": "explore.epsilon",
    }

    def state_dict(self, include_replay: bool = True) -> dict[str, Any]:
        state = save_state(self, self.SAVED, include_replay)
        ep = self.episode if include_replay else None  # its rows live in the replay
        state["episode"] = (
            None
            if ep is None
            else {"episode": copy.deepcopy(ep), "y": self.y_TK.copy(), "cursor": self.cursor}
        )
        return state

    def load_state_dict(self, state: dict[str, Any]) -> None:
        load_state(self, self.SAVED, state)
        self.episode, self.cursor = None, 0
        if state.get("replay") is not None and state.get("episode") is not None:
            self.episode = state["episode"]["episode"]
            self.y_TK = state["episode"]["y"]
            self.cursor = state["episode"]["cursor"]


AGENT: AgentFactory = OB2IAgent  # the class farsighter.algorithms names; mypy checks the protocol
