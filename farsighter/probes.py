"""Probes of trained runs: what a run's values say, read back from its run directory.

``farsighter inspect <probe> RUN_DIR [RUN_DIR ...] [options]`` loads each run with
:func:`farsighter.load_agent`, reads its ``q_estimate`` (the posterior mean of Q for the Bayesian
agents, the learned Q otherwise) and prints one JSON object with a row per run (``--out PATH``
also writes it to a file). Runs of the discrete-action agents only; nothing is trained and the
run directories are not changed.

* ``action-gaps``: how clearly the run prefers one action. Uniform random walks in the run's own
  environment (evaluation flavour, at most :data:`MAX_STEPS` steps each), and at every state
  passed: the best action's Q (mean, median, 90th percentile, max), the median gap between the
  best and the second-best action, and for the Bayesian agents the median predictive sd of the
  best action's Q. Where the gaps are below the values' own error, the greedy moves are set by
  noise and draws rather than by the task.
* ``tabular-values``: learned Q against the exact Q* of a Gymnasium toy-text task (FrozenLake,
  CliffWalking, Taxi), whose transition table (``env.unwrapped.P``) gives Q* under the run's
  discount by value iteration (a time limit ignored, as a bootstrapped target ignores it): the
  mean of Q - Q* over non-terminal states and actions, Q and Q* at the start state, the states
  whose greedy action is among Q*'s best (ties within 1e-6), and the states next to the goal
  where it is not.
* ``value-calibration``: whether Q promises more than the greedy policy earns. Greedy episodes in
  the run's environment, and at every state visited the Q of the action taken against the
  discounted return that followed (on a deterministic task a Q that were this policy's value
  would match it): the mean and median of Q - G, Q and G at the start state, the largest Q, the
  share of episodes that ended before the time limit (what follows a cut is not observed), and
  with ``--max-return`` the share of states whose Q exceeds that bound on any return.

From Python the probes are :func:`action_gaps`, :func:`tabular_values` and
:func:`value_calibration`, each taking a run directory and returning its row.
"""

from __future__ import annotations

import shlex
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import tyro

from farsighter import jsonio
from farsighter.cli_args import parse_flags
from farsighter.errors import ConfigError, EnvError, FarsighterError

MAX_STEPS = 100
"""Steps of one random walk of ``action-gaps``: the states near the start, which every run
passes."""

Runs = Annotated[
    tuple[str, ...],
    tyro.conf.Positional,
    tyro.conf.arg(metavar="RUN_DIR [RUN_DIR ...]", help_behavior_hint="(one or more)"),
]


def _load(run_dir: str | Path) -> Any:
    """The run's :class:`farsighter.train.Policy`; a run of a continuous-action agent, whose
    ``q_estimate`` is V(s) alone, is refused."""
    from farsighter import algorithms
    from farsighter.train import load_agent

    policy = load_agent(run_dir)
    if policy.config.algo not in algorithms.names_for("discrete"):
        raise ConfigError(
            f"{run_dir} is a run of {policy.config.algo}, whose Q has no value per action; "
            f"accepted: runs of {', '.join(algorithms.names_for('discrete'))}"
        )
    return policy


# ---------------------------------------------------------------------------- action gaps


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


def action_gaps(run_dir: str | Path, episodes: int = 10, seed: int = 0) -> dict[str, Any]:
    """Q and its action gaps over the states of ``episodes`` random walks (module docstring)."""
    policy = _load(run_dir)
    states = walk_states(policy, episodes, seed)
    q, var = policy.agent.q_estimate(states)
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


# ---------------------------------------------------------------------------- tabular values

Table = dict[int, dict[int, list[Any]]]
"""A toy-text transition table: state -> action -> [(probability, next state, reward,
terminated)]."""


def optimal_q(table: Table, gamma: float, tol: float = 1e-10) -> np.ndarray:
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


def terminal_states(table: Table) -> set[int]:
    """States every action of which stays put and ends (FrozenLake's holes and goal)."""
    return {
        s
        for s, actions in table.items()
        if all(all(s2 == s and done for _, s2, _, done in outs) for outs in actions.values())
    }


def next_to_goal(table: Table, ends: set[int]) -> list[int]:
    """Non-terminal states with an action that can end the episode with a positive reward."""
    return [
        s
        for s, actions in table.items()
        if s not in ends
        and any(r > 0 and done for outs in actions.values() for _, _, r, done in outs)
    ]


def tabular_values(run_dir: str | Path) -> dict[str, Any]:
    """Learned Q against the exact Q* of the run's toy-text task (module docstring)."""
    import gymnasium as gym

    policy = _load(run_dir)
    cfg = policy.config
    env = gym.make(cfg.env)
    try:
        table = getattr(env.unwrapped, "P", None)
        start = env.reset(seed=0)[0]
    finally:
        env.close()
    if not isinstance(table, dict) or not isinstance(start, int | np.integer):
        raise EnvError(
            f"{cfg.env} publishes no transition table (env.unwrapped.P over discrete states); "
            "tabular-values needs a Gymnasium toy-text task (FrozenLake, CliffWalking, Taxi)"
        )
    start = int(start)
    q_star = optimal_q(table, cfg.gamma)
    ends = terminal_states(table)
    live = [s for s in range(len(table)) if s not in ends]
    obs = np.eye(len(table), dtype=np.float32)[live]  # the runs' one-hot observations
    q, _ = policy.agent.q_estimate(obs)
    q = np.asarray(q, dtype=np.float64)
    err = q - q_star[live]
    best = q_star[live] >= q_star[live].max(axis=1, keepdims=True) - 1e-6
    greedy = q.argmax(axis=1)
    agrees = best[np.arange(len(live)), greedy]
    return {
        "run_dir": str(run_dir),
        "algo": cfg.algo,
        "env": cfg.env,
        "seed": cfg.seed,
        "gamma": float(cfg.gamma),
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
            for s in next_to_goal(table, ends)
            if not agrees[live.index(s)]
        ],
    }


