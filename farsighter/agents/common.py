"""Plumbing shared by the agents (defined once): optimizer, schedules, replay, tensors, losses."""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import nn

from farsighter.config import AdaptiveKConfig, Config
from farsighter.ops.adaptive_k import after_refresh
from farsighter.replay import Batch, ReplayBuffer
from farsighter.replay.buffer import host_to_device
from farsighter.stacked import clip_per_seed


def make_optimizer(params: Iterable[nn.Parameter], cfg: Config) -> torch.optim.Optimizer:
    """Table 1's RMSProp (centered, decay 0.95 as in DQN) or Adam."""
    # foreach: one call over every parameter tensor instead of a Python loop over them; the
    # same arithmetic (torch's default on CUDA already; on CPU an update of a small net is
    # a third of a millisecond faster, and the weights are bit-identical).
    if cfg.optimizer == "rmsprop":
        return torch.optim.RMSprop(
            params,
            lr=cfg.lr,
            alpha=cfg.rmsprop_alpha,
            eps=cfg.optim_eps,
            centered=cfg.rmsprop_centered,
            foreach=True,
        )
    return torch.optim.Adam(params, lr=cfg.lr, eps=cfg.optim_eps, foreach=True)


def make_replay(
    cfg: Config,
    obs_space: gym.spaces.Box,
    frame_stack: int,
    seed: int,
    act_space: gym.Space | None = None,
    device: torch.device | None = None,
    kind: type[ReplayBuffer] = ReplayBuffer,
) -> ReplayBuffer:
    """A replay buffer sized for the run; uint8 images keep one byte per pixel. Discrete actions
    are stored as int32; Box actions (``act_space``) as float32 vectors of their shape. On a CUDA
    ``device`` with ``cfg.runtime.gpu_replay`` auto, observations are mirrored there (minibatches are
    gathered on the GPU: :func:`sample_minibatch`). ``kind``: the buffer's class (a subclass of
    :class:`ReplayBuffer`, such as one seed's replay of an agent written over seeds)."""
    shape = obs_space.shape
    assert shape is not None
    action_shape: tuple[int, ...] = ()
    action_dtype: Any = np.int32
    if isinstance(act_space, gym.spaces.Box):
        action_shape, action_dtype = tuple(act_space.shape), np.float32
    return kind(
        cfg.buffer_size,
        tuple(shape),
        obs_space.dtype,
        num_envs=cfg.num_envs,
        frame_stack=frame_stack,
        action_shape=action_shape,
        action_dtype=action_dtype,
        seed=seed,
        cut_exploratory=cfg.k_target == "cut",  # and from blr.optimism's switch on
        device=device if uses_gpu_replay(cfg, device, row_bytes(obs_space, frame_stack)) else None,
    )


def row_bytes(obs_space: gym.spaces.Box, frame_stack: int) -> int:
    """Bytes of one replay row: one frame of a stack, or the whole observation."""
    assert obs_space.shape is not None
    return int(np.prod(obs_space.shape)) // frame_stack * obs_space.dtype.itemsize


MIRROR_SHARE = 0.5  # gpu_replay auto mirrors only what fits in this share of the free GPU memory


def uses_gpu_replay(
    cfg: Config,
    device: torch.device | str | None,
    bytes_per_row: int = 0,
    free_bytes: int | None = None,
) -> bool:
    """``cfg.runtime.gpu_replay`` auto on a CUDA device, when the mirror (``buffer_size`` rows of
    ``bytes_per_row``) fits in half the device's free memory (``free_bytes``, asked of the device
    when not given). A mirror that does not fit is left out with a warning (several runs sharing
    one GPU with big buffers): the minibatches are the same, gathered on the host."""
    if device is None or torch.device(device).type != "cuda" or cfg.runtime.gpu_replay != "auto":
        return False
    need = cfg.buffer_size * bytes_per_row
    if free_bytes is None:
        free_bytes = torch.cuda.mem_get_info(torch.device(device))[0]
    if need <= MIRROR_SHARE * free_bytes:
        return True
    warnings.warn(
        f"gpu_replay: the replay's frames need {need / 2**30:.1f} GiB, more than half of the "
        f"GPU's free {free_bytes / 2**30:.1f} GiB; minibatches are gathered on the host "
        "(a smaller --buffer-size keeps them on the GPU)",
        stacklevel=2,
    )
    return False


def obs_tensor(obs: np.ndarray | torch.Tensor, device: torch.device) -> torch.Tensor:
    """Observations keep their dtype (uint8 frames cross to the device as bytes). To a GPU they
    go through pinned memory with a non-blocking copy, so the host does not wait for it; a
    tensor already there (from a replay's device mirror) is used as it is."""
    return to_device(obs if isinstance(obs, torch.Tensor) else np.asarray(obs), device)


