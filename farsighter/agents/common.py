"""Plumbing shared by the agents (defined once): optimizer, schedules, replay, tensors, losses."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import nn

from farsighter.config import Config
from farsighter.replay import Batch, ReplayBuffer


def make_optimizer(params: Iterable[nn.Parameter], cfg: Config) -> torch.optim.Optimizer:
    """Table 1's RMSProp (centered, decay 0.95 as in DQN) or Adam."""
    if cfg.optimizer == "rmsprop":
        return torch.optim.RMSprop(
            params,
            lr=cfg.lr,
            alpha=cfg.rmsprop_alpha,
            eps=cfg.optim_eps,
            centered=cfg.rmsprop_centered,
        )
    return torch.optim.Adam(params, lr=cfg.lr, eps=cfg.optim_eps)


def linear_schedule(start: float, end: float, duration: int, step: int) -> float:
    """Linear interpolation from ``start`` to ``end`` over ``duration`` steps, then constant."""
    if duration <= 0:
        return end
    frac = min(max(step / duration, 0.0), 1.0)
    return start + frac * (end - start)


def make_replay(
    cfg: Config, obs_space: gym.spaces.Box, frame_stack: int, seed: int
) -> ReplayBuffer:
    """A replay buffer sized for the run; uint8 images keep one byte per pixel."""
    shape = obs_space.shape
    assert shape is not None
    return ReplayBuffer(
        cfg.buffer_size,
        tuple(shape),
        obs_space.dtype,
        num_envs=cfg.num_envs,
        frame_stack=frame_stack,
        action_dtype=np.int32,
        seed=seed,
    )


def obs_tensor(obs: np.ndarray, device: torch.device) -> torch.Tensor:
    """Observations keep their dtype (uint8 frames cross to the device as bytes)."""
    return torch.as_tensor(np.asarray(obs), device=device)


def batch_tensors(batch: Batch, device: torch.device) -> dict[str, torch.Tensor]:
    return {
        "obs": obs_tensor(batch.obs, device),
        "next_obs": obs_tensor(batch.next_obs, device),
        "actions": torch.as_tensor(batch.actions, device=device, dtype=torch.int64),
        "returns": torch.as_tensor(batch.returns, device=device),
        "bootstrap": torch.as_tensor(batch.bootstrap, device=device),
    }


def td_loss(pred_B: torch.Tensor, target_B: torch.Tensor, kind: str) -> torch.Tensor:
    """Eq. 3 (squared error) or the Huber loss of DQN's error clipping."""
    if kind == "mse":
        return torch.nn.functional.mse_loss(pred_B, target_B)
    return torch.nn.functional.smooth_l1_loss(pred_B, target_B)


def clip_and_step(
    loss: torch.Tensor, params: list[nn.Parameter], opt: torch.optim.Optimizer, max_norm: float
) -> None:
    opt.zero_grad(set_to_none=True)
    loss.backward()
    if max_norm > 0:
        nn.utils.clip_grad_norm_(params, max_norm)
    opt.step()


def updates_due(global_step: int, cfg: Config, done: int) -> int:
    """Representation updates owed at ``global_step`` (one every ``train_every`` steps after
    ``learning_starts``), so vectorised environments that advance several steps at once get the
    same number of updates per environment step as a single one."""
    if global_step < cfg.learning_starts:
        return 0
    total = (global_step - cfg.learning_starts) // cfg.train_every + 1
    return max(0, total - done)


def build_seeded(seed: int, fn: Any) -> Any:
    """Run ``fn`` with torch's global RNG seeded, without leaking that state to the caller."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        return fn()
