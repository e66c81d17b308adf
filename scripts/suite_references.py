"""The normalised-score references of the exploration suite (farsighter/studies/suite.yaml).

For every task: ``random`` (score 0, the uniform random policy's expected episodic return) and
``best`` (score 1, the optimal or best known return), each with its source. The tabular tasks'
come from backward induction on their tables; the random return of every other task is measured
with the uniform policy on the environment the agents train on (the library's factory, seed 0),
and the best is worked out per task (below). Prints a table; ``--write`` rewrites the numbers and
sources in suite.yaml. Cheap: about a minute on one core.

    python scripts/suite_references.py [--write] [--tasks ENV ...]
"""

from __future__ import annotations

import argparse
import copy
import re
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

from farsighter.config import make_config
from farsighter.envs import make_env
from farsighter.envs.tabular import TABULAR_TASKS, reference_returns
from farsighter.studies.explore.families import deep_sea_optimal_return
from farsighter.studies.suite_file import SUITE_FILE, load_suite

EPISODES = 1_000
SLOW = {"Acrobot-v1": 200, "LunarLander-v3": 200, "MiniGrid-DoorKey-5x5-v0": 200}
"""Fewer episodes where one is long or slow to step."""
SEED = 0
DOORKEY_LAYOUTS = 100
TABLES = "backward induction on the task's tables"


def uniform_return(env_id: str, episodes: int, seed: int = SEED) -> tuple[float, float]:
    """The mean episodic return of the uniform random policy and its standard error."""
    env = make_env(make_config("ddqn", env_id, preset="auto"), seed=seed)
    returns = []
    env.reset(seed=seed)
    for i in range(episodes):
        if i:
            env.reset()
        total, done = 0.0, False
        while not done:
            _, reward, terminated, truncated, _ = env.step(env.action_space.sample())
            total += float(reward)
            done = terminated or truncated
        returns.append(total)
    env.close()
    x = np.asarray(returns)
    return float(x.mean()), float(x.std(ddof=1) / np.sqrt(len(x)))


def toy_text_best(env_id: str) -> float:
    """The best expected return within the time limit of a Gymnasium toy-text task: backward
    induction on ``env.unwrapped.P`` over the limit, averaged over the start distribution."""
    env = gym.make(env_id)
    u: Any = env.unwrapped
    limit = env.spec.max_episode_steps if env.spec else None
    assert limit, env_id
    S, A = len(u.P), len(u.P[0])
    v = np.zeros(S)
    for _ in range(limit):
        q = np.array(
            [
                [
                    sum(p * (r + (0.0 if d else v[s2])) for p, s2, r, d in u.P[s][a])
                    for a in range(A)
                ]
                for s in range(S)
            ]
        )
        v = q.max(axis=1)
    return float(np.asarray(u.initial_state_distrib) @ v)


def minigrid_best(env_id: str, layouts: int = 1) -> tuple[float, float]:
    """A MiniGrid task's best return, 1 - 0.9 t / T at the fewest steps t to the goal
    (breadth-first over copies of the env, the grid's state in the key), averaged over the
    layouts of ``layouts`` seeds (0, 1, ...); and the mean fewest steps."""
    import minigrid  # noqa: F401  (registers the ids)

    rewards, steps = [], []
    for seed in range(layouts):
        reward, t = _shortest(gym.make(env_id).unwrapped, seed)
        rewards.append(reward)
        steps.append(t)
    return float(np.mean(rewards)), float(np.mean(steps))


def _shortest(env: Any, seed: int) -> tuple[float, int]:
    env.reset(seed=seed)

    def key(e: Any) -> tuple[Any, ...]:
        carrying = e.carrying.encode() if e.carrying else None
        return (tuple(e.agent_pos), e.agent_dir, carrying, e.grid.encode().tobytes())

    a = env.actions
    frontier, seen = [env], {key(env)}
    for t in range(1, env.max_steps + 1):
        nxt = []
        for e in frontier:
            for action in (a.left, a.right, a.forward, a.pickup, a.toggle):
                c = copy.deepcopy(e)
                _, reward, terminated, _, _ = c.step(action)
                if terminated and reward > 0:
                    return float(reward), t
                if not terminated and key(c) not in seen:
                    seen.add(key(c))
                    nxt.append(c)
        frontier = nxt
    raise RuntimeError(f"{env.spec.id if env.spec else env}: no path to the goal (seed {seed})")


