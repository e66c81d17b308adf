"""What the seed batches share (:mod:`farsighter.seeds`): the settings they refuse, their replay,
and one seed of a batch seen as an agent (a member), which the run log, evaluation, a study's
callbacks and checkpoints use. A member acts greedily for evaluation; it explores, records
steps and learns only through its batch. Its checkpoint is the one its agent alone writes, so a
seed started in a batch resumes alone, and the other way round."""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np
import torch

from farsighter.agents.common import obs_tensor, row_bytes, uses_gpu_replay
from farsighter.config import Config
from farsighter.replay import VectorStep
from farsighter.replay.seeds import SeedReplay
from farsighter.stacked import load_member_optimizer_state, member_optimizer_state

if TYPE_CHECKING:
    from farsighter.agents.ddqn_seeds import SeedBatchDDQN
    from farsighter.agents.farsighter_seeds import SeedBatchFarsighter
    from farsighter.agents.rnd_seeds import SeedBatchRND


def stack_refusal(cfg: Config, obs_space: gym.Space | None) -> str:
    """Why networks of ``cfg`` on ``obs_space`` cannot be stacked ('' when they can)."""
    if not isinstance(obs_space, gym.spaces.Box) or len(obs_space.shape or ()) == 3:
        return "image observations train their seeds one at a time (batched: flat observations)"
    if cfg.runtime.precision != "fp32" or cfg.runtime.compile or cfg.runtime.cuda_graph == "on":
        return "precision bf16, compile and cuda_graph train their seeds one at a time"
    return ""


def seed_replay(
    cfgs: Sequence[Config], obs_space: gym.spaces.Box, device: torch.device
) -> SeedReplay:
    """The seeds' replays in one buffer: each seed's streams and generator (seed + 1), as its
    agent alone makes them (discrete actions as int32)."""
    cfg = cfgs[0]
    return SeedReplay(
        [c.seed + 1 for c in cfgs],
        cfg.buffer_size,
        tuple(obs_space.shape or ()),
        obs_space.dtype,
        num_envs=cfg.num_envs,
        action_dtype=np.int32,
        cut_exploratory=cfg.k_target == "cut",  # and each seed from its blr.optimism switch
        device=device
        if uses_gpu_replay(cfg, device, row_bytes(obs_space, 1) * len(cfgs))
        else None,
    )


class Member:
    """What every member does alike; :meth:`q_mean` is its greedy Q."""

    def __init__(self, batch: Any, s: int) -> None:
        self.batch, self.s = batch, s
        self.cfg = batch.cfgs[s]

    def q_mean(self, obs_B: np.ndarray) -> torch.Tensor:
        raise NotImplementedError

    def act(self, obs_E: np.ndarray, global_step: int, explore: bool = True) -> np.ndarray:
        if explore:
            raise NotImplementedError("a seed of a batch explores through the batch's act")
        return self.greedy(obs_E)

    def greedy(self, obs_E: np.ndarray) -> np.ndarray:
        """argmax_a of this seed's greedy Q alone (its slice of the batch's networks)."""
        with torch.inference_mode():
            return self.q_mean(obs_E).argmax(dim=1).cpu().numpy()

    def observe(self, step: VectorStep) -> None:
        raise NotImplementedError("a seed of a batch records its steps through the batch")

    def learn(self, global_step: int) -> dict[str, torch.Tensor]:
        raise NotImplementedError("a seed of a batch learns through the batch")


class SeedMember(Member):
    """A seed of :class:`~farsighter.agents.ddqn_seeds.SeedBatchDDQN`: ``DDQNAgent`` alone."""

    batch: SeedBatchDDQN

    def q_mean(self, obs_B: np.ndarray) -> torch.Tensor:
        """Q(s, .) of this seed's network, (B, A)."""
        b = self.batch
        return b.q.member_forward(obs_tensor(np.asarray(obs_B), b.device), self.s)

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


