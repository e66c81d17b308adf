"""Which environments are back at a state they already visited this episode.

The ``revisit`` redraw rule (``blr.redraw = revisit``) holds a Thompson draw while an episode
keeps reaching new states and redraws when it returns to one: a held draw commits to one
exploratory plan (deep exploration, as a draw per episode does), and a fixed greedy policy that
walks in a circle (MiniGrid's failure under a draw per episode) is broken the first time the
circle closes. A state is its observation, compared exactly through an 8-byte digest; a task
whose observations never repeat (continuous states) thus holds the draw for the episode.
"""

from __future__ import annotations

import hashlib
from typing import Any

import numpy as np

__all__ = ["EpisodeVisits"]


def _digest(row: np.ndarray) -> bytes:
    return hashlib.blake2b(np.ascontiguousarray(row).tobytes(), digest_size=8).digest()


class EpisodeVisits:
    """The observations each of ``num_envs`` environments has visited in its current episode."""

    def __init__(self, num_envs: int) -> None:
        self.seen: list[set[bytes]] = [set() for _ in range(num_envs)]

    def visit(self, obs_E: np.ndarray) -> np.ndarray:
        """Record each environment's observation; True where it was already visited this
        episode."""
        again = np.zeros(len(self.seen), dtype=bool)
        for e, row in enumerate(obs_E):
            key = _digest(row)
            again[e] = key in self.seen[e]
            self.seen[e].add(key)
        return again

    def end(self, done_E: np.ndarray) -> None:
        """Forget the visits of the environments whose episode ended."""
        for e in np.flatnonzero(done_E):
            self.seen[e].clear()

    def state_dict(self) -> dict[str, Any]:
        return {"seen": [sorted(s) for s in self.seen]}

    def load_state_dict(self, state: dict[str, Any] | None) -> None:
        """Restore saved visits; None (a checkpoint from before them) starts afresh."""
        if state is not None and len(state["seen"]) == len(self.seen):
            self.seen = [set(s) for s in state["seen"]]
        else:
            self.seen = [set() for _ in self.seen]
