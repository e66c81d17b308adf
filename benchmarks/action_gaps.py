"""How clearly does a trained agent prefer one action? Q and its action gaps over visited states.

A greedy policy follows its values only where the best action's Q stands above the others by
more than the values' own error; where the gaps are below it (a one-step target at gamma near
1 values a wrong turn in a room at about gamma V, a gap of about (1 - gamma) V), the moves are
chosen by the noise and the draws, not by the task. This loads run directories, walks each
run's own (evaluation-flavoured) environment with uniform random actions for a number of
episodes, and reads at every state passed the posterior-mean (or learned) Q of every action
and, for the Bayesian agents, the predictive sd of each.

    python -m benchmarks.action_gaps RUN_DIR [RUN_DIR ...] --episodes 10 --name action_gaps

Per run: the number of states, the best action's Q (mean, median, 90th percentile, max), the
median gap between the best and the second-best action, and the median predictive sd (of the
best action's Q, where the agent has one). Writes ``benchmarks/results/<name>.json``.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import write_result

MAX_STEPS = 100  # per walk: the states near the start, which every run passes


def walk_states(policy: Any, episodes: int, seed: int = 0) -> np.ndarray:
    """The observations of ``episodes`` uniform random walks of at most :data:`MAX_STEPS` steps
    in the run's own environment (episode e reset with seed ``seed + e``)."""
    env = policy.make_env(seed=seed)
    rng = np.random.default_rng(seed)
    states = []
    try:
        for episode in range(episodes):
            obs, _ = env.reset(seed=seed + episode)
            for _ in range(MAX_STEPS):
                states.append(np.asarray(obs))
                obs, _, terminated, truncated, _ = env.step(int(rng.integers(env.action_space.n)))
                if terminated or truncated:
                    break
    finally:
        env.close()
    return np.stack(states)


def action_gaps(run_dir: Path, episodes: int) -> dict[str, Any]:
    """The figures of one run (module docstring)."""
    from farsighter.train import load_agent

    policy = load_agent(run_dir)
    states = walk_states(policy, episodes)
    q_estimate = getattr(policy.agent, "q_estimate", None)
    if q_estimate is None:
        raise SystemExit(f"{run_dir}: {policy.config.algo} has no Q estimate to read")
    q, var = q_estimate(states)
    q_SA = np.asarray(q, dtype=np.float64)
    ordered = np.sort(q_SA, axis=1)
    best = ordered[:, -1]
    row: dict[str, Any] = {
        "run_dir": str(run_dir),
        "env": policy.config.env,
        "algo": policy.config.algo,
        "states": int(len(states)),
        "best_q_mean": round(float(best.mean()), 4),
        "best_q_median": round(float(np.median(best)), 4),
        "best_q_p90": round(float(np.quantile(best, 0.9)), 4),
        "best_q_max": round(float(best.max()), 4),
        "gap_median": round(float(np.median(ordered[:, -1] - ordered[:, -2])), 5),
    }
    if var is not None:  # the Bayesian agents' predictive variance
        var_SA = np.asarray(var, dtype=np.float64)
        greedy = q_SA.argmax(axis=1)
        sd = np.sqrt(np.maximum(var_SA[np.arange(len(greedy)), greedy], 0.0))
        row["predictive_sd_median"] = round(float(np.median(sd)), 5)
    return row


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("runs", nargs="+", type=Path, help="run directories (discrete actions)")
    p.add_argument("--episodes", type=int, default=10, help="random walks per run")
    p.add_argument("--name", default="action_gaps")
    args = p.parse_args()
    rows = []
    for run in args.runs:
        rows.append(action_gaps(run, args.episodes))
        print(rows[-1], flush=True)
    write_result(args.name, {"episodes": args.episodes, "runs": rows})


if __name__ == "__main__":
    main()
