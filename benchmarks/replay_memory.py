"""Bytes per stored Atari transition in a 1M-transition replay (goal <= 7,100).

The buffer is allocated at full size and written for real (every frame slot touched), and the
process's resident memory growth is measured beside the arrays' own size.
    python benchmarks/replay_memory.py [--capacity 1000000]
"""

from __future__ import annotations

import argparse
import resource

import numpy as np

from benchmarks.common import write_result
from farsighter.replay import ReplayBuffer


def rss_bytes() -> int:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * resource.getpagesize()


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--capacity", type=int, default=1_000_000)
    args = parser.parse_args()
    before = rss_bytes()
    buf = ReplayBuffer(args.capacity, (4, 84, 84), np.uint8, frame_stack=4)
    rng = np.random.default_rng(0)
    obs = rng.integers(0, 255, size=(1, 4, 84, 84), dtype=np.uint8)
    zero = np.zeros(1, dtype=bool)
    episode = 2_000  # ~ a long Atari episode: one extra final row per episode
    for i in range(args.capacity):
        end = (i + 1) % episode == 0
        obs[0, -1, 0, 0] = i % 251
        buf.add(
            obs,
            np.array([i % 18]),
            np.array([1.0]),
            np.array([end]),
            zero,
            [obs[0]] if end else None,
        )
    after = rss_bytes()
    # Final rows (one per episode) take slots too: count only real transitions held.
    held = int(((buf.flags[0] & 4) == 0).sum())
    write_result(
        "replay_memory",
        {
            "capacity": args.capacity,
            "transitions_held": held,
            "bytes_per_transition": buf.nbytes / held,
            "rss_bytes_per_transition": (after - before) / held,
            "array_bytes_total": buf.nbytes,
            "goal_bytes_per_transition": 7_100,
            "reference": {"dopamine": 7_065, "floor_84x84": 7_056, "cleanrl": 28_244},
            "layout": "one uint8 84x84 frame + int32 action + float32 reward + uint8 flags + "
            "int32 episode step per row; stacks rebuilt at sample time; one final row per episode",
        },
    )


if __name__ == "__main__":
    main()
