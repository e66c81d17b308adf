"""What the seed batches share (:mod:`farsighter.seeds`): the settings they refuse, their replay,
and the base of one seed of a batch seen as an agent (a member: ``Agent``), which the run log,
evaluation, a study's callbacks and checkpoints use. A member acts as its seed would alone
(greedily, or exploring from its seed's own generators); it records steps and learns through its
batch. Its checkpoint is the one its agent alone writes, so a seed started in a batch resumes
alone, and the other way round."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from farsighter.agents.common import make_replay, row_bytes, uses_gpu_replay
from farsighter.config import Config
from farsighter.replay.seeds import OneSeedReplay, SeedReplay


def stack_refusal(cfg: Config, obs_space: gym.Space | None) -> str:
    """Why networks of ``cfg`` on ``obs_space`` cannot be stacked ('' when they can)."""
    if not isinstance(obs_space, gym.spaces.Box) or len(obs_space.shape or ()) == 3:
        return "image observations do not stack (batched: flat observations)"
    if cfg.runtime.precision != "fp32" or cfg.runtime.compile or cfg.runtime.cuda_graph == "on":
        return "precision bf16, compile and cuda_graph do not stack"
    return ""


def seed_replay(
    cfgs: Sequence[Config],
    obs_space: gym.spaces.Box,
    device: torch.device,
    frame_stack: int = 1,
    act_space: gym.Space | None = None,
) -> SeedReplay | OneSeedReplay:
    """The seeds' replays in one buffer: each seed's streams and generator (seed + 1), as its
    agent alone makes them (discrete actions as int32); one seed's replay alone for one seed
    (:func:`farsighter.agents.common.make_replay`: frame stacks, Box actions)."""
    cfg = cfgs[0]
    if len(cfgs) == 1:
        replay = make_replay(
            cfg, obs_space, frame_stack, cfg.seed + 1, act_space, device, kind=OneSeedReplay
        )
        assert isinstance(replay, OneSeedReplay)
        return replay
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


class Member(ABC):
    """What every member does alike: :meth:`q_mean` is its greedy Q, :meth:`explore` its
    exploring actions from its seed's own generators (as its agent alone draws them)."""

    def __init__(self, batch: Any, s: int) -> None:
        self.batch, self.s = batch, s
        self.cfg = batch.cfgs[s]

    @abstractmethod
    def q_mean(self, obs_B: np.ndarray) -> torch.Tensor: ...

    @abstractmethod
    def explore(self, obs_E: np.ndarray, global_step: int) -> np.ndarray: ...

    def act(self, obs_E: np.ndarray, global_step: int, explore: bool = True) -> np.ndarray:
        return self.explore(obs_E, global_step) if explore else self.greedy(obs_E)

    def greedy(self, obs_E: np.ndarray) -> np.ndarray:
        """argmax_a of this seed's greedy Q alone (its slice of the batch's networks)."""
        with torch.inference_mode():
            return self.q_mean(obs_E).argmax(dim=1).cpu().numpy()
