"""Learning check: does each algorithm reach a mean evaluation return >= 475 on CartPole-v1
within 100k steps? Runs seeds in parallel worker processes (one torch thread each).

    python -m benchmarks.learning [--algos ddqn kddqn bdqn farsighter] [--seeds 1 2 3]

The continuous check (mean evaluation return > -300 on Pendulum-v1 within 30k steps):

    python -m benchmarks.learning --algos naf bnaf farsighter-naf --env Pendulum-v1 \
        --preset continuous --steps 30000 --threshold -300 --workers 1 --name learning_pendulum
"""

from __future__ import annotations

import argparse
import csv
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from benchmarks.common import write_result

ALGO_OVERRIDES: dict[str, dict[str, Any]] = {
    "kddqn": {"k": 3},
    "farsighter": {"k": 3},
    # Pendulum-v1 (dt = 0.05 s): k = 2 is the largest k at which k-NAF learned in our runs.
    "knaf": {"k": 2},
    "farsighter-naf": {"k": 2},
}


def run_one(
    algo: str, seed: int, env: str, steps: int, preset: str, threshold: float
) -> dict[str, Any]:
    import torch

    from farsighter import make_config, train

    torch.set_num_threads(1)
    with tempfile.TemporaryDirectory() as tmp:
        cfg = make_config(
            algo,
            env,
            preset=preset,
            seed=seed,
            total_steps=steps,
            eval_every=5_000,
            eval_episodes=10,
            progress=False,
            run_dir=f"{tmp}/run",
            **ALGO_OVERRIDES.get(algo, {}),
        )
        summary = train(cfg)
        with (Path(tmp) / "run" / "eval.csv").open() as fh:
            evals = [
                (int(r["global_step"]), float(r["eval_return_mean"])) for r in csv.DictReader(fh)
            ]
    first = next((s for s, m in evals if m >= threshold), None)
    return {
        "algo": algo,
        "seed": seed,
        "k": cfg.k,
        "best_eval": max(m for _, m in evals),
        "final_eval": evals[-1][1],
        "first_step_reaching_threshold": first,
        "reached": first is not None,
        "evals": evals,
        "wall_seconds": summary["wall_seconds"],
    }


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--algos", nargs="+", default=["ddqn", "kddqn", "bdqn", "farsighter"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[1, 2, 3])
    parser.add_argument("--env", default="CartPole-v1")
    parser.add_argument("--steps", type=int, default=100_000)
    parser.add_argument("--preset", default="cartpole")
    parser.add_argument("--threshold", type=float, default=475.0)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--name", default="learning_cartpole")
    args = parser.parse_args()
    jobs = [(a, s) for a in args.algos for s in args.seeds]
    with ProcessPoolExecutor(args.workers) as pool:
        futures = [
            pool.submit(run_one, a, s, args.env, args.steps, args.preset, args.threshold)
            for a, s in jobs
        ]
        runs = [f.result() for f in futures]
    table = {
        a: {
            "reached": sum(r["reached"] for r in runs if r["algo"] == a),
            "of": sum(r["algo"] == a for r in runs),
            "best_eval": [r["best_eval"] for r in runs if r["algo"] == a],
            "final_eval": [r["final_eval"] for r in runs if r["algo"] == a],
            "first_step_reaching_threshold": [
                r["first_step_reaching_threshold"] for r in runs if r["algo"] == a
            ],
        }
        for a in args.algos
    }
    write_result(
        args.name,
        {
            "env": args.env,
            "steps": args.steps,
            "preset": args.preset,
            "threshold": args.threshold,
            "summary": table,
            "runs": runs,
        },
    )


if __name__ == "__main__":
    main()
