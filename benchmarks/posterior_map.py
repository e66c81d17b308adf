"""Where is the posterior uncertain? Trains Farsighter (the library's defaults) on bsuite's deep
sea and maps, cell by cell, its predictive standard deviation sqrt(phi(s)^T Cov_a phi(s)) (the
larger of the two actions) against how often the run visited the cell, to show whether the BLR
head's uncertainty is about states (large where the run has not been) or the same everywhere.

    python -m benchmarks.posterior_map --size 20 --episodes 1000 --seed 1

Writes ``benchmarks/results/<name>.json``: the grid of standard deviations, the grid of visits
(from the replay, which holds the whole run), and summaries by class of cell: never reachable
(above the diagonal: a wrong move cannot be undone, so column > row is out of reach), reachable
but never visited, visited rarely (1 to 10 times) and often (more than 100 times).
"""

from __future__ import annotations

import argparse

import numpy as np

from benchmarks.common import train_deep_sea, write_result


def summary(values: np.ndarray) -> dict[str, float] | None:
    if values.size == 0:
        return None
    return {
        "cells": int(values.size),
        "min": round(float(values.min()), 4),
        "median": round(float(np.median(values)), 4),
        "max": round(float(values.max()), 4),
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--size", type=int, default=20)
    p.add_argument("--episodes", type=int, default=1_000)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--name", default="posterior_map")
    p.add_argument(
        "--random-features", type=int, default=0, help="blr.random_features of the run (0: none)"
    )
    args = p.parse_args()

    n = args.size
    cfg, agent, episode_returns = train_deep_sea(
        n,
        args.episodes,
        args.seed,
        max(100, 5 * n),
        **{"blr.random_features": args.random_features},
    )
    returns = np.array(episode_returns)
    replay = agent.replay
    rows = min(int(replay.count[0]), replay.frames.shape[1])
    frames = replay.frames[0, :rows].reshape(rows, -1)
    frames = frames[frames.max(axis=1) > 0]  # the rows past an episode's end are blank
    visits = np.bincount(frames.argmax(axis=1), minlength=n * n).reshape(n, n)
    _, var = agent.q_estimate(np.eye(n * n, dtype=np.float32))
    sd = np.sqrt(var).max(axis=1).reshape(n, n)
    row, col = np.indices((n, n))
    reachable = col <= row
    classes = {
        "never reachable (column > row)": ~reachable,
        "reachable, never visited": reachable & (visits == 0),
        "visited 1 to 10 times": (visits >= 1) & (visits <= 10),
        "visited more than 100 times": visits > 100,
    }
    figures = {
        "agent": "farsighter (preset auto -> general"
        + (
            f", blr.random_features {args.random_features})"
            if args.random_features
            else ", no flag)"
        ),
        "env": cfg.env,
        "seed": args.seed,
        "steps": cfg.total_steps,
        "episodes": len(returns),
        "episodes_with_treasure": int((returns > 0.5).sum()),
        "noise_std": agent.head.noise_std,
        "feature_dim": agent.head.dim,
        "predictive_sd_by_cells": {k: summary(sd[m]) for k, m in classes.items()},
        "corr_log_visits_sd_reachable": round(
            float(np.corrcoef(np.log1p(visits[reachable]), sd[reachable])[0, 1]), 3
        ),
        "predictive_sd": np.round(sd, 4).tolist(),
        "visits": visits.tolist(),
    }
    for k, v in figures["predictive_sd_by_cells"].items():
        print(f"{k}: {v}")
    print(
        "corr(log(1 + visits), sd) over reachable cells:", figures["corr_log_visits_sd_reachable"]
    )
    print(write_result(args.name, figures))


if __name__ == "__main__":
    main()
