"""Does a trained agent's Q promise more than its greedy policy earns?

An optimistic target (a posterior draw added to the next state's value, the larger of the k-step
and one-step targets) lifts Q above what the policy gets, and on a task whose reward ends the
episode the lift works as a bonus for not ending it: every step the episode goes on adds the
target's optimism once more. FrozenLake showed it against the exact Q* (``benchmarks.
tabular_values``); tasks without a published transition table (MiniGrid) have no Q*, but the
greedy policy's own return is measurable. This loads each run directory given, runs greedy
episodes in the run's environment (its own wrappers, evaluation flavour), and compares at every
visited state the Q of the action taken with the discounted return that followed (the policy
and, on a deterministic task, the environment being fixed, a Q that were this policy's value
would match it). Episodes cut by the time limit are counted apart: what follows the cut is not
observed.

    python -m benchmarks.value_calibration RUN_DIR [RUN_DIR ...] [--episodes 10]
        [--max-return 1.0] --name value_calibration

Per run: the mean and median of Q - G over visited states, Q and G at the start state, the
largest Q seen, the share of episodes that ended (terminated) before the time limit, and with
``--max-return`` the share of visited states whose Q exceeds that bound on any return. Writes
``benchmarks/results/<name>.json``.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import write_result


def discounted_returns(rewards: list[float], gamma: float) -> np.ndarray:
    """G_t = sum_j gamma^j r_{t+j} of every step of one episode."""
    out = np.zeros(len(rewards))
    running = 0.0
    for t in range(len(rewards) - 1, -1, -1):
        running = rewards[t] + gamma * running
        out[t] = running
    return out


def calibrate(
    run_dir: Path, episodes: int, seed: int, max_return: float | None = None
) -> dict[str, Any]:
    """Greedy episodes of one run: Q of the action taken against the return that followed."""
    from farsighter.train import load_agent

    policy = load_agent(run_dir)
    gamma = float(policy.config.gamma)
    env = policy.make_env(seed=seed)
    q_taken, returns, starts, ended = [], [], [], 0
    try:
        for episode in range(episodes):
            obs, _ = env.reset(seed=seed + episode)
            qs: list[float] = []
            rewards: list[float] = []
            while True:
                batch = np.asarray(obs)[None]
                q, _ = policy.agent.q_estimate(batch)
                action = int(policy.act(batch)[0])
                qs.append(float(q[0, action]))
                obs, reward, terminated, truncated, _ = env.step(action)
                rewards.append(float(reward))
                if terminated or truncated:
                    ended += bool(terminated)
                    break
            g = discounted_returns(rewards, gamma)
            q_taken.extend(qs)
            returns.extend(g.tolist())
            starts.append((qs[0], float(g[0])))
    finally:
        env.close()
    q_arr, g_arr = np.asarray(q_taken), np.asarray(returns)
    gap = q_arr - g_arr
    result = {
        "run_dir": str(run_dir),
        "env": policy.config.env,
        "gamma": gamma,
        "episodes": episodes,
        "states": int(len(q_arr)),
        "ended_share": ended / episodes,
        "gap_mean": round(float(gap.mean()), 4),
        "gap_median": round(float(np.median(gap)), 4),
        "q_start_mean": round(float(np.mean([q for q, _ in starts])), 4),
        "return_start_mean": round(float(np.mean([g for _, g in starts])), 4),
        "q_max": round(float(q_arr.max()), 4),
    }
    if max_return is not None:
        result["share_above_max_return"] = round(float(np.mean(q_arr > max_return)), 4)
    return result


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("runs", nargs="+", type=Path, help="run directories")
    p.add_argument("--episodes", type=int, default=10)
    p.add_argument("--seed", type=int, default=10_000, help="the first episode's reset seed")
    p.add_argument("--max-return", type=float, default=None, help="a bound on any return")
    p.add_argument("--name", default="value_calibration")
    args = p.parse_args()
    rows = []
    for run in args.runs:
        rows.append(calibrate(run, args.episodes, args.seed, args.max_return))
        print(rows[-1], flush=True)
    write_result(args.name, {"runs": rows})


if __name__ == "__main__":
    main()
