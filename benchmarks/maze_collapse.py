"""Count collapsed runs in maze study directories (issue #10, Algorithm 1's order).

A run has collapsed when its final greedy value at the start state is far below anything a
200-step episode can return (Q(start) < -200) and no training episode of its last quarter reached
the apple. Compare two study directories run on the same seeds (before and after a change):

    python -m benchmarks.maze_collapse /tmp/maze-before studies/maze --name maze_collapse

writes ``benchmarks/results/<name>.json`` with one entry per study and agent.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import write_result
from farsighter.plots import read_csv

MAX_STEPS = 200  # the maze's time limit: a failed episode returns exactly -200


def run_status(run_dir: Path) -> dict[str, Any]:
    probe = read_csv(run_dir / "probe.csv")
    metrics = read_csv(run_dir / "metrics.csv")
    q_final = float(probe["q_start"][-1])
    steps, returns = metrics["global_step"], metrics["episodic_return"]
    last = steps > 0.75 * steps.max()
    success = float((returns[last] > -MAX_STEPS).mean()) if last.any() else 0.0
    return {"q_start": q_final, "success_last_quarter": success}


def study_collapses(study: Path) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for run_dir in sorted((study / "runs").iterdir()):
        if not (run_dir / "probe.csv").exists():
            continue
        agent, _, seed = run_dir.name.rpartition("__s")
        status = run_status(run_dir)
        status["collapsed"] = status["q_start"] < -MAX_STEPS and status["success_last_quarter"] == 0
        out.setdefault(agent, {})[f"seed {seed}"] = status
    for runs in out.values():
        flags = [r["collapsed"] for r in runs.values() if isinstance(r, dict)]
        runs["collapsed_seeds"] = f"{int(np.sum(flags))}/{len(flags)}"
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("studies", nargs="+", type=Path, help="maze study directories")
    parser.add_argument("--name", default="maze_collapse", help="results file name")
    args = parser.parse_args()
    studies = {str(s): study_collapses(s) for s in args.studies}
    for study, agents in studies.items():
        for agent, runs in agents.items():
            print(f"{study}  {agent}: {runs['collapsed_seeds']} collapsed")
    write_result(args.name, {"studies": studies})


if __name__ == "__main__":
    main()