def to_device(
    x: np.ndarray | torch.Tensor, device: torch.device, dtype: torch.dtype | None = None
) -> torch.Tensor:
    """A numpy array on ``device``: as is on the CPU; through pinned memory and a non-blocking
    copy to a GPU (the copy is ordered before any kernel that reads it on the same stream). A
    tensor already on a GPU (a replay's device mirror) is not copied again."""
    if isinstance(x, torch.Tensor) and x.device.type != "cpu":
        return x.to(device=device, dtype=dtype)  # no copy when already there ("cuda" = "cuda:0")
    return host_to_device(torch.as_tensor(x, dtype=dtype), device)


@dataclass(frozen=True)
class TensorBatch:
    """A k-step minibatch on the device, as the agents receive it (B rows)."""

    obs_B: torch.Tensor
    """s_t, in the observation's dtype (uint8 frames stay bytes), shape (B, *obs)."""
    next_obs_B: torch.Tensor
    """s_{t+n}, where the return bootstraps (n <= k), shape (B, *obs)."""
    actions_B: torch.Tensor
    """a_t: int64 (B,) for discrete actions, float32 (B, A) for Box actions."""
    returns_B: torch.Tensor
    """sum_{i<n} gamma^i r_{t+i}, shape (B,)."""
    bootstrap_B: torch.Tensor
    """gamma^n, or 0 where the episode terminated inside the window, shape (B,)."""

    def tensors(self) -> dict[str, torch.Tensor]:
        """The fields by name (a captured step's inputs; :meth:`of` reads them back)."""
        return {name: getattr(self, name) for name in _BATCH_FIELDS}

    @classmethod
    def of(cls, tensors: dict[str, torch.Tensor]) -> TensorBatch:
        return cls(**{name: tensors[name] for name in _BATCH_FIELDS})


_BATCH_FIELDS = tuple(f.name for f in dataclasses.fields(TensorBatch))  # (torch.compile traces it)


def batch_tensors(batch: Batch, device: torch.device) -> TensorBatch:
    return TensorBatch(
        obs_B=obs_tensor(batch.obs, device),
        next_obs_B=obs_tensor(batch.next_obs, device),
        actions_B=to_device(
            batch.actions,
            device,
            dtype=torch.int64 if batch.actions.dtype.kind in "iu" else torch.float32,
        ),
        returns_B=to_device(batch.returns, device),
        bootstrap_B=to_device(batch.bootstrap, device),
    )


def td_loss(pred_B: torch.Tensor, target_B: torch.Tensor, kind: str) -> torch.Tensor:
    """Eq. 3 (squared error) or the Huber loss of DQN's error clipping."""
    if kind == "mse":
        return torch.nn.functional.mse_loss(pred_B, target_B)
    return torch.nn.functional.smooth_l1_loss(pred_B, target_B)


