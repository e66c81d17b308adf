"""Which learner should ``auto`` give small discrete tasks? Runs candidate learners (optimiser,
replay ratio, target period, width, replay window) for each agent over the exploration tasks and
the CartPole learning check at once, and writes one JSON with every run's measures.

    python -m benchmarks.small_task_learner --learners control adam-step adam-step-uniform \
        --agents farsighter --tasks deepsea10 deepsea14 deepsea20 chain30 --seeds 1 2

Each candidate is a set of overrides applied over the ``general`` preset (what ``auto`` gives a
discrete task that is not Atari) for every agent alike; nothing here is tuned per task. Runs go
to worker processes with one torch thread each. Measures per run:

- deep sea (deterministic): bsuite's criterion, the first episode at which the running fraction
  of bad episodes falls below 0.9 (in the deterministic task an episode is bad exactly when it
  misses the reward), counted when before 2^N + 100; and the greedy criterion (an evaluation
  episode takes the reward);
- chain: the greedy criterion (an evaluation reaches the end of the chain);
- MiniGrid DoorKey (50k steps): the greedy criterion (mean evaluation return >= 0.5, the goal
  reached in more than half of 5 greedy episodes);
- CartPole: the best and final mean evaluation returns (the learning check asks for 475).
"""

from __future__ import annotations

import argparse
import csv
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import write_result

# Over the general preset, for every agent alike.
LEARNERS: dict[str, dict[str, Any]] = {
    # Table 1's control column, what `auto` gave small tasks before: RMSProp 0.0025, an update
    # every 4 steps, a target copy every 1,000 steps, 64 x 64, batch 32.
    "control": {},
    # The cartpole preset's learner (CleanRL dqn.py's optimiser): Adam 5e-4, an update every
    # step, batch 64, a target copy every 500 steps, 128 x 128, a 50k buffer.
    "adam-step": {
        "optimizer": "adam",
        "lr": 0.0005,
        "optim_eps": 1e-8,
        "train_every": 1,
        "batch_size": 64,
        "target_update_every": 500,
        "hidden_sizes": (128, 128),
        "buffer_size": 50_000,
    },
}
LEARNERS["adam-step-uniform"] = {**LEARNERS["adam-step"], "sample_recent": False}
LEARNERS["adam-4"] = {**LEARNERS["adam-step"], "train_every": 4, "lr": 0.001}
LEARNERS["adam-4-uniform"] = {**LEARNERS["adam-4"], "sample_recent": False}
LEARNERS["control-uniform"] = {"sample_recent": False}

# Agents by name: the algorithm and its own overrides (the redraw rules compared).
AGENTS: dict[str, tuple[str, dict[str, Any]]] = {
    "farsighter": ("farsighter", {}),
    "farsighter-revisit": ("farsighter", {"blr.redraw": "revisit"}),
    "farsighter-episode": ("farsighter", {"blr.redraw": "episode"}),
    "farsighter-k": ("farsighter", {"blr.redraw": "k"}),
    "farsighter-cov0.1": ("farsighter", {"blr.cov_scale": 0.1}),
    "farsighter-cov0.01": ("farsighter", {"blr.cov_scale": 0.01}),
    "bdqn": ("bdqn", {}),
    "ddqn": ("ddqn", {}),
    "kddqn": ("kddqn", {}),
    "rnd": ("rnd", {}),
    "ob2i": ("ob2i", {}),
}

DEEP_SEA_MAX_EPISODES = 1_500


def task_of(name: str) -> dict[str, Any]:
    """(env id, steps, evaluation) of a task name: deepseaN, chainN, cartpole."""
    if name.startswith("deepsea"):
        n = int(name[len("deepsea") :])
        episodes = min(2**n + 100, DEEP_SEA_MAX_EPISODES)
        return {
            "env": f"farsighter/DeepSea{n}-v0",
            "steps": n * episodes,
            "eval_every": max(100, 5 * n),
            "eval_episodes": 1,
            "size": n,
        }
    if name.startswith("chain"):
        n = int(name[len("chain") :])
        return {
            "env": f"farsighter/Chain{n}-v0",
            "steps": max(10_000, 1_000 * n),
            "eval_every": 100,
            "eval_episodes": 1,
            "size": n,
        }
    if name.startswith("doorkey"):
        n = int(name[len("doorkey") :])
        return {
            "env": f"MiniGrid-DoorKey-{n}x{n}-v0",
            "steps": 50_000,
            "eval_every": 5_000,
            "eval_episodes": 5,
        }
    if name == "cartpole":
        return {"env": "CartPole-v1", "steps": 100_000, "eval_every": 5_000, "eval_episodes": 10}
    raise SystemExit(f"unknown task '{name}'; accepted: deepseaN, chainN, doorkeyN, cartpole")


