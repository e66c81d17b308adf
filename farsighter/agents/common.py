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
    cfg: Config,
    obs_space: gym.spaces.Box,
    frame_stack: int,
    seed: int,
    act_space: gym.Space | None = None,
) -> ReplayBuffer:
    """A replay buffer sized for the run; uint8 images keep one byte per pixel. Discrete actions
    are stored as int32; Box actions (``act_space``) as float32 vectors of their shape."""
    shape = obs_space.shape
    assert shape is not None
    action_shape: tuple[int, ...] = ()
    action_dtype: Any = np.int32
    if isinstance(act_space, gym.spaces.Box):
        action_shape, action_dtype = tuple(act_space.shape), np.float32
    return ReplayBuffer(
        cfg.buffer_size,
        tuple(shape),
        obs_space.dtype,
        num_envs=cfg.num_envs,
        frame_stack=frame_stack,
        action_shape=action_shape,
        action_dtype=action_dtype,
        seed=seed,
    )


def obs_tensor(obs: np.ndarray, device: torch.device) -> torch.Tensor:
    """Observations keep their dtype (uint8 frames cross to the device as bytes)."""
    return torch.as_tensor(np.asarray(obs), device=device)


def batch_tensors(batch: Batch, device: torch.device) -> dict[str, torch.Tensor]:
    return {
        "obs": obs_tensor(batch.obs, device),
        "next_obs": obs_tensor(batch.next_obs, device),
        "actions": torch.as_tensor(
            batch.actions,
            device=device,
            dtype=torch.int64 if batch.actions.dtype.kind in "iu" else torch.float32,
        ),
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


def sample_minibatch(replay: ReplayBuffer, cfg: Config, batch_size: int, k: int) -> Batch:
    """A k-step minibatch as the config asks for it: from the latest N transitions with
    ``sample_recent``, one window per k steps with ``stride`` (Algorithm 1 literally). Raises
    ValueError like :meth:`ReplayBuffer.sample` when no complete window is stored yet."""
    return replay.sample(
        batch_size,
        k=k,
        gamma=cfg.gamma,
        recent=cfg.effective_recent_window if cfg.sample_recent else None,
        stride=k if cfg.stride else 1,
    )


def updates_due(global_step: int, cfg: Config, done: int) -> int:
    """Representation updates owed at ``global_step`` (one every ``train_every`` steps after
    ``learning_starts``), so vectorised environments that advance several steps at once get the
    same number of updates per environment step as a single one."""
    if global_step < cfg.learning_starts:
        return 0
    total = (global_step - cfg.learning_starts) // cfg.train_every + 1
    return max(0, total - done)


class UpdateClock:
    """Counts the representation updates an agent has made and says how many are owed.

    After a resume whose checkpoint holds no replay (the ``atari`` preset's default), the agent
    must refill before it updates: :meth:`hold` pauses updates for ``cfg.learning_starts``
    environment steps from the first :meth:`due` call after it (the warm-up a fresh run gets); the
    updates that fall in that window are skipped, not made up afterwards.
    """

    def __init__(self, cfg: Config) -> None:
        self.cfg = cfg
        self.done = 0
        self.hold_until = 0  # no updates before this global step
        self._hold_pending = False

    def hold(self) -> None:
        self._hold_pending = True

    def due(self, global_step: int) -> int:
        """Updates owed now; they are counted as made."""
        if self._hold_pending:
            self.hold_until = global_step + self.cfg.learning_starts
            self._hold_pending = False
        n = updates_due(global_step, self.cfg, self.done)
        self.done += n
        return 0 if global_step < self.hold_until else n

    def state_dict(self) -> dict[str, int]:
        return {"done": self.done, "hold_until": self.hold_until}

    def load_state_dict(self, state: dict[str, int] | int) -> None:
        if isinstance(state, int):  # checkpoints before v0.2 stored the count alone
            self.done, self.hold_until = state, 0
        else:
            self.done, self.hold_until = int(state["done"]), int(state["hold_until"])


def build_seeded(seed: int, fn: Any) -> Any:
    """Run ``fn`` with torch's global RNG seeded, without leaking that state to the caller."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        return fn()


def epsilon_greedy(
    rng: np.random.Generator,
    epsilon: float,
    num_actions: int,
    greedy: Any,
    n: int,
) -> np.ndarray:
    """Epsilon-greedy actions for ``n`` environments; ``greedy()`` (the forward pass) is only
    called when some environment acts greedily."""
    random_E = np.asarray(rng.random(n) < epsilon)
    random_actions_E = np.asarray(rng.integers(0, num_actions, size=n))
    if random_E.all():
        return random_actions_E
    return np.where(random_E, random_actions_E, greedy())


class RunningMeanStd:
    """Running mean and variance over batches (Chan et al.'s parallel update, as in OpenAI
    baselines' ``RunningMeanStd``, which RND and OB2I's code use to normalise bonuses)."""

    def __init__(self, shape: tuple[int, ...] = (), epsilon: float = 1e-4) -> None:
        self.mean = np.zeros(shape, dtype=np.float64)
        self.var = np.ones(shape, dtype=np.float64)
        self.count = epsilon  # a tiny prior count keeps the first update well defined

    def update(self, x_N: np.ndarray) -> None:
        """Add the rows of ``x_N`` (the first axis indexes samples)."""
        x = np.asarray(x_N, dtype=np.float64).reshape(-1, *self.mean.shape)
        if len(x) == 0:
            return
        batch_mean, batch_var, n = x.mean(axis=0), x.var(axis=0), len(x)
        delta = batch_mean - self.mean
        total = self.count + n
        self.mean = self.mean + delta * n / total
        m2 = self.var * self.count + batch_var * n + delta**2 * self.count * n / total
        self.var = m2 / total
        self.count = total

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(self.var)

    def state_dict(self) -> dict[str, Any]:
        return {"mean": self.mean.copy(), "var": self.var.copy(), "count": self.count}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.mean = np.array(state["mean"], dtype=np.float64)
        self.var = np.array(state["var"], dtype=np.float64)
        self.count = float(state["count"])
