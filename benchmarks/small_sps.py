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
steps after ``learning_starts``); for ours, the steps between the first step at or after
``learning_starts`` and the last step over the wall time between them (a loop callback). Each
round runs every entry once in turn, so the ratios are taken side by side.

    python -m benchmarks.small_sps --cleanrl DIR [--algos ddqn farsighter] [--rounds 2]

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
import time
from pathlib import Path
from typing import Any

import torch

from benchmarks.atari_sps import child_env, fail, run_child
from benchmarks.common import REPO, write_result

ENV = "CartPole-v1"
RESULT_TAG = "SMALL_SPS_RESULT "
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


class Window:
    """Loop callback: wall time and step at the first step >= ``start`` and at the last one."""

    def __init__(self, start: int) -> None:
        self.start = start
        self.first: tuple[int, float] | None = None
        self.last: tuple[int, float] | None = None

    def on_step(self, global_step: int, info: dict[str, Any], agent: Any) -> None:
        now = time.perf_counter()
        if self.first is None:
            if global_step >= self.start:
                self.first = (global_step, now)
            return
        self.last = (global_step, now)

    def on_finish(self, run_dir: Path, agent: Any) -> None:
        pass


def run_one(spec: dict[str, Any]) -> dict[str, Any]:
    """One run of ours (in this process); the training phase's figures."""
    from farsighter import make_config, train

    torch.set_num_threads(spec["threads"])
    with tempfile.TemporaryDirectory() as tmp:
        cfg = make_config(
            spec["algo"],
            ENV,
            seed=spec["seed"],
            total_steps=spec["steps"],
            learning_starts=spec["learning_starts"],
            eps_decay_steps=spec["steps"] // 2,  # dqn.py: exploration_fraction 0.5
            torch_threads=spec["threads"],
            device="cpu",
            eval_every=0,
            eval_episodes=1,
            run_dir=f"{tmp}/run",
            **CLEANRL_DQN,  # type: ignore[arg-type]
        )
        window = Window(spec["learning_starts"])
        train(cfg, callbacks=[window])
    assert window.first is not None and window.last is not None
    steps = window.last[0] - window.first[0]
    wall = window.last[1] - window.first[1]
    return {
        "algo": spec["algo"],
        "measured_steps": steps,
        "window_seconds": round(wall, 3),
        "sps": round(steps / wall, 1),
        "config": {
            "preset": cfg.preset,
            "k": cfg.k,
            "k_target": cfg.k_target,
            "blr_mode": cfg.blr.mode,
            "blr_redraw": cfg.blr.redraw,
            "blr_target": cfg.blr.target,
            "blr_posterior_every": cfg.blr.posterior_every,
            "sample_recent": cfg.sample_recent,
            "checkpoint_every": cfg.checkpoint_every,
            "log_every": cfg.log_every,
        },
    }


def measure_ours(spec: dict[str, Any]) -> dict[str, Any]:
    cmd = [sys.executable, "-m", "benchmarks.small_sps", "--one", json.dumps(spec)]
    rc, lines, _ = run_child(cmd, REPO, child_env(spec["threads"]))
    results = [text[len(RESULT_TAG) :] for _, text in lines if text.startswith(RESULT_TAG)]
    if rc != 0 or not results:
        fail(f"farsighter train --algo {spec['algo']}", rc, lines)
    return json.loads(results[-1])


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
    p.add_argument("--name", default="small_sps")
    p.add_argument("--one", help=argparse.SUPPRESS)  # internal: one run of ours, JSON spec
    args = p.parse_args()
    if args.one is not None:
        print(RESULT_TAG + json.dumps(run_one(json.loads(args.one))), flush=True)
        return
    if args.learning_starts + 2 * SPS_EVERY > args.steps:
        raise SystemExit("--steps must exceed --learning-starts by at least 200")
    base = {
        "steps": args.steps,
        "learning_starts": args.learning_starts,
        "seed": args.seed,
        "threads": args.threads,
    }
    entries = (["cleanrl_dqn"] if args.cleanrl else []) + list(args.algos)
    rows: dict[str, list[dict[str, Any]]] = {name: [] for name in entries}
    load_before = os.getloadavg()[0]
    for rnd in range(args.rounds):
        for name in entries:
            print(f"[round {rnd + 1}] {name}", file=sys.stderr, flush=True)
            if name == "cleanrl_dqn":
                row = measure_cleanrl(args.cleanrl, base)
            else:
                row = measure_ours({**base, "algo": name})
            rows[name].append({**row, "round": rnd + 1})
            print(f"  {row['sps']} steps/s", file=sys.stderr, flush=True)
    figures: dict[str, Any] = {
        "env": ENV,
        "settings": {**CLEANRL_DQN, **base},
        "load_average_1min_before": round(load_before, 2),
        "runs": rows,
        "median_sps": {n: statistics.median(r["sps"] for r in rs) for n, rs in rows.items()},
    }
    if args.cleanrl:
        # per round, ours over CleanRL's measured right beside it
        figures["ratio_to_cleanrl_per_round"] = {
            n: [
                round(ours["sps"] / ref["sps"], 3)
                for ours, ref in zip(rows[n], rows["cleanrl_dqn"], strict=True)
            ]
            for n in args.algos
        }
        figures["goals"] = {
            n: {
                "goal_ratio": GOALS[n],
                "met_every_round": all(
                    x >= GOALS[n] for x in figures["ratio_to_cleanrl_per_round"][n]
                ),
            }
            for n in args.algos
            if n in GOALS
        }
    write_result(args.name, figures)


if __name__ == "__main__":
    main()