def _threshold(env_id: str) -> float:
    threshold = gym.spec(env_id).reward_threshold
    assert threshold is not None, env_id
    return float(threshold)


def best_of(env_id: str) -> tuple[float, str]:
    """The best return of a task that is not tabular, and its source."""
    if re.fullmatch(r"farsighter/(Chain|DriftChain|DeepSea)\d+-v0", env_id):
        return 0.99, "the reward 1 less the move cost 0.01 (0.01 / L a move)"
    if env_id == "farsighter/DeepSeaStochastic10-v0":
        return deep_sea_optimal_return(10, stochastic=True), (
            "bsuite's optimal expected return, (1 - 1/N)^(N - 1) - 0.01 at N = 10 "
            "(explore.deep_sea_optimal_return)"
        )
    if env_id in ("FrozenLake-v1", "Taxi-v4"):
        return toy_text_best(env_id), (
            "backward induction over its time limit on env.unwrapped.P, averaged over the start "
            "distribution"
        )
    if env_id.startswith("MiniGrid-Empty"):  # one layout
        value, steps = minigrid_best(env_id)
        return value, f"the shortest path ({steps:.0f} steps): 1 - 0.9 * {steps:.0f} / max_steps"
    if env_id.startswith("MiniGrid-DoorKey"):  # a layout drawn per episode
        value, steps = minigrid_best(env_id, DOORKEY_LAYOUTS)
        return value, (
            f"the shortest solve (key, door, goal) by breadth-first search, 1 - 0.9 t / max_steps, "
            f"averaged over the layouts of seeds 0-{DOORKEY_LAYOUTS - 1} (mean t {steps:.1f})"
        )
    if env_id == "CartPole-v1":
        return 500.0, "the time limit: +1 a step for 500 steps"
    if env_id in ("Acrobot-v1", "LunarLander-v3"):
        return _threshold(env_id), "best known: Gymnasium's reward_threshold (the solved level)"
    raise KeyError(f"no best return known for {env_id}")


def references(env_id: str) -> dict[str, Any]:
    """The task's random and best returns with their sources (and, measured, the error)."""
    if env_id in TABULAR_TASKS:
        random, best = reference_returns(TABULAR_TASKS[env_id]())
        return {"random": random, "random_source": TABLES, "best": best, "best_source": TABLES}
    episodes = SLOW.get(env_id, EPISODES)
    random, se = uniform_return(env_id, episodes)
    best, source = best_of(env_id)
    return {
        "random": random,
        "random_source": f"uniform policy, {episodes:,} episodes, seed {SEED} "
        "(scripts/suite_references.py)",
        "best": best,
        "best_source": source,
        "se": se,
    }


def _number(x: float) -> str:
    return f"{x:.6g}"


def rewrite(text: str, env_id: str, ref: dict[str, Any]) -> str:
    """suite.yaml with the task's four reference lines replaced (comments and layout kept)."""
    lines = text.splitlines(keepends=True)
    start = next(i for i, line in enumerate(lines) if line.strip() == f"- env: {env_id}")
    indent = len(lines[start]) - len(lines[start].lstrip()) + 2
    for i in range(start + 1, len(lines)):
        stripped = lines[i].lstrip()
        if len(lines[i]) - len(stripped) != indent or stripped.startswith("- "):
            break
        key = stripped.split(":", 1)[0]
        if key in ("random", "best"):
            lines[i] = f"{' ' * indent}{key}: {_number(ref[key])}\n"
        elif key in ("random_source", "best_source"):
            quoted = '"' + ref[key].replace('"', "'") + '"'
            lines[i] = f"{' ' * indent}{key}: {quoted}\n"
    return "".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help="rewrite suite.yaml's references")
    parser.add_argument("--tasks", nargs="*", default=list(load_suite().tasks()), metavar="ENV")
    args = parser.parse_args(argv)
    text = SUITE_FILE.read_text()
    show: Callable[[float], str] = _number
    for env_id in args.tasks:
        ref = references(env_id)
        se = f" +- {show(ref['se'])}" if "se" in ref else ""
        print(f"{env_id}: random {show(ref['random'])}{se} ({ref['random_source']})")
        print(f"{' ' * len(env_id)}  best {show(ref['best'])} ({ref['best_source']})", flush=True)
        text = rewrite(text, env_id, ref)
    if args.write:
        SUITE_FILE.write_text(text)
        print(f"wrote {SUITE_FILE}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
