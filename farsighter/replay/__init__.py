"""Replay: the circular buffer that forms k-step targets at sample time, whole episodes for the
backward update, and hindsight relabelling (:mod:`farsighter.replay.her`)."""

from farsighter.replay.buffer import (
    FINAL,
    TERMINATED,
    TRUNCATED,
    Batch,
    Episode,
    ReplayBuffer,
    VectorStep,
)

__all__ = ["FINAL", "TERMINATED", "TRUNCATED", "Batch", "Episode", "ReplayBuffer", "VectorStep"]
