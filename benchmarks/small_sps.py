"""Throughput on a small task: CartPole-v1 with CleanRL ``dqn.py``'s settings, its script beside ours.

Issue #27's workload: an exploration study is hundreds of short runs on small tasks, where what a
step costs is the loop's own overhead (acting forward, environment, replay, bookkeeping) more than
the network. Every run here uses CleanRL ``dqn.py``'s defaults except the length: 30,000 steps,
learning from step 10,000, an update every 10 steps on 128 transitions, Adam 2.5e-4, a target copy
every 500 steps, a 10,000-transition buffer, epsilon 1 -> 0.05 over half the run, a 120 x 84 MLP,
the squared TD error, no gradient clipping, one torch thread. Ours also does what a run of ours
always does (TensorBoard and CSV logs, a checkpoint at step 25,000 with its replay, the progress
bar); what it does not (evaluations inside the window) is off.

The figure is the training phase's steps/s: for CleanRL, 100 steps per ``SPS:`` line over the time
between its first and last line (our clock, timestamped as they arrive; the lines come every 100
steps after ``learning_starts``); for ours, the run's own ``train_phase_sps`` (summary.json: from
the first step at or after ``learning_starts`` to the last step, before the final evaluation) of
a ``farsighter train`` process with those settings as flags. Each round runs every entry once in
turn, so the ratios are taken side by side. ``--baseline DIR`` also measures the package of
another checkout (a git worktree of an older commit) the same way, for before/after ratios.
``--compile`` also measures each algorithm with ``--compile`` (``RuntimeConfig.compile``: the
update step through ``torch.compile``), as ``<algo>+compile``. The compile happens at the first
update, which falls before the window opens (the window starts after the step at
``learning_starts`` and its update, as CleanRL's first ``SPS:`` line comes after its first
update): the run's overall steps/s, which pays it, is each row's ``library_overall_sps``.

    python -m benchmarks.small_sps --cleanrl DIR [--baseline DIR] [--algos ddqn farsighter] [--rounds 2]
        [--compile]

``--cleanrl DIR``: a CleanRL checkout holding ``cleanrl/dqn.py`` and ``cleanrl_utils/``, run
unmodified through :func:`benchmarks.atari_sps.cleanrl_launch` (Gymnasium 1.x adapted to the 0.29
API the script expects). Without it only ours are measured.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
from pathlib import Path
from typing import Any

from benchmarks.atari_sps import child_env, fail, run_child
from benchmarks.common import REPO, write_result

ENV = "CartPole-v1"
SPS_EVERY = 100  # dqn.py prints SPS when global_step % 100 == 0 (past learning_starts)
# CleanRL dqn.py's defaults (its Args), in our field names; the length is set per run.
CLEANRL_DQN = {
    "lr": 2.5e-4,
    "optimizer": "adam",
    "optim_eps": 1e-8,
    "buffer_size": 10_000,
    "gamma": 0.99,
    "target_update_every": 500,
    "batch_size": 128,
    "eps_start": 1.0,
    "eps_end": 0.05,
    "train_every": 10,
    "hidden_sizes": (120, 84),
    "loss": "mse",
    "max_grad_norm": 0.0,
}
GOALS = {"ddqn": 1.2, "farsighter": 1.0}  # issue #27: ours / CleanRL, one seed


def train_command(spec: dict[str, Any], run_dir: str) -> list[str]:
    """``farsighter train`` with CleanRL dqn.py's settings (what a user would type)."""
    flags: dict[str, Any] = {
        **CLEANRL_DQN,
        "algo": spec["algo"],
        "env": ENV,
        "seed": spec["seed"],
        "total_steps": spec["steps"],
        "learning_starts": spec["learning_starts"],
        "eps_decay_steps": spec["steps"] // 2,  # dqn.py: exploration_fraction 0.5
        "torch_threads": spec["threads"],
        "device": "cpu",
        "eval_every": 0,  # dqn.py evaluates nothing; one final episode, outside the window
        "eval_episodes": 1,
        "run_dir": run_dir,
    }
    cmd = ["-m", "farsighter", "train"] + (["--compile"] if spec.get("compile") else [])
    for key, value in flags.items():
        values = value if isinstance(value, tuple) else (value,)
        cmd += [f"--{key.replace('_', '-')}", *(str(v) for v in values)]
    return cmd + ["--no-progress"]


def measure_ours(spec: dict[str, Any], checkout: Path) -> dict[str, Any]:
    """One ``farsighter train`` run of the package in ``checkout``, in its own process; the
    training phase's steps/s is the run's own ``train_phase_sps`` (summary.json: from the first
    step at or after learning_starts to the last step, before the final evaluation)."""
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, *train_command(spec, f"{tmp}/run")]
        env = {**child_env(spec["threads"]), "PYTHONPATH": str(checkout)}
        rc, lines, _ = run_child(cmd, tmp, env)
        if rc != 0:
            fail(f"farsighter train --algo {spec['algo']} ({checkout})", rc, lines)
        summary = json.loads(Path(f"{tmp}/run/summary.json").read_text())
    return {
        "algo": spec["algo"],
        "compile": bool(spec.get("compile")),
        "checkout": str(checkout),
        "sps": round(summary["train_phase_sps"], 1),
        "library_overall_sps": round(summary["sps"], 1),
        "command": " ".join(["python", *train_command(spec, "RUN_DIR")]),
    }


