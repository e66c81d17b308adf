"""Replay memory that stores every observation once and forms k-step targets when sampling.

Layout (one circular stream per vectorised environment, Dopamine-style validity rules):

* Row ``i`` holds the observation ``o_i`` at which action ``a_i`` was taken, the reward ``r_i``,
  whether that step *terminated* or *truncated* the episode, and ``t_i``, the index of the row
  within its episode. For stacked image observations only the newest frame is stored; the stack
  is rebuilt at sample time from rows ``i-S+1..i`` and frames from before the episode start are
  zeros (matching ``FrameStackObservation(padding_type="zero")`` on the acting side).
* When an episode ends, one extra *final* row holds the last observation (action and reward
  unused, never a start). It lets a time-limit truncation bootstrap from the real last state.
* Rows are addressed by a monotonically increasing logical index; row ``L`` lives at
  ``L % capacity``. Rows below ``count - capacity`` were overwritten.

A start ``L`` is valid when (each rule has a unit test):

1. it is not a final row, and lies in the live range (wraparound);
2. all rows of its frame stack within the episode are still live (oldest rows overwritten);
3. its k-step window is complete: every row up to the bootstrap row ``L + n`` has been written
   (the write cursor), where ``n`` is k or the number of steps to the episode end (a window that
   crosses an episode end stops there: no reward from the next episode);
4. with ``stride``, ``t_L`` is a multiple of k (Algorithm 1 literally: one tuple per k steps);
5. with a recent window, ``L`` is among the latest rows (Algorithm 1 line 4).

**Device mirror** (``device``; the agents ask for it when they train on a GPU, ``Config.
gpu_replay``): the observation rows are also kept in one tensor on that device, with one extra
row of zeros, written as they are added. :meth:`sample` with ``on_device=True`` then forms the
stacks there: the host computes which row each frame of a stack is (the zero row before an
episode start) and sends those indices, not the frames. The indices, and so the minibatch, are
the same as the host gather's.

The records the replay takes and hands out (:class:`VectorStep`, :class:`Batch`,
:class:`Episode`) live in :mod:`farsighter.replay.records` and are re-exported here.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from farsighter.errors import ConfigError
from farsighter.ops.targets import nstep_returns, window_steps
from farsighter.replay.records import Batch, Episode, VectorStep

TERMINATED = np.uint8(1)
TRUNCATED = np.uint8(2)
FINAL = np.uint8(4)
EXPLORATORY = np.uint8(8)
"""The row's action was exploratory (``Config.k_target = cut`` stops k-step windows before it)."""
MIRROR_CHUNK = 65_536  # rows per copy when a loaded replay fills its device mirror
SLOT_ARRAYS = ("frames", "actions", "rewards", "flags", "t_ep")
"""The arrays with a row per stream and slot."""
STREAM_ARRAYS = ("count", "episode_t", "floor")
"""The arrays with a value per stream."""


