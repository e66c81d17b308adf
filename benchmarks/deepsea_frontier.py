"""How far does a run's exploration reach on bsuite's deep sea, and how fast? Trains Farsighter
(the library's defaults, plus any ``--set`` overrides) on deep sea N for a number of episodes and
reads the whole run back from its replay: the episode at which each column was first reached
(the frontier: column c can only be reached by c right moves, so the rightmost column reached is
how deep the run has explored), the reachable cells visited, and the episodes that took the
treasure. A run that never takes the treasure still says how close it came, which a solved or
unsolved verdict does not.

    python -m benchmarks.deepsea_frontier --size 24 --episodes 3000 --seed 1
    python -m benchmarks.deepsea_frontier --size 24 --set blr.redraw=episode --name ...

``--act-scale F`` scales the acting draw's noise only (w = mean + F sqrt(cov) z; 0 acts greedily
on the posterior mean, 1 is the library's draw), leaving the targets' posterior noise as it is:
an experiment on where the dithering comes from, by patching ``BLRHead.sample_weights`` in this
process, not an option of the library. ``--target-noise-scale F`` likewise scales the posterior
noise of the sampled targets only (``BLRHead.q_noise_rows``): how much optimism they carry.

Writes ``benchmarks/results/<name>.json``.
"""

from __future__ import annotations

import argparse
import ast
import math
import time
from typing import Any

import numpy as np
import torch

from benchmarks.common import train_deep_sea, write_result


def parse_value(text: str) -> Any:
    """A ``--set`` value: a Python literal where it is one (numbers, True, tuples), else text."""
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return text


def frontier(frames: np.ndarray, n: int) -> dict[str, Any]:
    """The frontier of a deep sea run from its replayed observations (one-hot N x N rows, in
    the order they were stored; blank rows are skipped): episodes start where the grid row is
    0."""
    frames = frames[frames.max(axis=1) > 0]
    cell = frames.argmax(axis=1)
    row, col = cell // n, cell % n
    episode = np.cumsum(row == 0) - 1  # 0-based episode of each stored observation
    columns, first = np.unique(col, return_index=True)  # each column's first observation
    first_episode_of_column = {
        int(c): int(episode[i]) + 1 for c, i in zip(columns, first, strict=True)
    }
    visits = np.bincount(cell, minlength=n * n).reshape(n, n)
    reachable = np.tril(np.ones((n, n), dtype=bool))
    return {
        "rightmost_column": int(col.max()),
        "first_episode_of_column": first_episode_of_column,
        "reachable_cells": int(reachable.sum()),
        "reachable_cells_visited": int((visits[reachable] > 0).sum()),
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--size", type=int, default=24)
    p.add_argument("--episodes", type=int, default=3_000)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--name", default="deepsea_frontier")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    p.add_argument("--act-scale", type=float, default=1.0)
    p.add_argument("--target-noise-scale", type=float, default=1.0)
    args = p.parse_args()

    from farsighter.ops.blr import BLRHead

    overrides = {}
    for item in args.set:
        key, sep, value = item.partition("=")
        if not sep:
            p.error(f"--set takes KEY=VALUE, got {item!r}")
        overrides[key] = parse_value(value)
    if args.act_scale != 1.0:
        original = BLRHead.sample_weights
        scale = args.act_scale

        def scaled(self: BLRHead, n: int, generator: torch.Generator | None = None) -> torch.Tensor:
            w = original(self, n, generator=generator)
            mean = self._mean32_AD.unsqueeze(0)
            return mean + scale * (w - mean)

        BLRHead.sample_weights = scaled  # type: ignore[method-assign]
    if args.target_noise_scale != 1.0:
        noise_rows = BLRHead.q_noise_rows
        factor = args.target_noise_scale

        def louder(self: BLRHead, phi_BD: torch.Tensor, eps_BA: torch.Tensor) -> torch.Tensor:
            return noise_rows(self, phi_BD, eps_BA).mul_(factor)

        BLRHead.q_noise_rows = louder  # type: ignore[method-assign]

    n = args.size
    start = time.perf_counter()
    cfg, agent, episode_returns = train_deep_sea(
        n,
        args.episodes,
        args.seed,
        n * args.episodes,
        **{"buffer_size": max(100_000, n * args.episodes + 1), **overrides},
    )
    seconds = time.perf_counter() - start
    returns = np.array(episode_returns)
    replay = agent.replay
    rows = min(int(replay.count[0]), replay.frames.shape[1])
    reach = frontier(replay.frames[0, :rows].reshape(rows, -1), n)
    treasure = np.flatnonzero(returns > 0.5) + 1
    last = returns[-100:]
    figures = {
        "agent": "farsighter (preset auto -> general)",
        "overrides": overrides,
        "act_scale": args.act_scale,
        "target_noise_scale": args.target_noise_scale,
        "env": cfg.env,
        "seed": args.seed,
        "episodes": int(len(returns)),
        "seconds": round(seconds, 1),
        "episodes_with_treasure": int(treasure.size),
        "first_treasure_episode": int(treasure[0]) if treasure.size else None,
        "treasure_share_last_100": round(float((last > 0.5).mean()), 3) if last.size else math.nan,
        **reach,
    }
    for key in ("episodes_with_treasure", "first_treasure_episode", "rightmost_column"):
        print(f"{key}: {figures[key]}")
    print(
        f"reachable cells visited: {reach['reachable_cells_visited']} of {reach['reachable_cells']}"
    )
    print("first episode of each column:", reach["first_episode_of_column"])
    print(write_result(args.name, figures))


if __name__ == "__main__":
    main()
