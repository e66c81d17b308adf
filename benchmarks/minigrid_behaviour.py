"""What does an agent do in a MiniGrid room while it trains?

Trains one run (``farsighter train``'s flags after ``--``) with MiniGrid's ``step`` recorded, and
reports per window of steps: how often each action was taken, the mean length of a run of one
action repeated, the mean number of cells an episode visits, and the steps that reached the
goal (a positive reward). A held Thompson draw under a posterior that prefers an action which
does not move the agent (MiniGrid's pick up, drop, toggle and done, in an empty room) shows as
long runs and few cells; epsilon-greedy's uniform actions as runs near 1.

    python -m benchmarks.minigrid_behaviour --windows 0 1000 3000 6000 --name NAME -- \\
        --algo farsighter --env MiniGrid-Empty-5x5-v0 --total-steps 6000 --run-dir DIR

Writes ``benchmarks/results/<name>.json``.
"""

from __future__ import annotations

import argparse
from collections import Counter
from typing import Any

from benchmarks.common import write_result

Step = tuple[int, int, tuple[int, int], float]
"""One recorded step: the episode's step count after it, the action, the cell, the reward."""


def record(train_args: list[str]) -> list[Step]:
    """Every MiniGrid step of one ``farsighter train`` run, in order. Evaluations step MiniGrid
    too: with ``--eval-every`` beyond the run only the final evaluation's steps come, after the
    training's, so the windows up to ``--total-steps`` are the training steps alone."""
    import minigrid.minigrid_env as minigrid_env

    from farsighter.cli import main as cli

    steps: list[Step] = []
    original = minigrid_env.MiniGridEnv.step

    def step(self: Any, action: Any) -> Any:
        out = original(self, action)
        pos = (int(self.agent_pos[0]), int(self.agent_pos[1]))
        steps.append((int(self.step_count), int(action), pos, float(out[1])))
        return out

    minigrid_env.MiniGridEnv.step = step  # type: ignore[method-assign]
    try:
        cli(["train", *train_args])
    finally:
        minigrid_env.MiniGridEnv.step = original  # type: ignore[method-assign]
    return steps


def summarise(steps: list[Step], lo: int, hi: int) -> dict[str, Any]:
    """The behaviour of steps [lo, hi): action counts, mean same-action run, cells an episode
    (episodes that start inside the window), goals reached."""
    window = steps[lo:hi]
    runs, run, last = [], 0, None
    cells: list[int] = []
    seen: set[tuple[int, int]] = set()
    for count, action, pos, _ in window:
        if count == 1 and seen:  # the first step of an episode closes the one before
            cells.append(len(seen))
            seen = set()
        seen.add(pos)
        run = run + 1 if action == last else 1
        last = action
        runs.append(run)
    return {
        "steps": [lo, lo + len(window)],
        "actions": dict(sorted(Counter(a for _, a, _, _ in window).items())),
        "mean_same_action_run": round(sum(runs) / max(1, len(runs)), 3),
        "cells_per_episode": round(sum(cells) / len(cells), 3) if cells else None,
        "goals": sum(1 for *_, reward in window if reward > 0),
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--windows", type=int, nargs="+", default=[0, 1000, 3000, 6000])
    p.add_argument("--name", default="minigrid_behaviour")
    p.add_argument("train", nargs=argparse.REMAINDER, help="-- then farsighter train's flags")
    args = p.parse_args()
    train_args = args.train[1:] if args.train[:1] == ["--"] else args.train
    steps = record(train_args)
    edges = args.windows
    windows = [summarise(steps, lo, hi) for lo, hi in zip(edges, edges[1:], strict=False)]
    for w in windows:
        print(w, flush=True)
    write_result(args.name, {"train": train_args, "windows": windows})


if __name__ == "__main__":
    main()