class ReplayBuffer:
    """Circular replay over ``num_envs`` streams with frame stacking and k-step sampling."""

    def __init__(
        self,
        capacity: int,
        obs_shape: tuple[int, ...],
        obs_dtype: Any,
        *,
        num_envs: int = 1,
        frame_stack: int = 1,
        action_shape: tuple[int, ...] = (),
        action_dtype: Any = np.int32,
        seed: int = 0,
        device: torch.device | str | None = None,
        cut_exploratory: bool = False,
    ) -> None:
        if capacity < 1:
            raise ConfigError(f"replay capacity must be >= 1 (got {capacity})")
        if num_envs < 1 or capacity < num_envs:
            raise ConfigError(
                f"replay capacity ({capacity}) must be at least num_envs ({num_envs}) >= 1"
            )
        if frame_stack < 1:
            raise ConfigError(f"frame_stack must be >= 1 (got {frame_stack})")
        if frame_stack > 1 and (len(obs_shape) < 2 or obs_shape[0] != frame_stack):
            raise ConfigError(
                f"frame_stack={frame_stack} needs observations shaped (stack, ...); got {obs_shape}"
            )
        self.num_envs = num_envs
        self.capacity = capacity // num_envs  # per stream
        self.frame_stack = frame_stack
        self.obs_shape = tuple(obs_shape)
        self.frame_shape = self.obs_shape[1:] if frame_stack > 1 else self.obs_shape
        e, c = num_envs, self.capacity
        self.frames = np.zeros((e, c, *self.frame_shape), dtype=obs_dtype)
        self.actions = np.zeros((e, c, *action_shape), dtype=action_dtype)
        self.rewards = np.zeros((e, c), dtype=np.float32)
        self.flags = np.zeros((e, c), dtype=np.uint8)
        self.t_ep = np.zeros((e, c), dtype=np.int32)
        self.count = np.zeros(e, dtype=np.int64)  # logical rows written per stream
        self.episode_t = np.zeros(e, dtype=np.int32)  # t of the next row per stream
        self.floor = np.zeros(e, dtype=np.int64)  # rows below it were cleared
        self.rng = np.random.default_rng(seed)
        # The device mirror: rows e * capacity + slot, then one row of zeros (stack padding).
        self.mirror: torch.Tensor | None = None
        if device is not None:
            dtype = torch.from_numpy(np.zeros(0, dtype=obs_dtype)).dtype
            self.mirror = torch.zeros((e * c + 1, *self.frame_shape), dtype=dtype, device=device)
        self._written: list[int] = []  # flat rows written by the current add (for the mirror)
        # one stream and no mirror: add() writes with scalar indices (_add_one)
        self.scalar_add = num_envs == 1 and self.mirror is None
        # k_target cut: in the streams marked here, windows stop before a step whose row is
        # flagged EXPLORATORY (per stream: the seeds of a batch switch on their own)
        self.cut_E = np.full(num_envs, cut_exploratory, dtype=bool)

    @property
    def cut_exploratory(self) -> bool:
        """Whether every stream cuts its windows at exploratory actions (``k_target cut``)."""
        return bool(self.cut_E.all())

    @cut_exploratory.setter
    def cut_exploratory(self, cut: bool) -> None:
        self.cut_E[:] = cut

    # ------------------------------------------------------------------ writing
    @property
    def nbytes(self) -> int:
        return sum(
            a.nbytes for a in (self.frames, self.actions, self.rewards, self.flags, self.t_ep)
        )

    def __len__(self) -> int:
        """Live rows over all streams (final rows included)."""
        return int(np.minimum(self.count, self.capacity).sum())

    def _frame(self, obs: np.ndarray) -> np.ndarray:
        return obs[-1] if self.frame_stack > 1 else obs

    def _write(self, e: int, frame: np.ndarray, action: Any, reward: float, flag: int) -> None:
        slot = self.count[e] % self.capacity
        self.frames[e, slot] = frame
        self.actions[e, slot] = action
        self.rewards[e, slot] = reward
        self.flags[e, slot] = flag
        self.t_ep[e, slot] = self.episode_t[e]
        if self.mirror is not None:
            self._written.append(e * self.capacity + int(slot))
        self.count[e] += 1
        self.episode_t[e] += 1

    def add_step(self, step: VectorStep, exploratory_E: np.ndarray | None = None) -> None:
        """Append one :class:`VectorStep` (see :meth:`add`)."""
        self.add(
            step.obs_E,
            step.action_E,
            step.reward_E,
            step.terminated_E,
            step.truncated_E,
            step.final_obs_E,
            exploratory_E,
        )

    def add(
        self,
        obs_E: np.ndarray,
        action_E: np.ndarray,
        reward_E: np.ndarray,
        terminated_E: np.ndarray,
        truncated_E: np.ndarray,
        final_obs_E: np.ndarray | list[Any] | None = None,
        exploratory_E: np.ndarray | None = None,
    ) -> None:
        """Append one step of every stream. ``final_obs_E[e]`` is the last observation of an
        episode that ended at this step (needed for truncations; stored for terminations too).
        ``exploratory_E``: where the action was exploratory (flagged :data:`EXPLORATORY`).

        Every stream's row is written in one array operation, then the final rows of the streams
        whose episode ended (the streams' rows are disjoint, so this order stores what writing
        stream after stream stores)."""
        if self.scalar_add:
            self._add_one(
                obs_E, action_E, reward_E, terminated_E, truncated_E, final_obs_E, exploratory_E
            )
            return
        term_E = np.asarray(terminated_E, dtype=bool).reshape(self.num_envs)
        trunc_E = np.asarray(truncated_E, dtype=bool).reshape(self.num_envs)
        e_E = np.arange(self.num_envs)
        slot_E = self.count % self.capacity
        obs = np.asarray(obs_E)
        self.frames[e_E, slot_E] = obs[:, -1] if self.frame_stack > 1 else obs
        self.actions[e_E, slot_E] = action_E
        self.rewards[e_E, slot_E] = np.asarray(reward_E, dtype=np.float64)
        flags_E = np.where(term_E, TERMINATED, 0) | np.where(trunc_E, TRUNCATED, 0)
        if exploratory_E is not None:
            flags_E |= np.where(np.asarray(exploratory_E, dtype=bool), EXPLORATORY, 0)
        self.flags[e_E, slot_E] = flags_E
        self.t_ep[e_E, slot_E] = self.episode_t
        if self.mirror is not None:
            self._written.extend((e_E * self.capacity + slot_E).tolist())
        self.count += 1
        self.episode_t += 1
        for e in np.flatnonzero(term_E | trunc_E):
            if final_obs_E is None or final_obs_E[e] is None:
                raise ValueError("final_obs_E is required for streams whose episode ended")
            self._write(int(e), self._frame(np.asarray(final_obs_E[e])), 0, 0.0, int(FINAL))
            self.episode_t[e] = 0
        if self._written:
            self._to_mirror(np.asarray(self._written, dtype=np.int64))
            self._written.clear()

    def _add_one(
        self,
        obs_E: Any,
        action_E: Any,
        reward_E: Any,
        terminated_E: Any,
        truncated_E: Any,
        final_obs_E: Any,
        exploratory_E: Any = None,
    ) -> None:
        """:meth:`add` for one stream and no device mirror (``scalar_add``): the rows of the
        array path written with scalar indices (its array operations cost about 60
        microseconds a step on a small task, more than its environment step;
        tests/replay/test_replay.py compares the two row for row)."""
        term = bool(np.asarray(terminated_E).reshape(-1)[0])
        trunc = bool(np.asarray(truncated_E).reshape(-1)[0])
        self._write(
            0,
            self._frame(np.asarray(obs_E)[0]),
            np.asarray(action_E)[0],
            float(np.asarray(reward_E, dtype=np.float64).reshape(-1)[0]),
            int(TERMINATED if term else 0)
            | int(TRUNCATED if trunc else 0)
            | int(EXPLORATORY if exploratory_E is not None and bool(exploratory_E[0]) else 0),
        )
        if term or trunc:
            if final_obs_E is None or final_obs_E[0] is None:
                raise ValueError("final_obs_E is required for streams whose episode ended")
            self._write(0, self._frame(np.asarray(final_obs_E[0])), 0, 0.0, int(FINAL))
            self.episode_t[0] = 0

    def _to_mirror(self, flat_N: np.ndarray) -> None:
        """Copy the host rows ``flat_N`` (flat ``e * capacity + slot``) into the device mirror."""
        assert self.mirror is not None
        rows = self.frames.reshape(-1, *self.frame_shape)[flat_N]
        index = host_to_device(torch.from_numpy(flat_N), self.mirror.device)
        self.mirror.index_copy_(
            0, index, host_to_device(torch.from_numpy(rows), self.mirror.device)
        )

    def clear(self) -> None:
        """Forget every row (Algorithm 1 line 7 empties the buffer when k changes).

        The episode in progress keeps its position so later rows stay consistent; its earlier
        rows are gone, so the first new rows are valid starts only with a complete window.
        """
        self.floor = self.count.copy()

    # ------------------------------------------------------------------ sampling
    def _low(self) -> np.ndarray:
        return np.maximum(np.maximum(self.count - self.capacity, 0), self.floor)

    def valid_mask(
        self, e_B: np.ndarray, start_B: np.ndarray, k: int, stride: int = 1
    ) -> tuple[np.ndarray, np.ndarray]:
        """Validity of logical starts; also returns the window steps n (for valid rows)."""
        low_B = self._low()[e_B]
        count_B = self.count[e_B]
        valid_B = (start_B >= low_B) & (start_B < count_B)
        slot_B = start_B % self.capacity
        flags_B = self.flags[e_B, slot_B]
        t_B = self.t_ep[e_B, slot_B].astype(np.int64)
        valid_B &= (flags_B & FINAL) == 0
        # Rule 2: the stack rows of this episode must still be live.
        valid_B &= start_B - np.minimum(t_B, self.frame_stack - 1) >= low_B
        if stride > 1:
            valid_B &= t_B % stride == 0
        # Rule 3: the window rows and the bootstrap row must be written.
        offsets_K = np.arange(k)
        rows_BK = start_B[:, None] + offsets_K[None, :]
        flags_BK = self.flags[e_B[:, None], rows_BK % self.capacity]
        written_BK = rows_BK < count_B[:, None]
        done_BK = ((flags_BK & (TERMINATED | TRUNCATED)) != 0) & written_BK
        steps_B = window_steps(done_BK)
        valid_B &= start_B + steps_B < count_B  # bootstrap row exists
        return valid_B, steps_B

    def sample(
        self,
        batch_size: int,
        *,
        k: int = 1,
        gamma: float = 0.99,
        recent: int | None = None,
        stride: int = 1,
        max_tries: int = 100,
        on_device: bool = False,
    ) -> Batch:
        """Uniform minibatch of valid k-step windows (rejection sampling, as in Dopamine).

        ``recent``: draw only from the latest ``recent`` transitions over all streams.
        ``on_device``: observations gathered from the device mirror, when there is one.
        """
        low_E, span_E = self.sample_span(k, recent, self.num_envs)
        if not (span_E > 0).any():
            raise ValueError("cannot sample from an empty replay buffer")
        chosen_e: list[np.ndarray] = []
        chosen_l: list[np.ndarray] = []
        chosen_n: list[np.ndarray] = []
        have = 0
        for _ in range(max_tries):
            need = batch_size - have
            n_cand = max(2 * need, 8)
            e_B, start_B = self._draw_rows(low_E, span_E, n_cand, self.rng)
            ok_B, steps_B = self.valid_mask(e_B, start_B, k, stride)
            idx = np.flatnonzero(ok_B)[:need]
            chosen_e.append(e_B[idx])
            chosen_l.append(start_B[idx])
            chosen_n.append(steps_B[idx])
            have += idx.size
            if have == batch_size:
                break
        if have < batch_size:
            raise ValueError(
                "not enough valid transitions to sample from (need a complete k-step window); "
                "collect more steps before learning"
            )
        e_B = np.concatenate(chosen_e)
        start_B = np.concatenate(chosen_l)
        return self.gather(e_B, start_B, k, gamma, on_device=on_device)

    def sample_span(
        self, k: int, recent: int | None, streams: int
    ) -> tuple[np.ndarray, np.ndarray]:
        """The first row a minibatch may start at in each stream, and how many rows follow it:
        the whole live replay, or with ``recent`` the latest ``recent`` transitions of a run of
        ``streams`` streams (split evenly between them). Checks ``k`` and ``recent``."""
        if k < 1:
            raise ConfigError(f"k must be >= 1 (got {k})")
        if recent is not None and recent > self.capacity * streams:
            raise ConfigError(
                f"recent window ({recent}) exceeds the replay capacity ({self.capacity * streams})"
            )
        window = self.capacity if recent is None else max(1, recent // streams)
        low_E = np.maximum(self._low(), self.count - window)
        return low_E, self.count - low_E

    def gather(
        self, e_B: np.ndarray, start_B: np.ndarray, k: int, gamma: float, on_device: bool = False
    ) -> Batch:
        """The k-step windows starting at logical rows ``start_B`` of streams ``e_B`` (valid
        starts only: see :meth:`sample_indices`, which checks them). With ``on_device`` and a
        mirror, ``obs`` and ``next_obs`` are tensors on the mirror's device."""
        rows_BK = (start_B[:, None] + np.arange(k)[None, :]) % self.capacity
        flags_BK = self.flags[e_B[:, None], rows_BK]
        rewards_BK = self.rewards[e_B[:, None], rows_BK]
        returns_B, steps_B, bootstrap_B = nstep_returns(
            rewards_BK,
            (flags_BK & TERMINATED) != 0,
            (flags_BK & TRUNCATED) != 0,
            gamma,
            ((flags_BK & EXPLORATORY) != 0) & self.cut_E[e_B][:, None]
            if self.cut_E.any()
            else None,
        )
        next_B = start_B + steps_B
        slot_B = start_B % self.capacity
        obs: np.ndarray | torch.Tensor
        next_obs: np.ndarray | torch.Tensor
        if on_device and self.mirror is not None:
            both = self.stacked_on_device(
                np.concatenate([e_B, e_B]), np.concatenate([start_B, next_B])
            )
            obs, next_obs = both[: len(e_B)], both[len(e_B) :]
        else:
            obs, next_obs = self.stacked_obs(e_B, start_B), self.stacked_obs(e_B, next_B)
        return Batch(
            obs=obs,
            actions=self.actions[e_B, slot_B],
            returns=returns_B,
            bootstrap=bootstrap_B,
            next_obs=next_obs,
            steps=steps_B,
            env_index=e_B,
            index=start_B,
        )

    def stacked_obs(self, e_B: np.ndarray, logical_B: np.ndarray) -> np.ndarray:
        """Observation at logical rows, rebuilding frame stacks with zeros before episode start."""
        flat_BS = self.stack_rows(e_B, logical_B)
        if self.frame_stack == 1:
            return self.frames.reshape(-1, *self.frame_shape)[flat_BS[:, 0]]
        padding_BS = flat_BS == self.num_envs * self.capacity  # the mirror's zero row
        out = self.frames.reshape(-1, *self.frame_shape)[np.where(padding_BS, 0, flat_BS)]
        out[padding_BS] = 0
        return out

    def stack_rows(self, e_B: np.ndarray, logical_B: np.ndarray) -> np.ndarray:
        """(B, S) flat rows (``e * capacity + slot``) of the frames that stack the observations
        at logical rows ``logical_B``, oldest first; frames from before the episode start point
        at the mirror's zero row (``num_envs * capacity``)."""
        slot_B = logical_B % self.capacity
        s = self.frame_stack
        if s == 1:
            return (e_B * self.capacity + slot_B)[:, None]
        t_B = self.t_ep[e_B, slot_B].astype(np.int64)
        back_S = np.arange(s - 1, -1, -1)  # oldest first
        rows_BS = (logical_B[:, None] - back_S[None, :]) % self.capacity
        flat_BS = e_B[:, None] * self.capacity + rows_BS
        flat_BS[back_S[None, :] > t_B[:, None]] = self.num_envs * self.capacity
        return flat_BS

    def stacked_on_device(self, e_B: np.ndarray, logical_B: np.ndarray) -> torch.Tensor:
        """:meth:`stacked_obs` gathered from the device mirror: only indices cross to it."""
        if self.mirror is None:
            raise ValueError("this replay keeps no device mirror (made without a device)")
        flat_BS = torch.from_numpy(self.stack_rows(e_B, logical_B))
        out = self.mirror[host_to_device(flat_BS, self.mirror.device)]  # (B, S, *frame)
        return out[:, 0] if self.frame_stack == 1 else out

    def recent_indices(self, n: int, streams: slice = slice(None)) -> tuple[np.ndarray, np.ndarray]:
        """(stream, logical index) of up to ``n`` most recent non-final live rows whose next row
        exists: the D tuples of a posterior refresh (k-step windows are formed by the caller).
        ``streams``: of these streams only (one seed's, in a seed replay)."""
        es, ls = [], []
        ids = range(self.num_envs)[streams]
        per = max(1, n // len(ids))
        low_E = np.maximum(self._low(), self.count - per)
        for e in ids:
            logical = np.arange(low_E[e], self.count[e], dtype=np.int64)
            es.append(np.full(logical.shape, e, dtype=np.int64))
            ls.append(logical)
        return np.concatenate(es), np.concatenate(ls)

    def uniform_indices(
        self, n: int, rng: np.random.Generator, streams: slice = slice(None)
    ) -> tuple[np.ndarray, np.ndarray]:
        """(stream, logical index) of ``n`` rows drawn uniformly with replacement from every live
        row of ``streams`` (candidates: invalid starts are dropped by :meth:`sample_indices`)."""
        low_E = self._low()[streams]
        span_E = self.count[streams] - low_E
        if not (span_E > 0).any():
            empty = np.zeros(0, dtype=np.int64)
            return empty, empty.copy()
        e_N, l_N = self._draw_rows(low_E, span_E, n, rng)
        return e_N + range(self.num_envs)[streams].start, l_N

    @staticmethod
    def _draw_rows(
        low_E: np.ndarray, span_E: np.ndarray, n: int, rng: np.random.Generator
    ) -> tuple[np.ndarray, np.ndarray]:
        """n (stream, logical index) pairs, uniform over the rows [low_E, low_E + span_E) of
        every stream (streams weighted by their span), with replacement."""
        # Generator.choice(len(low_E), size=n, p=...)'s own method, with the same draws, less
        # its checks of p (tens of microseconds an update): a uniform per row, then the stream
        # whose cumulative weight it falls under.
        p_E = span_E / span_E.sum()
        u_N = rng.random(n)
        if len(p_E) == 1:
            e_N = np.zeros(n, dtype=np.int64)
        else:
            cdf_E = p_E.cumsum()
            cdf_E /= cdf_E[-1]
            e_N = cdf_E.searchsorted(u_N, side="right").astype(np.int64)
        l_N = low_E[e_N] + (rng.random(n) * span_E[e_N]).astype(np.int64)
        return e_N, l_N

    def sample_indices(
        self,
        e_B: np.ndarray,
        start_B: np.ndarray,
        k: int,
        gamma: float,
        stride: int = 1,
        on_device: bool = False,
    ) -> Batch:
        """k-step batch at the given candidate starts, keeping only the valid ones."""
        ok_B, _ = self.valid_mask(e_B, start_B, k, stride)
        return self.gather(e_B[ok_B], start_B[ok_B], k, gamma, on_device=on_device)

    # ------------------------------------------------------------------ whole episodes
    def episode_bounds(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(stream, logical start, length) of every complete episode whose rows are all live.

        An episode ends with a final row F whose ``t_ep`` is the episode length T, so its
        transitions are rows F - T .. F - 1. It is complete once F is written and fully live when
        F - T is not below the live range (wraparound, ``clear``). Frames from before an episode
        start are zeros in the stacks, so no row outside the episode is needed.
        """
        es, starts, lengths = [], [], []
        low_E = self._low()
        for e in range(self.num_envs):
            hi = int(self.count[e])
            if hi <= low_E[e]:
                continue
            slots = np.flatnonzero(self.flags[e] & FINAL).astype(np.int64)
            # The logical row held by each slot: the latest L < hi with L % capacity == slot.
            final = slots + (hi - 1 - slots) // self.capacity * self.capacity
            length = self.t_ep[e, slots].astype(np.int64)
            start = final - length
            keep = (final < hi) & (start >= low_E[e]) & (length > 0)
            order = np.argsort(start[keep], kind="stable")
            es.append(np.full(int(keep.sum()), e, dtype=np.int64))
            starts.append(start[keep][order])
            lengths.append(length[keep][order])
        if not es:
            empty = np.zeros(0, dtype=np.int64)
            return empty, empty.copy(), empty.copy()
        return np.concatenate(es), np.concatenate(starts), np.concatenate(lengths)

    def sample_episode(self, rng: np.random.Generator | None = None) -> Episode:
        """A complete, fully live episode drawn uniformly (EBU samples whole episodes, Lee et al.
        2019). Only its actions and rewards are copied; gather its observations in chunks with
        ``stacked_obs(env, start + t)``."""
        e_N, start_N, length_N = self.episode_bounds()
        if len(e_N) == 0:
            raise ValueError("no complete episode in the replay buffer yet; collect more steps")
        i = int((self.rng if rng is None else rng).integers(len(e_N)))
        e, start, length = int(e_N[i]), int(start_N[i]), int(length_N[i])
        slots = (start + np.arange(length)) % self.capacity
        return Episode(
            env=e,
            start=start,
            length=length,
            actions=self.actions[e, slots].copy(),
            rewards=self.rewards[e, slots].copy(),
            terminated=bool(self.flags[e, slots[-1]] & TERMINATED),
        )

    def is_live(self, e: int, logical: int) -> bool:
        """Row ``logical`` of stream ``e`` (and every later written row) is still stored."""
        return bool(self._low()[e] <= logical < self.count[e])

    # ------------------------------------------------------------------ checkpointing
    def state_dict(self) -> dict[str, Any]:
        return {**self.streams_state(slice(None)), "rng": self.rng.bit_generator.state}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.load_streams(slice(None), state)
        self.rng.bit_generator.state = state["rng"]
        if self.mirror is not None:  # in chunks: no pinned copy of the whole replay at once
            rows = self.num_envs * self.capacity
            for lo in range(0, rows, MIRROR_CHUNK):
                self._to_mirror(np.arange(lo, min(lo + MIRROR_CHUNK, rows), dtype=np.int64))

    def streams_state(self, streams: slice) -> dict[str, np.ndarray]:
        """The arrays of ``streams`` (copies), the slot arrays (:data:`SLOT_ARRAYS`) cut to the
        slots written so far. A stream's logical row r lands in slot r mod capacity, so the slots
        from the largest count on still hold the zeros they were made with and a checkpoint need
        not carry them: a 100k-row replay after 10k steps saves 10k rows a stream, not 100k."""
        n = min(int(self.count[streams].max(initial=0)), self.capacity)
        state = {key: getattr(self, key)[streams, :n].copy() for key in SLOT_ARRAYS}
        return state | {key: getattr(self, key)[streams].copy() for key in STREAM_ARRAYS}

    def load_streams(self, streams: slice, state: dict[str, Any]) -> None:
        """Inverse of :meth:`streams_state`: the saved slots, zeros after them (a checkpoint of
        full arrays, as earlier versions wrote, loads too), and the streams' counters."""
        for key in SLOT_ARRAYS:
            target = getattr(self, key)[streams]  # a view of the streams
            src = np.asarray(state[key])
            if (
                src.ndim != target.ndim
                or src.shape[0] != target.shape[0]
                or src.shape[2:] != target.shape[2:]
                or src.shape[1] > self.capacity
            ):
                raise ValueError(
                    f"replay '{key}' has shape {src.shape}, expected {target.shape} "
                    f"(or fewer than {self.capacity} slots)"
                )
            target[:, : src.shape[1]] = src
            target[:, src.shape[1] :] = 0
        for key in STREAM_ARRAYS:
            target = getattr(self, key)[streams]
            src = np.asarray(state[key])
            if src.shape != target.shape:
                raise ValueError(f"replay '{key}' has shape {src.shape}, expected {target.shape}")
            target[...] = src


def host_to_device(x: torch.Tensor, device: torch.device | str) -> torch.Tensor:
    """A host tensor on ``device``: as it is on the CPU; to a GPU through pinned memory and a
    non-blocking copy (ordered before the kernels that read it on the same stream)."""
    if torch.device(device).type != "cuda":
        return x
    return x.pin_memory().to(device, non_blocking=True)