def bsuite_episode(returns: np.ndarray, size: int, thresh: float = 0.9) -> float:
    """bsuite's deep sea criterion (:func:`farsighter.studies.explore.bsuite_solution`) with an
    episode counted bad exactly when it misses the reward (true of the deterministic task); NaN
    if never met."""
    from farsighter.studies.explore import bsuite_solution

    episode = bsuite_solution(returns < 0.5, thresh)
    return float("nan") if episode is None else float(episode)


def _read(path: Path) -> dict[str, np.ndarray]:
    if not path.exists():
        return {}
    with path.open() as fh:
        rows = list(csv.DictReader(fh))
    if not rows:
        return {}
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}


def run_one(learner: str, agent: str, task: str, seed: int) -> dict[str, Any]:
    import torch

    from farsighter import make_config, train

    torch.set_num_threads(1)
    t = task_of(task)
    algo, own = AGENTS[agent]
    with tempfile.TemporaryDirectory() as tmp:
        cfg = make_config(
            algo,
            t["env"],
            seed=seed,
            total_steps=t["steps"],
            eval_every=t["eval_every"],
            eval_episodes=t["eval_episodes"],
            progress=False,
            checkpoint_every=0,
            save_replay=False,
            run_dir=f"{tmp}/run",
            torch_threads=1,
            **{**LEARNERS[learner], **own},
        )
        start = time.perf_counter()
        train(cfg)
        wall = time.perf_counter() - start
        m = _read(Path(tmp) / "run" / "metrics.csv")
        e = _read(Path(tmp) / "run" / "eval.csv")
    returns = m.get("episodic_return", np.array([]))
    ev = e.get("eval_return_mean", np.array([]))
    ev_steps = e.get("global_step", np.array([]))
    out: dict[str, Any] = {
        "learner": learner,
        "agent": agent,
        "task": task,
        "seed": seed,
        "steps": t["steps"],
        "episodes": len(returns),
        "wall_s": round(wall, 1),
        "best_eval": float(ev.max()) if len(ev) else float("nan"),
        "final_eval": float(ev[-1]) if len(ev) else float("nan"),
    }
    if task == "cartpole":
        out["solved"] = bool(len(ev) and ev.max() >= 475)
        return out
    hit = np.flatnonzero(ev >= 0.5)
    out["greedy_solved"] = bool(len(hit))
    out["greedy_step"] = float(ev_steps[hit[0]]) if len(hit) else float("nan")
    out["held"] = bool(len(ev) and ev[-1] >= 0.5)
    reward = np.flatnonzero(returns > (0.0 if task.startswith("doorkey") else 0.5))
    out["first_reward_episode"] = float(reward[0] + 1) if len(reward) else float("nan")
    if task.startswith("deepsea"):
        ep = bsuite_episode(returns, t["size"])
        out["bsuite_episode"] = ep
        out["bsuite_solved"] = bool(np.isfinite(ep) and ep < 2 ** t["size"] + 100)
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--learners", nargs="+", default=["control", "adam-step"], choices=LEARNERS)
    p.add_argument("--agents", nargs="+", default=["farsighter"], choices=AGENTS)
    p.add_argument("--tasks", nargs="+", default=["deepsea10", "deepsea14", "chain30"])
    p.add_argument("--seeds", nargs="+", type=int, default=[1, 2])
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--name", default="small_task_learner")
    args = p.parse_args()
    for task in args.tasks:
        task_of(task)
    jobs = [
        (learner, agent, task, seed)
        for task in args.tasks
        for agent in args.agents
        for learner in args.learners
        for seed in args.seeds
    ]
    rows = []
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        for row in pool.map(run_one, *zip(*jobs, strict=True)):
            rows.append(row)
            print({k: v for k, v in row.items() if k not in ("steps",)}, flush=True)
    write_result(
        args.name,
        {
            "learners": {k: LEARNERS[k] for k in args.learners},
            "deep_sea_max_episodes": DEEP_SEA_MAX_EPISODES,
            "runs": rows,
        },
    )


if __name__ == "__main__":
    main()