class FarsighterSeedMember(Member):
    """A seed of :class:`~farsighter.agents.farsighter_seeds.SeedBatchFarsighter`:
    ``FarsighterAgent`` alone."""

    batch: SeedBatchFarsighter

    def __init__(self, batch: SeedBatchFarsighter, s: int) -> None:
        super().__init__(batch, s)
        self.parts = batch.parts[s]

    def q_mean(self, obs_B: np.ndarray) -> torch.Tensor:
        """Q at the posterior mean, phi(s)^T mean_a, (B, A)."""
        return self._phi(obs_B) @ self.parts.head.mean_AD.T

    @torch.no_grad()
    def q_estimate(self, obs_B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        phi_BD = self._phi(obs_B)
        mean_BA = phi_BD @ self.parts.head.mean_AD.T
        return mean_BA.cpu().numpy(), self.parts.head.predictive_var(phi_BD).cpu().numpy()

    def _phi(self, obs_B: np.ndarray) -> torch.Tensor:
        """phi(s) of this seed's torso, (B, D)."""
        b = self.batch
        return b.torso.member_forward(obs_tensor(np.asarray(obs_B), b.device), self.s)

    def episode_diagnostics(self) -> dict[str, float]:
        """What an episode's metrics row reads (k), without the deferred Q-variance."""
        return {"k": float(self.parts.counters.k)}

    def diagnostics(self) -> dict[str, float]:
        head, c = self.parts.head, self.parts.counters
        return {
            "k": float(c.k),
            "q_variance": c.settle().q_variance,
            "posterior_refreshes": float(head.num_refreshes),
            "jitter_events": float(head.jitter_events),
            "noise_std": head.noise_std,
        }

    def state_dict(self, include_replay: bool = True) -> dict[str, Any]:
        """The checkpoint of ``FarsighterAgent`` alone, for this seed."""
        b, s, p = self.batch, self.s, self.parts
        return (
            {
                "torso": b.torso.member_state(s),
                "torso_target": b.torso_target.member_state(s),
                "head": p.head.state_dict(),
                "target_mean_AD": p.target_mean_AD.clone(),
                "opt": member_optimizer_state(b.opt, s),
                "rng": p.rng.bit_generator.state,
                "gen": p.gen.get_state(),
                "counters": dataclasses.asdict(p.counters.settle()),
                "replay": b.replay.member_state(s) if include_replay else None,
                "exploration": p.exploration.state_dict(),
                "recent_phi": p.recent_phi.state_dict(),
                "target_cache": p.cache.state_dict()
                if p.cache is not None and include_replay
                else None,
            }
            | ({"calibrated": p.calibrated} if self.cfg.blr.optimism != "always" else {})
            | ({"unpaid": p.unpaid} if self.cfg.blr.rearm_episodes else {})
        )

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """A checkpoint of this seed (written alone or in a batch). Seeds resume together only
        from checkpoints with the same counters (:func:`farsighter.seeds.train_seeds` groups
        them so)."""
        b, s, p = self.batch, self.s, self.parts
        b.torso.load_member(s, state["torso"])
        b.torso_target.load_member(s, state["torso_target"])
        p.head.load_state_dict(state["head"])
        p.target_mean_AD.copy_(state["target_mean_AD"])
        load_member_optimizer_state(b.opt, s, state["opt"])
        p.rng.bit_generator.state = state["rng"]
        p.gen.set_state(state["gen"])
        for key, value in state["counters"].items():
            setattr(p.counters, key, value)
        p.recent_phi.load_state_dict(state["recent_phi"])
        if state.get("calibrated", False) and not p.calibrated:
            b.calibrate(s, restart=False)
        p.unpaid = state.get("unpaid", 0)
        p.exploration.load_state_dict(state.get("exploration", state))
        if p.cache is not None:  # the rows it keeps, when the checkpoint has them
            p.cache.load_state_dict(state.get("target_cache"))
        if state.get("replay") is not None:
            b.replay.load_member(s, state["replay"])
        else:
            p.counters.hold_pending = True


class RNDSeedMember(SeedMember):
    """A seed of :class:`~farsighter.agents.rnd_seeds.SeedBatchRND`: ``RNDAgent`` alone."""

    batch: SeedBatchRND

    def diagnostics(self) -> dict[str, float]:
        bonus = self.batch.bonuses[self.s]
        return {
            **super().diagnostics(),
            "intrinsic_reward": bonus.stats["intrinsic_reward"],
            "intrinsic_std": float(bonus.intrinsic_rms.std),
            "predictor_loss": bonus.stats["predictor_loss"],
        }

    def state_dict(self, include_replay: bool = True) -> dict[str, Any]:
        """The checkpoint of ``RNDAgent`` alone, for this seed."""
        bonus = self.batch.bonuses[self.s]
        return {
            **super().state_dict(include_replay),
            **{key: getattr(bonus, key).state_dict() for key in RND_STATEFUL},
            "epsilon": self.batch.epsilon,
            "stats": dict(bonus.stats),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        super().load_state_dict(state)
        bonus = self.batch.bonuses[self.s]
        for key in RND_STATEFUL:  # copies: never the caller's tensors (as load_state does)
            getattr(bonus, key).load_state_dict(copy.deepcopy(state[key]))
        bonus.stats = dict(state["stats"])
        self.batch.epsilon = state["epsilon"]


RND_STATEFUL = ("rnd_target", "predictor", "rnd_opt", "obs_rms", "intrinsic_rms")
"""The pieces of an RND bonus saved by their ``state_dict`` (``RNDAgent``'s keys)."""