def seed_td_losses(
    pred: torch.Tensor, target: torch.Tensor, kind: str, seeds: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """The loss to differentiate and each seed's :func:`td_loss` over its own rows, (S,), for
    rows laid seed after seed. The loss is the sum of the seeds' means (each seed's gradient is
    its own loss's); for one seed it is :func:`td_loss` itself (the same numbers, a smaller graph:
    the update of a small network costs a tenth less)."""
    if seeds == 1:
        loss = td_loss(pred, target, kind)
        return loss, loss.detach().unsqueeze(0)
    fn = torch.nn.functional.mse_loss if kind == "mse" else torch.nn.functional.smooth_l1_loss
    loss_S = fn(pred.view(seeds, -1), target.view(seeds, -1), reduction="none").mean(1)
    return loss_S.sum(), loss_S.detach()


def clip_and_step(
    loss: torch.Tensor,
    params: list[nn.Parameter],
    opt: torch.optim.Optimizer,
    max_norm: float,
    seeds: int = 1,
) -> None:
    """Backward, the gradients clipped (each seed's by its own norm where ``params`` carry a
    seed axis of ``seeds`` > 1), and the optimizer step."""
    opt.zero_grad(set_to_none=True)
    loss.backward()
    if max_norm > 0 and seeds > 1:
        clip_per_seed(params, seeds, max_norm)
    elif max_norm > 0:
        clip_gradients(params, max_norm)
    opt.step()


def clip_gradients(params: list[nn.Parameter], max_norm: float) -> None:
    """``nn.utils.clip_grad_norm_``, the same numbers. It multiplies every gradient by
    min(1, max_norm / (norm + 1e-6)) even when that is 1, so that a GPU never waits to read the
    norm; on a CPU (outside ``torch.compile``) the norm is already on the host, and the identity
    pass over every gradient is skipped."""
    grads = [p.grad for p in params if p.grad is not None]
    if not grads:
        return
    norm = nn.utils.get_total_norm(grads)
    if norm.device.type != "cpu" or torch.compiler.is_compiling():
        nn.utils.clip_grads_with_norm_(params, max_norm, norm)
        return
    coef = max_norm / (norm + 1e-6)
    if coef.item() < 1.0:
        torch._foreach_mul_(grads, coef)


def sample_minibatch(replay: ReplayBuffer, cfg: Config, batch_size: int, k: int) -> Batch:
    """A k-step minibatch as the config asks for it (:func:`minibatch_args`). Raises ValueError
    like :meth:`ReplayBuffer.sample` when no complete window is stored yet."""
    return replay.sample(batch_size, **minibatch_args(cfg, k))


def minibatch_args(cfg: Config, k: int) -> dict[str, Any]:
    """How a config samples its k-step minibatches (a replay alone's ``sample``, or a seed
    replay's ``sample_seeds``): from the latest N transitions with ``sample_recent``, one
    window per k steps with ``stride`` (Algorithm 1 literally)."""
    return {
        "k": k,
        "gamma": cfg.gamma,
        "recent": cfg.effective_recent_window if cfg.sample_recent else None,
        "stride": k if cfg.stride else 1,
        "on_device": True,  # observations from the replay's device mirror when it keeps one
    }


class RecentRows:
    """The latest ``keep`` rows added, oldest first: a ring buffer, so that adding a minibatch
    copies the minibatch only (keeping them by concatenation copied all ``keep`` rows per add).
    Saved as the ordered rows (or None), so checkpoints hold what they held before."""

    def __init__(self, keep: int) -> None:
        if keep < 1:
            raise ValueError(f"keep must be >= 1, got {keep}")
        self.keep = int(keep)
        self.buf: torch.Tensor | None = None
        self.added = 0  # rows added in all

    def add(self, rows_ND: torch.Tensor) -> None:
        rows_ND = rows_ND[-self.keep :]
        n = rows_ND.shape[0]
        if n == 0:
            return
        if self.buf is None:
            shape = (self.keep, *rows_ND.shape[1:])
            self.buf = torch.empty(shape, dtype=rows_ND.dtype, device=rows_ND.device)
        at = self.added % self.keep
        first = min(n, self.keep - at)
        self.buf[at : at + first] = rows_ND[:first]
        self.buf[: n - first] = rows_ND[first:]
        self.added += n

    def rows(self) -> torch.Tensor | None:
        """The rows kept, oldest first (None before any was added)."""
        if self.buf is None:  # allocated by the first add of a row
            return None
        if self.added < self.keep:
            return self.buf[: self.added]
        at = self.added % self.keep
        return torch.cat([self.buf[at:], self.buf[:at]]) if at else self.buf

    def state_dict(self) -> torch.Tensor | None:
        rows = self.rows()
        return None if rows is None else rows.clone()

    def load_state_dict(self, rows_ND: torch.Tensor | None) -> None:
        self.buf, self.added = None, 0
        if rows_ND is not None:
            self.add(rows_ND)


@dataclass
class Counters:
    """What an agent counts, checkpointed as a whole (:func:`save_state`): a field added here is
    saved and restored without further code. ``k`` has its one owner here: the config gives its
    start value, adaptive k moves it. Agents that count more extend this dataclass."""

    k: int
    updates: int = 0  # representation updates made (see updates_owed)
    hold_until: int = 0  # no updates before this global step (refill after a replay-less resume)
    hold_pending: bool = False  # set on such a resume; the next call of updates_owed starts it
    target_syncs: int = 0  # target updates made every target_update_every steps


def updates_owed(c: Counters, cfg: Config, global_step: int) -> int:
    """Representation updates owed at ``global_step`` (one every ``train_every`` steps after
    ``learning_starts``), counted as made, so vectorised environments that advance several steps
    at once get the same number of updates per environment step as a single one.

    After a resume whose checkpoint holds no replay (the ``atari`` preset's default) the agent
    must refill before it updates: ``hold_pending`` pauses updates for ``learning_starts``
    environment steps from the first call after it (the warm-up a fresh run gets); the updates
    that fall in that window are skipped, not made up afterwards."""
    if c.hold_pending:
        c.hold_until, c.hold_pending = global_step + cfg.learning_starts, False
    n = 0
    if global_step >= cfg.learning_starts:
        n = max(0, (global_step - cfg.learning_starts) // cfg.train_every + 1 - c.updates)
    c.updates += n
    return 0 if global_step < c.hold_until else n


def crossed(c: Counters, name: str, global_step: int, every: int) -> bool:
    """True once each time ``global_step`` passes a multiple of ``every``; the counter ``name``
    records how many multiples have passed (several at once count as one crossing)."""
    n = global_step // every
    if n <= getattr(c, name):
        return False
    setattr(c, name, n)
    return True


def sync_target(
    c: Counters, global_step: int, every: int, *pairs: tuple[nn.Module, nn.Module]
) -> bool:
    """The hard target copy every N steps (Algorithm 1 line 8): ``target <- online`` for each
    ``(online, target)`` pair when a multiple of ``every`` was passed; True when it copied."""
    if not crossed(c, "target_syncs", global_step, every):
        return False
    for online, target in pairs:
        target.load_state_dict(online.state_dict())
    return True


def adapt_k(c: Counters, q_variance: float, ak: AdaptiveKConfig, replay: ReplayBuffer) -> None:
    """Algorithm 1 line 7 after a posterior update: move ``c.k`` and empty the replay when asked."""
    c.k, empty = after_refresh(c.k, q_variance, ak)
    if empty:
        replay.clear()


def save_state(agent: Any, names: Sequence[str], include_replay: bool) -> dict[str, Any]:
    """An agent's checkpoint: each named attribute in its saved form (modules, optimizers and
    anything with ``state_dict``; generators' states; dataclasses as dicts; tensors, arrays and
    plain values as they are), and the replay when asked."""
    state = {name: _saved(_held(agent, name)[0]) for name in names}
    state["replay"] = agent.replay.state_dict() if include_replay else None
    return state


def set_generator_state(gen: torch.Generator, state: torch.Tensor) -> None:
    """``gen.set_state(state)``; where ``state`` was saved by a generator of another device, whose
    state has another form (a CUDA generator's 16 bytes against a CPU one's Mersenne Twister: a
    GPU run loaded or resumed on a CPU, or back), ``gen`` is seeded from the saved bytes instead:
    the same draws for the same checkpoint, though not the stream the saving generator would have
    drawn next."""
    if state.numel() == gen.get_state().numel():
        gen.set_state(state)
        return
    digest = hashlib.sha256(state.cpu().numpy().tobytes()).digest()
    gen.manual_seed(int.from_bytes(digest[:8], "little") >> 1)


def load_state(agent: Any, names: Sequence[str], state: dict[str, Any]) -> None:
    """Inverse of :func:`save_state`. A checkpoint saved without its replay makes the agent
    refill before it updates again (``Counters.hold_pending``)."""
    for name in names:
        (current, owner, attr), value = _held(agent, name), state[name]
        if isinstance(current, np.random.Generator):
            current.bit_generator.state = value
        elif isinstance(current, torch.Generator):
            set_generator_state(current, value)
        elif dataclasses.is_dataclass(current):
            for key, item in value.items():
                setattr(current, key, item)
        elif isinstance(current, torch.optim.Optimizer):
            # torch keeps the given state tensors (no copy on the same device): copy them, so
            # that this agent never shares its optimizer state with the one that saved it
            current.load_state_dict(copy.deepcopy(value))
        elif hasattr(current, "load_state_dict"):
            current.load_state_dict(value)
        elif isinstance(value, torch.Tensor):
            # into the tensor the agent holds when it fits (a captured CUDA graph may read it),
            # else a copy: never the caller's tensor, which a later in-place update would change
            if isinstance(current, torch.Tensor) and current.shape == value.shape:
                current.copy_(value)
            else:
                setattr(owner, attr, value.to(agent.device, copy=True))
        elif isinstance(value, np.ndarray):
            setattr(owner, attr, value.copy())
        else:
            setattr(owner, attr, value)
    if state.get("replay") is not None:
        agent.replay.load_state_dict(state["replay"])
    else:
        agent.counters.hold_pending = True


def _held(agent: Any, key: str) -> tuple[Any, Any, str]:
    """What checkpoint key ``key`` saves: the agent's attribute of that name, or the one its
    ``SAVED_AT`` maps it to (a dotted path such as ``loss.q_target``: pieces that moved into a
    loss or a learner keep the keys they were saved under). Returns it, its owner and its name."""
    owner: Any = agent
    path: list[str] = getattr(agent, "SAVED_AT", {}).get(key, key).split(".")
    for attr in path[:-1]:
        owner = getattr(owner, attr)
    return getattr(owner, path[-1]), owner, path[-1]


def _saved(value: Any) -> Any:
    if isinstance(value, np.random.Generator):
        return value.bit_generator.state
    if isinstance(value, torch.Generator):
        return value.get_state()
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return dataclasses.asdict(value)
    if hasattr(value, "state_dict"):
        return value.state_dict()
    if isinstance(value, np.ndarray):
        return value.copy()
    return value


def build_seeded(seed: int, fn: Any) -> Any:
    """Run ``fn`` with torch's global RNG seeded, without leaking that state to the caller."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        return fn()