def measure_cleanrl(root: Path, spec: dict[str, Any]) -> dict[str, Any]:
    """CleanRL's dqn.py, unmodified; steps/s between its first and last SPS line."""
    script = (root / "cleanrl" / "dqn.py").resolve()
    if not script.is_file() or not (root / "cleanrl_utils").is_dir():
        raise SystemExit(f"--cleanrl {root}: no cleanrl/dqn.py and cleanrl_utils/ there")
    args = [
        "--env-id", ENV,
        "--total-timesteps", str(spec["steps"]),
        "--learning-starts", str(spec["learning_starts"]),
        "--seed", str(spec["seed"]),
        "--no-cuda",
    ]  # fmt: skip
    cmd = [sys.executable, "-u", "-m", "benchmarks.atari_sps", "--cleanrl-launch"]
    cmd += [str(spec["threads"]), str(script), *args]
    with tempfile.TemporaryDirectory() as tmp:  # its runs/ (TensorBoard) goes there
        rc, lines, _ = run_child(cmd, tmp, child_env(spec["threads"], str(root.resolve())))
    times = [t for t, text in lines if text.startswith("SPS:")]
    if rc != 0 or len(times) < 2:
        fail("CleanRL dqn.py", rc, lines)
    steps = SPS_EVERY * (len(times) - 1)
    wall = times[-1] - times[0]
    return {
        "algo": "cleanrl_dqn",
        "script": "cleanrl/dqn.py (unmodified)",
        "measured_steps": steps,
        "window_seconds": round(wall, 3),
        "sps": round(steps / wall, 1),
        "command": " ".join(["python", "cleanrl/dqn.py", *args])
        + f"  (through benchmarks.atari_sps.cleanrl_launch, torch threads {spec['threads']})",
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--algos", nargs="+", default=["ddqn", "farsighter"])
    p.add_argument("--cleanrl", type=Path, help="CleanRL checkout to measure beside ours")
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--steps", type=int, default=30_000)
    p.add_argument("--learning-starts", type=int, default=10_000)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument(
        "--baseline",
        type=Path,
        help="another checkout of this repository (e.g. a git worktree of an older commit): its "
        "package is measured beside this one, each algorithm as <algo>@baseline",
    )
    p.add_argument(
        "--compile",
        action="store_true",
        help="also measure each algorithm with --compile (torch.compile of the update), as "
        "<algo>+compile",
    )
    p.add_argument("--name", default="small_sps")
    args = p.parse_args()
    if args.baseline is not None and not (args.baseline / "farsighter" / "train.py").is_file():
        raise SystemExit(f"--baseline {args.baseline}: no farsighter package there")
    if args.learning_starts + 2 * SPS_EVERY > args.steps:
        raise SystemExit("--steps must exceed --learning-starts by at least 200")
    base = {
        "steps": args.steps,
        "learning_starts": args.learning_starts,
        "seed": args.seed,
        "threads": args.threads,
    }
    entries = (["cleanrl_dqn"] if args.cleanrl else []) + list(args.algos)
    if args.compile:
        entries += [f"{a}+compile" for a in args.algos]
    if args.baseline is not None:
        entries += [f"{a}@baseline" for a in args.algos]
    rows: dict[str, list[dict[str, Any]]] = {name: [] for name in entries}
    load_before = os.getloadavg()[0]
    for rnd in range(args.rounds):
        for name in entries:
            print(f"[round {rnd + 1}] {name}", file=sys.stderr, flush=True)
            if name == "cleanrl_dqn":
                row = measure_cleanrl(args.cleanrl, base)
            else:
                algo, _, which = name.partition("@")
                algo, plus, _ = algo.partition("+")
                checkout = args.baseline if which else REPO
                row = measure_ours({**base, "algo": algo, "compile": bool(plus)}, checkout)
            rows[name].append({**row, "round": rnd + 1})
            print(f"  {row['sps']} steps/s", file=sys.stderr, flush=True)
    figures: dict[str, Any] = {
        "env": ENV,
        "settings": {**CLEANRL_DQN, **base},
        "load_average_1min_before": round(load_before, 2),
        "runs": rows,
        "median_sps": {n: statistics.median(r["sps"] for r in rs) for n, rs in rows.items()},
    }
    if args.baseline is not None:
        figures["baseline"] = str(args.baseline)
        figures["ratio_to_baseline_per_round"] = {
            a: [
                round(now["sps"] / then["sps"], 3)
                for now, then in zip(rows[a], rows[f"{a}@baseline"], strict=True)
            ]
            for a in args.algos
        }
    if args.cleanrl:
        # per round, ours over CleanRL's measured right beside it
        figures["ratio_to_cleanrl_per_round"] = {
            n: [
                round(ours["sps"] / ref["sps"], 3)
                for ours, ref in zip(rows[n], rows["cleanrl_dqn"], strict=True)
            ]
            for n in entries
            if n != "cleanrl_dqn"
        }
        goal_of = {n: GOALS.get(n.partition("+")[0]) for n in entries}
        figures["goals"] = {
            n: {
                "goal_ratio": goal,
                "met_every_round": all(x >= goal for x in figures["ratio_to_cleanrl_per_round"][n]),
            }
            for n, goal in goal_of.items()
            if goal is not None and "@" not in n
        }
    write_result(args.name, figures)


if __name__ == "__main__":
    main()
