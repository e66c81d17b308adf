"""The target network's output for replay rows, kept until the target network changes.

Farsighter samples its minibatches from the latest N transitions (Algorithm 1 line 4) and copies
the target network every N steps (line 8). Within one target period each next state s' is then
drawn about batch_size / train_every times (8 with Table 1's 32 and 4), and its target features
are the same every time: the target network has not moved. :class:`TargetCache` computes them
once per period and hands out the stored rows afterwards, so an update runs the target network
only over the next states it has not seen since the last copy.

Rows are keyed by (stream, logical row of s'): a logical row is written once and never reused
(the replay counts rows per stream and never rewinds; emptying it moves a floor), so the stacked
observation behind a key does not change. The table is direct-mapped (``slot = stream * rows +
logical % rows``) and tagged with the logical row, so a collision or an overwritten slot is a
miss, never a wrong value. The owner calls :meth:`clear` when the target network changes.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import torch

__all__ = ["MAX_ROWS", "TargetCache", "target_cache_rows"]

MAX_ROWS = 1 << 16
"""Most rows a cache holds over all streams (128 MiB of float32 at width 512)."""


class TargetCache:
    """Stored outputs (width ``width``) of a fixed network for replay rows; see the module."""

    def __init__(self, num_envs: int, rows_per_env: int, width: int, device: torch.device) -> None:
        if num_envs < 1 or rows_per_env < 1 or width < 1:
            raise ValueError(
                f"num_envs, rows_per_env and width must be >= 1, got {num_envs}, "
                f"{rows_per_env}, {width}"
            )
        self.rows = int(rows_per_env)
        self.values = torch.zeros(num_envs * self.rows, width, device=device)
        self.tags = np.full(num_envs * self.rows, -1, dtype=np.int64)  # logical row, -1: empty
        self.hits = 0
        self.misses = 0

    def clear(self) -> None:
        """Forget every row (the network whose outputs are stored has changed)."""
        self.tags[:] = -1

    def lookup(
        self,
        e_B: np.ndarray,
        logical_B: np.ndarray,
        compute: Callable[[np.ndarray], torch.Tensor],
    ) -> torch.Tensor:
        """Outputs (B, width) for rows ``(e_B, logical_B)``; ``compute(i)`` gives those of the
        batch positions ``i`` not stored (in that order), which are then stored."""
        slot_B = e_B * self.rows + logical_B % self.rows
        miss = np.flatnonzero(self.tags[slot_B] != logical_B)
        slot_t = torch.from_numpy(slot_B).to(self.values.device)
        out = self.values.index_select(0, slot_t)
        if miss.size:
            fresh = compute(miss)
            miss_t = torch.from_numpy(miss).to(self.values.device)
            out.index_copy_(0, miss_t, fresh)  # from fresh: two keys of a batch may share a slot
            # store one row per slot (the last of the batch's keys there), value and tag alike
            _, first_of_reversed = np.unique(slot_B[miss][::-1], return_index=True)
            keep = miss.size - 1 - first_of_reversed
            keep_t = torch.from_numpy(keep).to(self.values.device)
            self.values.index_copy_(0, slot_t[miss_t[keep_t]], fresh.index_select(0, keep_t))
            self.tags[slot_B[miss[keep]]] = logical_B[miss[keep]]
        self.hits += len(e_B) - miss.size
        self.misses += miss.size
        return out

    def state_dict(self) -> dict[str, Any]:
        live = np.flatnonzero(self.tags >= 0)
        rows = torch.from_numpy(live).to(self.values.device)
        return {
            "slots": live,
            "tags": self.tags[live].copy(),
            "values": self.values.index_select(0, rows).cpu(),
        }

    def load_state_dict(self, state: dict[str, Any] | None) -> None:
        """Restore :meth:`state_dict`; ``None`` (nothing saved) leaves the cache empty."""
        self.clear()
        if state is None:
            return
        slots = np.asarray(state["slots"], dtype=np.int64)
        if slots.size:
            rows = torch.from_numpy(slots).to(self.values.device)
            self.values.index_copy_(0, rows, state["values"].to(self.values.device))
            self.tags[slots] = state["tags"]


def target_cache_rows(cfg: Any) -> int:
    """Rows per stream for a config's recent window (``Config.effective_recent_window``): the
    window and a quarter more, so that the next states of the window's starts (up to k rows
    later) do not collide while k is below a quarter of the window; at most :data:`MAX_ROWS`
    over all streams (beyond that some rows miss and are computed again)."""
    per_env = -(-cfg.effective_recent_window // cfg.num_envs)
    return max(1, min(per_env * 5 // 4 + 1, MAX_ROWS // cfg.num_envs))
