"""Learned Q against the exact Q* of a tabular task: how far trained agents over- or
under-estimate, and whether their greedy action is Q*'s.

A Gymnasium toy-text task (FrozenLake, CliffWalking, Taxi) publishes its transition table
(``env.unwrapped.P``: state -> action -> [(probability, next state, reward, terminated)]), so its
optimal action values under the run's discount are known exactly (value iteration to a fixed
point; a time limit is ignored, as a bootstrapped target ignores it). Each run directory given is
loaded with :func:`farsighter.load_agent`, its ``q_estimate`` (the posterior mean for Bayesian
heads) is read at every non-terminal state's one-hot observation, and the result summarises,
per run: the mean of Q - Q* over states and actions, the same at the start state, the states
whose greedy action is among Q*'s best (ties within 1e-6), and the states next to the goal
(those from which some action reaches a rewarding terminal state) where the greedy action is a
different one than Q*'s.

    python -m benchmarks.tabular_values RUN_DIR [RUN_DIR ...] --name tabular_values_frozenlake

Writes ``benchmarks/results/<name>.json``.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from benchmarks.common import write_result


def optimal_q(
    table: dict[int, dict[int, list[Any]]], gamma: float, tol: float = 1e-10
) -> np.ndarray:
    """Q* (states x actions) of a transition table under discount ``gamma``, by value iteration
    to ``tol``; a terminated transition bootstraps nothing."""
    n_s, n_a = len(table), len(table[0])
    q = np.zeros((n_s, n_a))
    while True:
        v = q.max(axis=1)
        new = np.array(
            [
                [
                    sum(
                        p * (r + (0.0 if done else gamma * v[s2])) for p, s2, r, done in table[s][a]
                    )
                    for a in range(n_a)
                ]
                for s in range(n_s)
            ]
        )
        if np.abs(new - q).max() < tol:
            return new
        q = new


def terminal_states(table: dict[int, dict[int, list[Any]]]) -> set[int]:
    """States every action of which stays put and ends (FrozenLake's holes and goal)."""
    return {
        s
        for s, actions in table.items()
        if all(all(s2 == s and done for _, s2, _, done in outs) for outs in actions.values())
    }


def next_to_goal(table: dict[int, dict[int, list[Any]]], ends: set[int]) -> list[int]:
    """Non-terminal states with an action that can end the episode with a positive reward."""
    return [
        s
        for s, actions in table.items()
        if s not in ends
        and any(r > 0 and done for outs in actions.values() for _, _, r, done in outs)
    ]


def measure(run_dir: Path) -> dict[str, Any]:
    from farsighter import load_agent

    policy = load_agent(run_dir)
    cfg = policy.config
    env = gym.make(cfg.env)
    table = env.unwrapped.P  # type: ignore[attr-defined]
    start = int(env.reset(seed=0)[0])
    env.close()
    q_star = optimal_q(table, cfg.gamma)
    ends = terminal_states(table)
    live = [s for s in range(len(table)) if s not in ends]
    obs = np.eye(len(table), dtype=np.float32)[live]
    q, _ = policy.agent.q_estimate(obs)
    err = q - q_star[live]
    best = q_star[live] >= q_star[live].max(axis=1, keepdims=True) - 1e-6
    greedy = q.argmax(axis=1)
    agrees = best[np.arange(len(live)), greedy]
    near = next_to_goal(table, ends)
    return {
        "run_dir": str(run_dir),
        "algo": cfg.algo,
        "env": cfg.env,
        "seed": cfg.seed,
        "overrides": {"blr.target": cfg.blr.target, "k_target": cfg.k_target},
        "mean_q_minus_q_star": round(float(err.mean()), 4),
        "start_state": {
            "q": [round(float(x), 4) for x in q[live.index(start)]],
            "q_star": [round(float(x), 4) for x in q_star[start]],
        },
        "greedy_is_optimal": f"{int(agrees.sum())}/{len(live)}",
        "next_to_goal_wrong": [
            {
                "state": s,
                "q": [round(float(x), 4) for x in q[live.index(s)]],
                "q_star": [round(float(x), 4) for x in q_star[s]],
            }
            for s in near
            if not agrees[live.index(s)]
        ],
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("runs", nargs="+", type=Path, help="run directories of a toy-text task")
    p.add_argument("--name", default="tabular_values", help="results/<name>.json")
    args = p.parse_args()
    rows = [measure(run) for run in args.runs]
    for row in rows:
        print(
            f"{row['run_dir']}: mean Q - Q* {row['mean_q_minus_q_star']:+.3f}, greedy optimal "
            f"{row['greedy_is_optimal']}, wrong next to the goal {len(row['next_to_goal_wrong'])}"
        )
    write_result(args.name, {"runs": rows})


if __name__ == "__main__":
    main()
