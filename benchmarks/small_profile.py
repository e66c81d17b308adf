"""Where a small task's environment step goes: wall-clock time per phase of the real loop.

Issue #27 item 1: on small tasks the loop's own overhead, not the network, sets the speed. This
runs ``farsighter train`` in process with timers around the agent's ``act``, ``observe`` and
``learn``, the vector env's ``step`` and the run log's ``step`` (everything else of the loop is
"rest"), and reports microseconds per environment step for each, for two small tasks:

* ``cartpole``: CartPole-v1 with CleanRL ``dqn.py``'s settings (those of
  :mod:`benchmarks.small_sps`), 30,000 steps;
* ``deepsea``: bsuite's deep sea N = 20 with the library's defaults (``auto``: the general
  preset), 20,000 steps.

Each algorithm and task runs in its own process, one torch thread. ``--baseline DIR`` runs the
same in the package of another checkout (a git worktree of an older commit) for a before/after
table; the timers wrap whatever vector env that package builds.

    python -m benchmarks.small_profile [--algos ddqn farsighter] [--tasks cartpole deepsea]
        [--baseline DIR] [--name small_profile]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

# The child (--one) imports nothing from benchmarks/: it runs as a script with only the measured
# checkout's package on its path.
REPO = Path(__file__).resolve().parent.parent
TAG = "SMALL_PROFILE_RESULT "
TASKS = ("cartpole", "deepsea")
PHASES = ("act", "env.step", "observe", "learn", "log.step")


def task_spec(task: str) -> tuple[str, int, dict[str, Any]]:
    """(env id, steps, config values) of a task."""
    from benchmarks.small_sps import CLEANRL_DQN

    if task == "cartpole":
        return "CartPole-v1", 30_000, {**CLEANRL_DQN, "eps_decay_steps": 15_000}
    return "farsighter/DeepSea20-v0", 20_000, {}


def phase_timer(seconds: dict[str, float]) -> Any:
    """``timed(name, fn)``: ``fn`` wrapped to add its wall time to ``seconds[name]``."""

    def timed(name: str, fn: Any) -> Any:
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            t0 = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                seconds[name] += time.perf_counter() - t0

        return wrapper

    return timed


def profile(algo: str, env: str, steps: int, values: dict[str, Any]) -> dict[str, Any]:
    """One run with phase timers (in this process: the package on sys.path is measured)."""
    import importlib

    import torch

    from farsighter import make_config
    from farsighter.agents import loop_class
    from farsighter.session import RunLog

    train_module = importlib.import_module("farsighter.train")
    torch.set_num_threads(1)
    seconds: dict[str, float] = defaultdict(float)
    timed = phase_timer(seconds)

    agent_cls = loop_class(algo)
    for name in ("act", "observe", "learn"):
        setattr(agent_cls, name, timed(name, getattr(agent_cls, name)))
    RunLog.step = timed("log.step", RunLog.step)  # type: ignore[method-assign]
    make_vector_env = train_module.make_vector_env

    def timed_envs(*args: Any, **kwargs: Any) -> Any:
        envs = make_vector_env(*args, **kwargs)
        envs.step = timed("env.step", envs.step)  # this instance: whatever class it is
        return envs

    train_module.make_vector_env = timed_envs
    marks: dict[str, float] = {}
    end_of_training = RunLog.end_of_training

    def mark_end(self: Any) -> None:
        marks["end"] = time.perf_counter()
        end_of_training(self)

    RunLog.end_of_training = mark_end  # type: ignore[method-assign]
    act = agent_cls.act

    def mark_first(self: Any, *args: Any, **kwargs: Any) -> Any:
        marks.setdefault("start", time.perf_counter())
        return act(self, *args, **kwargs)

    agent_cls.act = mark_first
    with tempfile.TemporaryDirectory() as tmp:
        cfg = make_config(
            algo,
            env,
            seed=1,
            total_steps=steps,
            run_dir=f"{tmp}/run",
            torch_threads=1,
            device="cpu",
            eval_every=0,
            eval_episodes=1,
            progress=False,
            **values,
        )
        train_module.train(cfg)
    loop = marks["end"] - marks["start"]  # first action to last step (no final evaluation)
    phases = {name: round(1e6 * seconds[name] / steps, 1) for name in PHASES}
    phases["rest"] = round(1e6 * (loop - sum(seconds.values())) / steps, 1)
    return {
        "algo": algo,
        "env": env,
        "steps": steps,
        "us_per_step": phases,
        "loop_sps": round(steps / loop, 1),
        "preset": cfg.preset,
    }


def measure(algo: str, task: str, checkout: Path) -> dict[str, Any]:
    from benchmarks.atari_sps import child_env, fail, run_child

    env_id, steps, values = task_spec(task)
    spec = json.dumps({"algo": algo, "env": env_id, "steps": steps, "values": values})
    cmd = [sys.executable, str(Path(__file__).resolve()), "--one", spec]
    env = {**child_env(1), "PYTHONPATH": str(checkout)}
    rc, lines, _ = run_child(cmd, checkout, env)
    rows = [text[len(TAG) :] for _, text in lines if text.startswith(TAG)]
    if rc != 0 or not rows:
        fail(f"{algo} on {task} ({checkout})", rc, lines)
    return {**json.loads(rows[-1]), "task": task, "checkout": str(checkout)}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--algos", nargs="+", default=["ddqn", "farsighter"])
    p.add_argument("--tasks", nargs="+", choices=TASKS, default=list(TASKS))
    p.add_argument("--baseline", type=Path, help="another checkout, measured the same way")
    p.add_argument("--name", default="small_profile")
    p.add_argument("--one", help=argparse.SUPPRESS)  # internal: one run, JSON spec
    args = p.parse_args()
    if args.one is not None:
        spec = json.loads(args.one)
        values = {k: tuple(v) if isinstance(v, list) else v for k, v in spec["values"].items()}
        print(TAG + json.dumps(profile(spec["algo"], spec["env"], spec["steps"], values)))
        return
    from benchmarks.common import write_result

    checkouts = [("now", REPO)] + ([("baseline", args.baseline)] if args.baseline else [])
    runs = []
    for task in args.tasks:
        for algo in args.algos:
            for label, checkout in checkouts:
                print(f"{task} {algo} ({label})", file=sys.stderr, flush=True)
                runs.append({**measure(algo, task, checkout), "which": label})
                print(f"  {runs[-1]['us_per_step']}", file=sys.stderr, flush=True)
    write_result(args.name, {"threads": 1, "runs": runs})


if __name__ == "__main__":
    main()
