"""Deep sea with the library's defaults, for bsuite's own run length, scored as bsuite scores it.

Issue #25's goal: bsuite's deep sea at N = 10, 14 and 20 solved in at least 4 of 5 seeds by
bsuite's criterion, with the defaults (no preset, no flag). bsuite runs every size for 10,000
episodes and counts a size as solved ("beats dithering") when the running fraction of bad
episodes (bad episodes so far over episodes so far) falls below 0.9 before episode 2^N + 100
(:func:`farsighter.studies.explore.bsuite_solution`). ``farsighter explore`` caps a deep sea run
at 3,000 episodes so that the suite stays affordable; this script runs bsuite's 10,000.

Each (size, seed) is one ``farsighter train`` run of ``farsighter`` on ``farsighter/DeepSea<N>-v0``
(CPU, one torch thread, a greedy evaluation episode every 50 N steps), in ``--out``/N<N>_s<seed>.
A training episode is bad when it did not take the treasure (the run's own success.csv: the
environment's success flag; on the deterministic deep sea that is bsuite's bad episode). A run
that has its summary.json is read, not trained again; a stopped run resumes from its checkpoint
(its success.csv keeps every episode), so the script can be run in parts.

    python -m benchmarks.deep_sea_bsuite --sizes 14 20 --seeds 1 2 3 4 5 [--workers 2]
        [--episodes 10000] [--out DIR] [--name deep_sea_bsuite]
"""

from __future__ import annotations

import argparse
import csv
import json
import multiprocessing as mp
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import REPO, write_result

BSUITE_EPISODES = 10_000  # bsuite's deep sea runs this many episodes at every size


def run_dir(out: Path, size: int, seed: int) -> Path:
    return out / f"N{size}_s{seed}"


def train_one(job: tuple[str, int, int, int]) -> None:
    """Train (or resume) one run; nothing is returned: the run directory holds what it made."""
    import torch

    from farsighter import make_config
    from farsighter.train import train

    out, size, seed, episodes = job
    torch.set_num_threads(1)
    directory = run_dir(Path(out), size, seed)
    cfg = make_config(
        "farsighter",
        f"farsighter/DeepSea{size}-v0",
        seed=seed,
        total_steps=episodes * size,  # every episode lasts N steps
        run_dir=str(directory),
        resume=(directory / "checkpoint.pt").exists(),
        torch_threads=1,
        device="cpu",
        eval_every=50 * size,
        eval_episodes=1,
        progress=False,
    )
    train(cfg)


def measure(directory: Path, size: int) -> dict[str, Any]:
    """bsuite's verdict and the training episodes' successes of one finished run."""
    from farsighter.studies.explore import beats_dithering, bsuite_solution

    with open(directory / "success.csv") as f:
        good = np.array([int(row["success"]) == 1 for row in csv.DictReader(f)])
    summary = json.loads((directory / "summary.json").read_text())
    episode = bsuite_solution(~good, 0.9)
    return {
        "episodes": int(len(good)),
        "bsuite_episode": episode,
        "beats_dithering": beats_dithering(episode, size),
        "first_success": int(np.argmax(good)) + 1 if good.any() else None,
        "successes": int(good.sum()),
        "successes_last_1000": int(good[-1000:].sum()),
        "final_greedy_return": summary.get("final_eval_return"),
        "wall_s": round(summary.get("wall_seconds", float("nan")), 1),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[10, 14, 20])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5])
    parser.add_argument("--episodes", type=int, default=BSUITE_EPISODES)
    parser.add_argument("--workers", type=int, default=1, help="processes, one thread each")
    parser.add_argument("--out", default=str(REPO / "results-build" / "deep_sea_bsuite"))
    parser.add_argument("--name", default="deep_sea_bsuite")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    todo = [
        (str(out), n, s, args.episodes)
        for n in args.sizes
        for s in args.seeds
        if not (run_dir(out, n, s) / "summary.json").exists()
    ]
    if todo:
        with mp.get_context("spawn").Pool(max(1, args.workers)) as pool:
            for _ in pool.imap_unordered(train_one, todo):
                pass
    runs = [
        {"size": n, "seed": s, **measure(run_dir(out, n, s), n)}
        for n in args.sizes
        for s in args.seeds
    ]
    per_size = {
        str(n): f"{sum(r['beats_dithering'] for r in runs if r['size'] == n)}/{len(args.seeds)}"
        for n in args.sizes
    }
    for r in runs:
        print(json.dumps(r))
    print("beats dithering (bsuite):", per_size)
    write_result(
        args.name,
        {
            "episodes_per_run": args.episodes,
            "config": "farsighter, the library's defaults (preset auto: general), one torch "
            "thread, CPU",
            "goal": "N = 10, 14, 20 in at least 4 of 5 seeds",
            "beats_dithering": per_size,
            "runs": runs,
        },
    )


if __name__ == "__main__":
    main()
