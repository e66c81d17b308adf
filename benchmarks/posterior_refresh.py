"""Cost of one posterior refresh at Atari size: D = 100k tuples, d = 512, 18 actions.

batch mode recomputes features and Eq. 8 targets of the D most recent tuples with the Nature CNN
and solves Eq. 9; incremental mode keeps running statistics fed by the representation updates, so
a refresh only factorises 18 precision matrices. Also reports the extra cost per update that the
incremental statistics add.
    python -m benchmarks.posterior_refresh [--samples 100000]
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np
import torch

from benchmarks.common import write_result
from farsighter import make_config
from farsighter.agents.farsighter import FarsighterAgent
from farsighter.replay import VectorStep


def build(mode: str, samples: int, threads: int) -> FarsighterAgent:
    torch.set_num_threads(threads)
    cfg = make_config(
        "farsighter",
        "ALE/MontezumaRevenge-v5",
        buffer_size=samples + 1_000,
        blr__posterior_samples=samples,
        blr__mode=mode,
        k=1,
        device="cpu",
    )
    obs_space = gym.spaces.Box(0, 255, (4, 84, 84), np.uint8)
    agent = FarsighterAgent(
        [cfg], obs_space, gym.spaces.Discrete(18), frame_stack=4, device=torch.device("cpu")
    )
    rng = np.random.default_rng(0)
    frame = np.zeros((1, 4, 84, 84), np.uint8)
    no = np.zeros(1, dtype=bool)
    for i in range(samples + 500):
        frame[0, -1] = (
            rng.integers(0, 255, size=(84, 84), dtype=np.uint8) if i < 64 else frame[0, -1]
        )
        frame[0, -1, i % 84, :] = i % 255  # distinct frames without 100k random draws
        agent.observe([VectorStep(frame, np.array([i % 18]), np.array([0.0]), no, no, None)])
    return agent


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--samples", type=int, default=100_000)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()

    batch = build("batch", args.samples, args.threads)
    t0 = time.perf_counter()
    batch.refresh_posterior()
    batch_s = time.perf_counter() - t0
    del batch

    inc = build("incremental", args.samples, args.threads)
    for _ in range(5):  # warm up
        inc.update()
    t0 = time.perf_counter()
    n_updates = 50
    for _ in range(n_updates):
        inc.update()
    with_stats = (time.perf_counter() - t0) / n_updates
    inc_plain = build("batch", 12_000, args.threads)  # same update without statistics
    for _ in range(5):
        inc_plain.update()
    t0 = time.perf_counter()
    for _ in range(n_updates):
        inc_plain.update()
    without_stats = (time.perf_counter() - t0) / n_updates
    t0 = time.perf_counter()
    inc.refresh_posterior()
    inc_s = time.perf_counter() - t0

    write_result(
        "posterior_refresh",
        {
            "samples_D": args.samples,
            "feature_dim_d": 512,
            "num_actions": 18,
            "posterior_refresh_seconds": {"batch": batch_s, "incremental": inc_s},
            "incremental_goal_seconds": 1.0,
            "update_seconds": {"with_incremental_stats": with_stats, "plain": without_stats},
            "incremental_extra_ms_per_update": 1_000 * (with_stats - without_stats),
            "reference": {"batch_mode_feature_recompute_seconds_reported": 13},
        },
    )


if __name__ == "__main__":
    main()