# ---------------------------------------------------------------------------- value calibration


def discounted_returns(rewards: Sequence[float], gamma: float) -> np.ndarray:
    """G_t = sum_j gamma^j r_{t+j} of every step of one episode."""
    out = np.zeros(len(rewards))
    running = 0.0
    for t in range(len(rewards) - 1, -1, -1):
        running = rewards[t] + gamma * running
        out[t] = running
    return out


def value_calibration(
    run_dir: str | Path, episodes: int = 10, seed: int = 10_000, max_return: float | None = None
) -> dict[str, Any]:
    """Greedy episodes of one run: Q of the action taken against the return that followed
    (module docstring); episode e is reset with seed ``seed + e``."""
    policy = _load(run_dir)
    gamma = float(policy.config.gamma)
    env = policy.make_env(seed=seed)
    q_taken: list[float] = []
    returns: list[float] = []
    starts: list[tuple[float, float]] = []
    ended = 0
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
    row: dict[str, Any] = {
        "run_dir": str(run_dir),
        "env": policy.config.env,
        "algo": policy.config.algo,
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
        row["share_above_max_return"] = round(float(np.mean(q_arr > max_return)), 4)
    return row


# ---------------------------------------------------------------------------- command line


@dataclass(frozen=True)
class ActionGapsArgs:
    """Q and its action gaps over the states of uniform random walks in each run's environment:
    the best action's Q, the median gap to the second best and (Bayesian agents) the median
    predictive sd of the best action's Q."""

    runs: Runs
    """Run directories written by ``farsighter train`` (discrete actions)."""
    episodes: int = 10
    """Random walks per run (each at most 100 steps)."""
    seed: int = 0
    """Seed of the first walk's reset and of the random actions."""
    out: Annotated[str, tyro.conf.arg(metavar="PATH")] = ""
    """Also write the JSON to PATH."""


@dataclass(frozen=True)
class TabularValuesArgs:
    """Learned Q against the exact Q* of a Gymnasium toy-text task (FrozenLake, CliffWalking,
    Taxi) from its transition table: mean Q - Q*, the start state, the states whose greedy
    action is optimal, and the states next to the goal where it is not."""

    runs: Runs
    """Run directories of a toy-text task."""
    out: Annotated[str, tyro.conf.arg(metavar="PATH")] = ""
    """Also write the JSON to PATH."""


@dataclass(frozen=True)
class ValueCalibrationArgs:
    """Q of the greedy action along greedy episodes against the discounted return that
    followed: how much more the values promise than the policy earns."""

    runs: Runs
    """Run directories written by ``farsighter train`` (discrete actions)."""
    episodes: int = 10
    """Greedy episodes per run."""
    seed: int = 10_000
    """Reset seed of the first episode (episode e: seed + e)."""
    max_return: float | None = None
    """A bound on any return: also report the share of visited states whose Q exceeds it."""
    out: Annotated[str, tyro.conf.arg(metavar="PATH")] = ""
    """Also write the JSON to PATH."""


@dataclass(frozen=True)
class Probe:
    args: type
    run: Callable[[Any, str], dict[str, Any]]
    """The row of one run directory, given the parsed arguments."""


PROBES: dict[str, Probe] = {
    "action-gaps": Probe(ActionGapsArgs, lambda a, run: action_gaps(run, a.episodes, a.seed)),
    "tabular-values": Probe(TabularValuesArgs, lambda a, run: tabular_values(run)),
    "value-calibration": Probe(
        ValueCalibrationArgs,
        lambda a, run: value_calibration(run, a.episodes, a.seed, a.max_return),
    ),
}

USAGE = f"""usage: farsighter inspect <probe> RUN_DIR [RUN_DIR ...] [options]

Probe trained runs (discrete actions) and print one JSON object, a row per run:

  action-gaps        Q and the gap between the best and second-best action over random walks:
                     farsighter inspect action-gaps RUN_DIR [--episodes 10] [--seed 0]
  tabular-values     learned Q against the exact Q* of a toy-text task (FrozenLake, Taxi, ...):
                     farsighter inspect tabular-values RUN_DIR
  value-calibration  Q along greedy episodes against the discounted return that followed:
                     farsighter inspect value-calibration RUN_DIR [--episodes 10] [--max-return R]

Every probe takes --out PATH (also write the JSON there); farsighter inspect <probe> --help
lists its options. Probes: {", ".join(PROBES)}.
"""


def main(argv: Sequence[str]) -> int:
    """``farsighter inspect ARGV``."""
    args = list(argv)
    if not args or args[0] in ("-h", "--help"):
        print(USAGE)
        return 0
    probe = PROBES.get(args[0])
    if probe is None:
        raise FarsighterError(f"unknown probe '{args[0]}'; accepted: {', '.join(PROBES)}")
    parsed: Any = parse_flags(probe.args, args[1:], f"farsighter inspect {args[0]}")
    if not parsed.runs:
        raise FarsighterError(f"inspect {args[0]} needs one or more run directories (RUN_DIR)")
    settings = {k: v for k, v in asdict(parsed).items() if k not in ("runs", "out")}
    report = {
        "command": shlex.join(["farsighter", "inspect", *args]),
        "probe": args[0],
        **settings,
        "runs": [probe.run(parsed, run) for run in parsed.runs],
    }
    text = jsonio.dumps(report)
    if parsed.out:
        Path(parsed.out).parent.mkdir(parents=True, exist_ok=True)
        Path(parsed.out).write_text(text + "\n")
    print(text)
    return 0
