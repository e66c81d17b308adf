"""How far ``blr.switch_restart = refit``'s fitted Q-iteration moves a run's values, by the number
of iterations: from a run directory whose checkpoint holds its replay (a run past its switch),
the posterior is restarted and refitted to the replay's rows with the run's own features, capped
at each count in turn, and the targets' range and each action's mean Q over the rows are
written. Used on Taxi-v4 (docs/design.md "The posterior refitted at the switch").

    python -m benchmarks.refit_iterations RUN_DIR --name refit_iterations_taxi_s38
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import torch

from benchmarks.common import write_result
from farsighter.agents import build_agent
from farsighter.agents.farsighter import FarsighterAgent
from farsighter.agents.farsighter_posterior import replay_rows
from farsighter.config import load_config
from farsighter.envs import frame_stack_of, make_env
from farsighter.ops.refit import bellman_targets, refit
from farsighter.rundir import CONFIG_FILE, load_checkpoint


def measure(run_dir: Path, caps: list[int]) -> dict[str, Any]:
    """The refit of ``run_dir``'s replay capped at each of ``caps`` iterations (module doc)."""
    cfg = load_config(run_dir / CONFIG_FILE)
    env = make_env(cfg, seed=0)
    cpu = torch.device("cpu")
    agent = build_agent(
        cfg, env.observation_space, env.action_space, frame_stack=frame_stack_of(cfg), device=cpu
    )
    env.close()
    if not isinstance(agent, FarsighterAgent):
        raise ValueError(f"{run_dir} is a run of {cfg.algo}; accepted: farsighter, bdqn")
    agent.load_state_dict(load_checkpoint(run_dir)["agent"])
    rows = replay_rows(agent.replay, cfg, agent.counters.k, cpu, agent.torso)
    by_cap: list[dict[str, Any]] = []
    for cap in caps:
        agent.head.restart()
        ran = refit(
            agent.head,
            rows,
            cfg.blr.data_weight,
            count=cfg.batch_size / cfg.train_every,
            max_iterations=cap,
        )
        y_N = bellman_targets(rows, agent.head.mean_AD)
        q_A = (rows.phi_ND.float() @ agent.head.mean_AD.T).mean(dim=0)
        by_cap.append(
            {
                "cap": cap,
                "iterations": ran.iterations,
                "accepted": ran.accepted,  # (rejected: the head at its prior)
                "largest_target_fitted": ran.largest,
                "target_max": float(y_N.max()),
                "target_min": float(y_N.min()),
                "mean_q_by_action": [round(float(q), 2) for q in q_A],
            }
        )
        print(by_cap[-1], flush=True)
    return {
        "run_dir": str(run_dir),
        "env": cfg.env,
        "rows": len(rows),
        "window_returns": [float(rows.returns_N.min()), float(rows.returns_N.max())],
        "by_cap": by_cap,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("--iterations", type=int, nargs="+", default=[1, 5, 10, 20, 50, 200])
    parser.add_argument("--name", default="refit_iterations")
    args = parser.parse_args()
    try:
        figures = measure(args.run_dir, args.iterations)
    except ValueError as e:
        parser.error(str(e))
    print(f"wrote {write_result(args.name, figures)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
