"""Does a trained agent value reaching MiniGrid's goal above not reaching it?

MiniGrid pays 1 - 0.9 t/T for stepping onto the goal, and the step ends the episode: no later
value is bootstrapped. A target whose optimism adds up at every step the episode goes on (a
posterior draw in the next state's value, the larger of two drawn targets) lifts the value of
every state that does not end the episode; where the lift exceeds what the goal pays, walking
onto the goal is the worst action in the greedy policy's eyes, and the agent learns to avoid
the reward it was meant to find. This loads a run directory, places the agent in every free
cell of the room in every direction (MiniGrid's Empty rooms: nothing but walls and the goal in
the far corner), passes the observation through the run's own wrappers, and reads the
posterior-mean Q of every action.

    python -m benchmarks.minigrid_values RUN_DIR [RUN_DIR ...] --name minigrid_values

Per run: at the two cells beside the goal, facing it, Q of moving forward onto the goal against
the best other action there, the largest reward the goal can pay (1 - 0.9 / T, at the first
step), and the mean of the best Q over all other placements. Writes
``benchmarks/results/<name>.json``.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import write_result

FORWARD = 2
"""MiniGrid's action index of moving forward (turn left 0, turn right 1, forward 2)."""
FACING = {(1, 0): 0, (0, 1): 1}
"""The direction index of facing right (+x) and down (+y)."""


def observation_at(env: Any, pos: tuple[int, int], direction: int) -> np.ndarray:
    """The run's observation of the agent at ``pos`` facing ``direction``: MiniGrid's own, then
    every observation wrapper of ``env`` from the innermost out."""
    wrappers = []
    inner = env
    while hasattr(inner, "env"):
        wrappers.append(inner)
        inner = inner.env
    inner.agent_pos = np.array(pos)
    inner.agent_dir = direction
    obs = inner.gen_obs()
    for wrapper in reversed(wrappers):
        if callable(getattr(wrapper, "observation", None)):
            obs = wrapper.observation(obs)
    return np.asarray(obs, dtype=np.float32)


def goal_values(run_dir: Path) -> dict[str, Any]:
    """Q of stepping onto the goal against the best other action, beside the goal (module
    docstring); the run's environment must be a MiniGrid room with the goal in the far corner."""
    from farsighter.train import load_agent

    policy = load_agent(run_dir)
    env = policy.make_env(seed=0)
    try:
        env.reset(seed=0)
        base = env.unwrapped
        goal = (base.width - 2, base.height - 2)
        if type(base.grid.get(*goal)).__name__ != "Goal":
            raise ValueError(f"{run_dir}: no goal at {goal} (an Empty room is needed)")

        def q_at(pos: tuple[int, int], direction: int) -> np.ndarray:
            q, _ = policy.agent.q_estimate(observation_at(env, pos, direction)[None])
            return np.asarray(q[0], dtype=np.float64)

        beside = []
        for (dx, dy), direction in FACING.items():
            pos = (goal[0] - dx, goal[1] - dy)
            q = q_at(pos, direction)
            others = np.delete(q, FORWARD)
            beside.append(
                {
                    "cell": list(pos),
                    "direction": direction,
                    "q_onto_goal": round(float(q[FORWARD]), 4),
                    "q_best_other": round(float(others.max()), 4),
                    "goal_is_greedy": bool(q.argmax() == FORWARD),
                }
            )
        elsewhere = [
            float(q_at((x, y), d).max())
            for x in range(1, base.width - 1)
            for y in range(1, base.height - 1)
            for d in range(4)
            if (x, y) != goal
        ]
        return {
            "run_dir": str(run_dir),
            "env": policy.config.env,
            "gamma": float(policy.config.gamma),
            "goal_pays_at_most": round(1 - 0.9 / base.max_steps, 4),
            "beside_goal": beside,
            "best_q_mean_elsewhere": round(float(np.mean(elsewhere)), 4),
            "placements": len(elsewhere),
        }
    finally:
        env.close()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("runs", nargs="+", type=Path, help="run directories (MiniGrid Empty rooms)")
    p.add_argument("--name", default="minigrid_values")
    args = p.parse_args()
    rows = []
    for run in args.runs:
        rows.append(goal_values(run))
        print(rows[-1], flush=True)
    write_result(args.name, {"runs": rows})


if __name__ == "__main__":
    main()
