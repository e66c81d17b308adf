"""Training-phase throughput of the continuous agents on MuJoCo tasks (CPU, one torch thread).

Steps per second from the first update on (``train_phase_sps`` of the run summary: acting,
environment, replay, TD updates and, for the Bayesian agents, the ELBO updates), with the
``continuous`` preset (one TD update and one ELBO step per environment step, batch 128).

    python -m benchmarks.continuous_sps [--envs Walker2d-v5 FetchPickAndPlace-v4] [--steps 4000]
"""

from __future__ import annotations

import argparse
import tempfile

import torch

from benchmarks.common import write_result

ALGOS = ("naf", "knaf", "bnaf", "farsighter-naf")


def measure(algo: str, env: str, steps: int, learning_starts: int) -> dict[str, float]:
    from farsighter import make_config, train

    with tempfile.TemporaryDirectory() as tmp:
        cfg = make_config(
            algo,
            env,
            preset="continuous",
            total_steps=steps,
            learning_starts=learning_starts,
            eval_every=0,
            eval_episodes=1,
            checkpoint_every=0,
            save_replay=False,
            progress=False,
            device="cpu",
            run_dir=f"{tmp}/run",
        )
        summary = train(cfg)
    return {
        "train_phase_sps": round(summary["train_phase_sps"], 1),
        "overall_sps": round(summary["sps"], 1),
    }


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--envs", nargs="+", default=["Walker2d-v5", "FetchPickAndPlace-v4"])
    parser.add_argument("--algos", nargs="+", default=list(ALGOS))
    parser.add_argument("--steps", type=int, default=4_000)
    parser.add_argument("--learning-starts", type=int, default=1_000)
    args = parser.parse_args()
    torch.set_num_threads(1)
    results = {
        env: {algo: measure(algo, env, args.steps, args.learning_starts) for algo in args.algos}
        for env in args.envs
    }
    write_result(
        "continuous_sps",
        {
            "steps": args.steps,
            "learning_starts": args.learning_starts,
            "preset": "continuous",
            "note": "steps/s after learning_starts, final evaluation excluded, one torch thread; "
            "machine.load_average says what else ran",
            "results": results,
        },
    )


if __name__ == "__main__":
    main()
