"""Seeds in one process against one seed alone: total environment steps per second.

Issue #27's goal: 16 seeds of one config in one process train at a total of at least 8x the
steps per second of one seed alone, on a small task (CartPole with CleanRL ``dqn.py``'s settings,
and deep sea N = 20 with the library's defaults). Each entry is one child process:

* ``alone``: ``farsighter.train.train`` on seed 1, one torch thread;
* ``batch S, T threads``: ``farsighter.seeds.train_seeds`` on seeds 1..S as one batch, with T
  torch threads (2 uses both cores of this machine for the batched products).

Steps/s is every seed's environment steps over the wall time of the training call (the final
evaluation and checkpoint excluded: :class:`farsighter.session.RunLog`'s ``loop_end``; the
one-time import of ``torch._dynamo`` made before the clock starts), the same count for the run
alone and the batch. Rounds interleave the entries, so that the machine's drift
falls on all of them alike.

    python -m benchmarks.seeds_sps [--algo ddqn|farsighter|rnd] [--tasks cartpole deepsea]
        [--seeds 16 [64 ...]] [--rounds 2] [--device cpu|cuda]

``--algo farsighter`` runs Farsighter (the library's defaults: the ``general`` preset, k = 10,
a draw held for k steps) with the same task settings (``--tasks mountaincar``: MountainCar-v0
with the defaults, 10k steps, not part of the goal), batched by
:class:`farsighter.agents.farsighter.FarsighterAgent`.

``--phases`` instead times where a batch step goes (one child per task, 16 seeds, one thread):
microseconds per batch step in the batch's ``greedy`` forward, the rest of ``act`` (each seed's
epsilon draws), the environments' ``step``, ``observe``, ``learn``, the seeds' run logs and the
rest of the loop (``seeds_profile.json``).
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
TAG = "SEEDS_SPS_RESULT "
TASKS = ("cartpole", "deepsea", "mountaincar")
GOAL = 8.0


def task_spec(task: str) -> tuple[str, int, dict[str, Any]]:
    """(env id, steps per seed, config values) of a task."""
    from benchmarks.small_sps import CLEANRL_DQN

    if task == "cartpole":
        return "CartPole-v1", 20_000, {**CLEANRL_DQN, "eps_decay_steps": 10_000}
    if task == "mountaincar":  # the library's defaults, as `farsighter explore` runs it
        return "MountainCar-v0", 10_000, {}
    return "farsighter/DeepSea20-v0", 10_000, {}


def _config(
    env: str,
    steps: int,
    values: dict[str, Any],
    tmp: str,
    threads: int,
    algo: str = "ddqn",
    device: str = "cpu",
) -> Any:
    """``algo`` on ``env`` as every entry runs it: on ``device``, no evaluation before the final
    one, quiet (Farsighter with its defaults: the random-feature torso of the general preset)."""
    from farsighter import make_config

    return make_config(
        algo,
        env,
        total_steps=steps,
        run_dir=f"{tmp}/run",
        torch_threads=threads,
        device=device,
        eval_every=0,
        eval_episodes=1,
        progress=False,
        **values,
    )


def run_one(
    env: str,
    steps: int,
    values: dict[str, Any],
    seeds: int,
    threads: int,
    algo: str = "ddqn",
    device: str = "cpu",
) -> dict[str, Any]:
    import torch

    from farsighter.seeds import seed_configs, train_seeds
    from farsighter.session import RunLog
    from farsighter.train import train

    torch.set_num_threads(threads)
    # torch's optimizers import torch._dynamo when the first one is built: 1.75 s once a process
    # (measured), which the clock would charge to the run alone, a third of a CartPole run's
    # 6 s, and inflate the ratios (the figures before session 27 include it)
    import torch._dynamo  # noqa: F401

    ends: list[float] = []
    end_of_training = RunLog.end_of_training

    def mark_end(self: Any) -> None:
        ends.append(time.perf_counter())
        end_of_training(self)

    RunLog.end_of_training = mark_end  # type: ignore[method-assign]
    with tempfile.TemporaryDirectory() as tmp:
        cfg = _config(env, steps, values, tmp, threads, algo, device)
        start = time.perf_counter()
        if seeds == 0:
            summaries = [train(dataclasses.replace(cfg, seed=1))]
        else:
            summaries = train_seeds(seed_configs(cfg, list(range(1, seeds + 1))))
    wall = min(ends) - start
    return {
        "algo": algo,
        "env": env,
        "seeds": max(seeds, 1),
        "alone": seeds == 0,
        "threads": threads,
        "device": device,
        "steps_per_seed": steps,
        "wall_s": round(wall, 2),
        "total_sps": round(max(seeds, 1) * steps / wall, 1),
        "final_eval_returns": [s["final_eval_return"] for s in summaries],
        "preset": cfg.preset,
    }


PHASES = ("greedy", "act", "env.step", "observe", "learn", "log.step")


def profile_one(
    env: str, steps: int, values: dict[str, Any], seeds: int, algo: str = "ddqn"
) -> dict[str, Any]:
    """One batch run with timers around its phases (in this process)."""
    from collections import defaultdict

    import torch

    import farsighter.seeds as seeds_module
    # the module (farsighter.train the attribute is the function the package exports)
    train_module = importlib.import_module("farsighter.train")
    from benchmarks.small_profile import phase_timer
    from farsighter import algorithms
    from farsighter.session import RunLog

    torch.set_num_threads(1)
    spent: dict[str, float] = defaultdict(float)
    timed = phase_timer(spent)

    module = algorithms.get(algo).seed_batch
    batch_class = importlib.import_module(f"farsighter.agents.{module}").SEED_AGENTS
    for name in ("greedy", "act", "observe", "learn"):
        if hasattr(batch_class, name):  # Farsighter's act computes its forward itself
            setattr(batch_class, name, timed(name, getattr(batch_class, name)))
    RunLog.step = timed("log.step", RunLog.step)  # type: ignore[method-assign]
    make_vector_env = train_module.make_vector_env

    def timed_envs(*args: Any, **kwargs: Any) -> Any:
        envs = make_vector_env(*args, **kwargs)
        envs.step = timed("env.step", envs.step)
        return envs

    train_module.make_vector_env = timed_envs
    with tempfile.TemporaryDirectory() as tmp:
        cfg = _config(env, steps, values, tmp, 1, algo)
        start = time.perf_counter()
        seeds_module.train_seeds(seeds_module.seed_configs(cfg, list(range(1, seeds + 1))))
        wall = time.perf_counter() - start
    us = {name: round(1e6 * spent[name] / steps, 1) for name in PHASES}
    us["act"] = round(us["act"] - us["greedy"], 1)  # act's own work (DDQN: the epsilon draws)
    us["rest"] = round(1e6 * wall / steps - sum(us.values()), 1)
    return {
        "algo": algo,
        "env": env,
        "seeds": seeds,
        "steps_per_seed": steps,
        "us_per_batch_step": us,
    }


def measure(
    task: str,
    seeds: int,
    threads: int,
    phases: bool = False,
    algo: str = "ddqn",
    device: str = "cpu",
) -> dict[str, Any]:
    from benchmarks.atari_sps import child_env, fail, run_child

    env_id, steps, values = task_spec(task)
    spec = json.dumps(
        {
            "env": env_id,
            "steps": steps,
            "values": values,
            "seeds": seeds,
            "threads": threads,
            "phases": phases,
            "algo": algo,
            "device": device,
        }
    )
    cmd = [sys.executable, str(Path(__file__).resolve()), "--one", spec]
    env = child_env(threads)  # the repository first on the path, a PYTHONPATH set here after it
    rc, lines, _ = run_child(cmd, REPO, env)
    rows = [text[len(TAG) :] for _, text in lines if text.startswith(TAG)]
    if rc != 0 or not rows:
        fail(f"{task} seeds={seeds} threads={threads}", rc, lines)
    return {**json.loads(rows[-1]), "task": task}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--algo", choices=("ddqn", "farsighter", "rnd"), default="ddqn")
    p.add_argument("--tasks", nargs="+", choices=TASKS, default=["cartpole", "deepsea"])
    p.add_argument(
        "--seeds", type=int, nargs="+", default=[16], help="seeds in a batch (one entry each)"
    )
    p.add_argument(
        "--device",
        default="cpu",
        choices=("cpu", "cuda"),
        help="cuda: every entry on the GPU, the batches with one host thread",
    )
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--name", default="seeds_sps")
    p.add_argument("--phases", action="store_true", help="time the phases of a batch step")
    p.add_argument("--one", help=argparse.SUPPRESS)  # internal: one run, JSON spec
    args = p.parse_args()
    if args.one is not None:
        spec = json.loads(args.one)
        values = {k: tuple(v) if isinstance(v, list) else v for k, v in spec["values"].items()}
        if spec.get("phases"):
            row = profile_one(spec["env"], spec["steps"], values, spec["seeds"], spec["algo"])
        else:
            row = run_one(
                spec["env"],
                spec["steps"],
                values,
                spec["seeds"],
                spec["threads"],
                spec["algo"],
                spec.get("device", "cpu"),
            )
        print(TAG + json.dumps(row))
        return
    from benchmarks.common import write_result

    if args.phases:
        rows = []
        for task in args.tasks:
            seeds = args.seeds[0]
            print(f"{task}: phases of a {seeds}-seed batch step", file=sys.stderr, flush=True)
            rows.append({**measure(task, seeds, 1, phases=True, algo=args.algo), "task": task})
            print(f"  {rows[-1]['us_per_batch_step']}", file=sys.stderr, flush=True)
        write_result("seeds_profile" if args.name == "seeds_sps" else args.name, {"runs": rows})
        return

    # (seeds, threads); 0 = alone. On a GPU the host thread count hardly matters: one each.
    threads = (1,) if args.device == "cuda" else (1, 2)
    entries = [(0, 1)] + [(s, t) for s in args.seeds for t in threads]
    runs = []
    for round_ in range(args.rounds):
        for task in args.tasks:
            for seeds, threads in entries:
                print(
                    f"round {round_ + 1} {task} seeds={seeds or 'alone'} threads={threads}",
                    file=sys.stderr,
                    flush=True,
                )
                row = measure(task, seeds, threads, algo=args.algo, device=args.device)
                runs.append({**row, "round": round_ + 1})
                print(f"  {runs[-1]['total_sps']} steps/s", file=sys.stderr, flush=True)
    ratios = {}
    for task in args.tasks:
        for round_ in range(1, args.rounds + 1):
            mine = [r for r in runs if r["task"] == task and r["round"] == round_]
            alone = next(r["total_sps"] for r in mine if r["alone"])
            for r in mine:
                if not r["alone"]:
                    key = f"{task} {r['seeds']} seeds {r['threads']} thread(s)"
                    ratios.setdefault(key, []).append(round(r["total_sps"] / alone, 2))
    write_result(
        args.name,
        {
            "algo": args.algo,
            "device": args.device,
            "goal": f"16 seeds >= {GOAL}x one seed alone (on 2 CPU cores)",
            "ratio_to_alone": ratios,
            "runs": runs,
        },
    )


if __name__ == "__main__":
    main()
