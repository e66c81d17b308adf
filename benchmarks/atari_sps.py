"""Steady-state training throughput on Breakout: DDQN, BDQN and Farsighter, CleanRL's DQN beside.

Every figure is environment steps per second of the real training loop (``farsighter.train``:
Atari preprocessing, replay, acting, updates) over a window of ``--measure`` steps that starts
``--warmup`` steps in (warm-up >= ``learning_starts``, so every step of the window trains), in
steady state:

* epsilon at its final value from the start (eps_start = eps_end = 0.01), so DDQN's acting
  forward pass runs on 99% of steps, as CleanRL's does once its schedule has ended;
* one update every 4 environment steps (``train_every`` 4, summed over environments: the replay
  ratio is 1/4 whatever E, the number of environments, is);
* target copies every ``--target-update-every`` steps (1,000, CleanRL's value), at least one
  inside the window (the JSON counts them);
* no posterior refresh inside the window (bdqn, farsighter: the Atari preset's M = 100k is kept;
  the JSON counts the refreshes that fell inside, see posterior_refresh.json for their cost).

Each measurement runs in its own Python process (``--one``), so torch threads, allocator state
and the peak RSS (``ru_maxrss`` of that process) do not leak from one to the next. ``--memory``
adds one Farsighter run with a ``--buffer-size`` (1M) replay: RSS counts only the pages touched,
so the JSON also gives the replay's allocated bytes.

``--compile off on`` measures each configuration eager and with ``RuntimeConfig.compile`` (the first
update compiles inside the warm-up, outside the window). Every measurement records its minor
page faults per step (``page_faults_per_step``).

    python -m benchmarks.atari_sps [--cleanrl DIR] [--precision fp32 bf16] [--compile off on]
    python -m benchmarks.atari_sps --device cuda --cleanrl DIR      # -> atari_sps_gpu.json

CleanRL reference (``--cleanrl DIR``, a checkout holding ``cleanrl/dqn_atari.py`` and
``cleanrl_utils/``): its script runs unmodified in a subprocess through :func:`cleanrl_launch`,
which adapts gymnasium 1.x to the 0.29 API the script was written for and sets its torch threads
to ``--threads`` (CleanRL sets none). It prints ``SPS:`` every 100 steps of training; each line
is timestamped as it arrives, and the figure is 100 steps per line over the time between the
first and the last line of the window (our clock, not its cumulative SPS).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import torch

from benchmarks.common import REPO, cpu_features, write_result
from farsighter.config import Config

ENV = "ALE/Breakout-v5"
CLEANRL_ENV = "BreakoutNoFrameskip-v4"  # what dqn_atari.py expects: frame skip in its wrappers
TRAIN_EVERY = 4  # replay ratio 1/4
EPSILON = 0.01
SPEED_BUFFER = 100_000  # capacity does not change the speed; keeps RSS small (CleanRL: the same)
GOAL_FP32_RATIO = 1.15
GOAL_BF16_RATIO = 1.4
GOAL_GPU_SPS = 3_000
RESULT_TAG = "ATARI_SPS_RESULT "
CLEANRL_SPS_EVERY = 100  # dqn_atari.py prints SPS when global_step % 100 == 0 (and % 4 == 0)


# ------------------------------------------------------------------------------------------
# One measurement of ours, in its own process (--one SPEC)
# ------------------------------------------------------------------------------------------


class Window:
    """Training-loop callback: wall and CPU time of the steps after ``start``, and the agent's
    update, target-sync and posterior-refresh counters at both ends of the window."""

    def __init__(self, start: int) -> None:
        self.start = start
        self.first: dict[str, Any] | None = None
        self.last: dict[str, Any] | None = None
        self.replay_bytes: int | None = None

    @staticmethod
    def counters(global_step: int, agent: Any) -> dict[str, Any]:
        c = agent.counters
        head = getattr(agent, "head", None)
        return {
            "step": global_step,
            "wall": time.perf_counter(),
            "cpu": time.process_time(),
            "faults": resource.getrusage(resource.RUSAGE_SELF).ru_minflt,
            "updates": c.updates,
            "target_syncs": c.target_syncs,
            "refreshes": None if head is None else head.num_refreshes,
        }

    def on_step(self, global_step: int, info: dict[str, Any], agent: Any) -> None:
        if self.first is None:
            if global_step >= self.start:
                self.first = self.counters(global_step, agent)
            return
        self.last = self.counters(global_step, agent)

    def on_finish(self, run_dir: Path, agent: Any) -> None:
        replay = getattr(agent, "replay", None)
        self.replay_bytes = None if replay is None else int(replay.nbytes)


def steady_state_config(spec: dict[str, Any], run_dir: str) -> Config:
    """The config of one measurement: Breakout, the Atari preset, epsilon at its final value,
    replay ratio 1/4, no evaluations or checkpoints inside the window."""
    from farsighter import make_config

    threads = spec["threads"]
    return make_config(
        spec["algo"],
        ENV,
        seed=spec["seed"],
        total_steps=spec["warmup"] + spec["measure"],
        learning_starts=spec["learning_starts"],
        num_envs=spec["num_envs"],
        train_every=TRAIN_EVERY,
        eps_start=EPSILON,
        eps_end=EPSILON,
        eps_decay_steps=1,
        target_update_every=spec["target_update_every"],
        buffer_size=spec["buffer_size"],
        torch_threads=threads,
        device=spec["device"],
        precision=spec["precision"],
        cuda_graph=spec.get("cuda_graph", "auto"),
        compile=spec.get("compile", False),
        overlap_env=spec.get("overlap_env", "auto"),
        gpu_replay=spec.get("gpu_replay", "auto"),
        target_cache=spec.get("target_cache", "auto"),
        eval_every=0,
        eval_episodes=1,  # the final evaluation is outside the window; keep it short
        eval_max_steps=200,
        checkpoint_every=0,
        save_replay=False,
        progress=False,
        run_dir=run_dir,
        **{"atari.backend": spec["backend"]},
    )


def run_one(spec: dict[str, Any]) -> dict[str, Any]:
    """Train ``spec['algo']`` on Breakout for warmup + measure steps; the window's figures."""
    from farsighter import train
    from farsighter.envs.envpool_vec import envpool_supports

    threads = spec["threads"]
    torch.set_num_threads(threads)
    with tempfile.TemporaryDirectory() as tmp:
        cfg = steady_state_config(spec, f"{tmp}/run")
        window = Window(spec["warmup"])
        summary = train(cfg, callbacks=[window])
    first, last = window.first, window.last
    if first is None or last is None or last["step"] <= first["step"]:
        raise SystemExit("the run ended before the measurement window had two steps")
    wall = last["wall"] - first["wall"]
    steps = last["step"] - first["step"]
    refreshes = None if first["refreshes"] is None else last["refreshes"] - first["refreshes"]
    backend = spec["backend"]
    if backend == "auto":
        backend = "envpool" if envpool_supports(ENV, cfg.atari.noop_max) else "gymnasium"
    cuda = spec["device"].startswith("cuda")
    return {
        "algo": spec["algo"],
        "num_envs": spec["num_envs"],
        "precision": spec["precision"],
        "cuda_graph": cfg.runtime.cuda_graph,
        "compile": cfg.runtime.compile,
        "overlap_env": cfg.runtime.overlap_env,
        "gpu_replay": cfg.runtime.gpu_replay,
        "target_cache": cfg.runtime.target_cache,
        "threads": torch.get_num_threads(),
        "device": spec["device"],
        "backend": backend,
        "warmup": spec["warmup"],
        "learning_starts": cfg.learning_starts,
        "window_first_step": first["step"],
        "measured_steps": steps,
        "window_seconds": round(wall, 3),
        "sps": round(steps / wall, 2),
        # process CPU seconds per wall second in the window (torch threads, envpool threads)
        "cpu_per_wall": round((last["cpu"] - first["cpu"]) / wall, 2),
        "page_faults_per_step": round((last["faults"] - first["faults"]) / steps, 1),
        "updates_in_window": last["updates"] - first["updates"],
        "target_syncs_in_window": last["target_syncs"] - first["target_syncs"],
        "posterior_refreshes_in_window": refreshes,
        # the library's own figures: from the first step at or after learning_starts, and overall
        "library_train_phase_sps": round(summary["train_phase_sps"], 2),
        "library_overall_sps": round(summary["sps"], 2),
        "buffer_size": cfg.buffer_size,
        "replay_allocated_bytes": window.replay_bytes,
        "cuda_max_memory_allocated_bytes": torch.cuda.max_memory_allocated() if cuda else None,
        "config": {
            "k": cfg.k,
            "train_every": cfg.train_every,
            "target_update_every": cfg.target_update_every,
            "eps_start": cfg.eps_start,
            "eps_end": cfg.eps_end,
            "sample_recent": cfg.sample_recent,
            "blr_redraw": cfg.blr.redraw,
            "blr_posterior_every": cfg.blr.posterior_every,
            "blr_mode": cfg.blr.mode,
            "log_every": cfg.log_every,
            "preset": cfg.preset,
        },
    }


# ------------------------------------------------------------------------------------------
# Subprocesses: stdout lines timestamped as they arrive, the child's own peak RSS
# ------------------------------------------------------------------------------------------


def run_child(
    cmd: list[str], cwd: Path | str, env: dict[str, str]
) -> tuple[int, list[tuple[float, str]], int]:
    """Run ``cmd``; returns its exit code, its output lines (stderr merged) each with the
    perf_counter time it arrived, and its peak RSS in bytes (``wait4``: this child alone)."""
    proc = subprocess.Popen(
        cmd,
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        bufsize=1,
    )
    lines: list[tuple[float, str]] = []
    assert proc.stdout is not None
    for line in iter(proc.stdout.readline, ""):
        lines.append((time.perf_counter(), line.rstrip("\n")))
    proc.stdout.close()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    return proc.returncode, lines, usage.ru_maxrss * 1024  # Linux: KiB


def child_env(threads: int, extra_path: str | None = None) -> dict[str, str]:
    path = [str(REPO)] + ([extra_path] if extra_path else [])
    if os.environ.get("PYTHONPATH"):
        path.append(os.environ["PYTHONPATH"])
    return {
        **os.environ,
        "OMP_NUM_THREADS": str(threads),
        "MKL_NUM_THREADS": str(threads),
        "PYTHONPATH": os.pathsep.join(path),
    }


def fail(what: str, rc: int, lines: list[tuple[float, str]]) -> None:
    tail = "\n".join(text for _, text in lines[-30:])
    raise SystemExit(f"{what} failed (exit {rc}):\n{tail}")


def measure(spec: dict[str, Any]) -> dict[str, Any]:
    cmd = [sys.executable, "-m", "benchmarks.atari_sps", "--one", json.dumps(spec)]
    load_before = os.getloadavg()[0]
    t0 = time.perf_counter()
    rc, lines, rss = run_child(cmd, REPO, child_env(spec["threads"]))
    results = [text[len(RESULT_TAG) :] for _, text in lines if text.startswith(RESULT_TAG)]
    if rc != 0 or not results:
        fail(f"{spec['algo']} E={spec['num_envs']} {spec['precision']}", rc, lines)
    return {
        **json.loads(results[-1]),
        "peak_rss_bytes": rss,
        "process_seconds": round(time.perf_counter() - t0, 1),
        "load_average_1min": [round(load_before, 2), round(os.getloadavg()[0], 2)],
    }


# ------------------------------------------------------------------------------------------
# CleanRL: a small launcher for gymnasium 1.x, and its measurement
# ------------------------------------------------------------------------------------------


def _final_info_list(final_info: dict[str, Any], n: int) -> list[dict[str, Any] | None]:
    """gymnasium 1.x's final_info (a dict of arrays with ``_key`` masks) as 0.29's list of
    per-environment dicts (None where nothing ended), keeping what CleanRL reads: episode r, l."""
    episode, mask = final_info.get("episode"), final_info.get("_episode")
    rows: list[dict[str, Any] | None] = []
    for i in range(n):
        ended = episode is not None and mask is not None and bool(mask[i])
        rows.append({"episode": {"r": episode["r"][i], "l": episode["l"][i]}} if ended else None)
    return rows


def cleanrl_launch(threads: int, script: str, args: list[str]) -> None:
    """Run a CleanRL script written for gymnasium 0.29 unmodified on gymnasium 1.x: the renamed
    wrappers get their old names, SyncVectorEnv resets finished environments in the same step
    and exposes ``final_observation`` and a list-style ``final_info`` again, and ale_py's ids
    are registered. Torch threads are set here, as CleanRL sets none."""
    import runpy

    import ale_py
    import gymnasium as gym

    torch.set_num_threads(threads)
    gym.register_envs(ale_py)
    gym.wrappers.GrayScaleObservation = gym.wrappers.GrayscaleObservation  # renamed in 1.0
    gym.wrappers.FrameStack = gym.wrappers.FrameStackObservation

    class LegacySyncVectorEnv(gym.vector.SyncVectorEnv):
        def __init__(self, env_fns: Any, **kwargs: Any) -> None:
            kwargs.setdefault("autoreset_mode", gym.vector.AutoresetMode.SAME_STEP)
            super().__init__(env_fns, **kwargs)

        def step(self, actions: Any) -> Any:
            obs, rewards, terminated, truncated, info = super().step(actions)
            if "final_obs" in info:
                info["final_observation"] = info["final_obs"]
            if "final_info" in info:
                info["final_info"] = _final_info_list(info["final_info"], self.num_envs)
            return obs, rewards, terminated, truncated, info

    gym.vector.SyncVectorEnv = LegacySyncVectorEnv
    print(f"LAUNCHER torch_threads={torch.get_num_threads()} gymnasium={gym.__version__}")
    sys.argv = [script, *args]
    runpy.run_path(script, run_name="__main__")


def measure_cleanrl(
    root: Path,
    warmup: int,
    steps: int,
    threads: int,
    device: str,
    target_every: int,
    seed: int,
) -> dict[str, Any]:
    """CleanRL's dqn_atari.py for warmup + steps steps; steps/s between its SPS lines."""
    script = (root / "cleanrl" / "dqn_atari.py").resolve()
    if not script.is_file() or not (root / "cleanrl_utils").is_dir():
        raise SystemExit(f"--cleanrl {root}: no cleanrl/dqn_atari.py and cleanrl_utils/ there")
    total = warmup + steps
    fraction = warmup / 2 / total  # epsilon reaches 0.01 half-way through the warm-up
    args = [
        "--env-id", CLEANRL_ENV,
        "--total-timesteps", str(total),
        "--learning-starts", str(warmup),
        "--buffer-size", str(SPEED_BUFFER),
        "--exploration-fraction", repr(fraction),
        "--end-e", str(EPSILON),
        "--target-network-frequency", str(target_every),
        "--train-frequency", str(TRAIN_EVERY),
        "--seed", str(seed),
    ]  # fmt: skip
    if not device.startswith("cuda"):
        args.append("--no-cuda")
    cmd = [sys.executable, "-u", "-m", "benchmarks.atari_sps", "--cleanrl-launch", str(threads)]
    cmd += [str(script), *args]
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:  # its runs/ (TensorBoard) goes there
        rc, lines, rss = run_child(cmd, tmp, child_env(threads, str(root.resolve())))
    if rc != 0:
        fail("CleanRL dqn_atari.py", rc, lines)
    # SPS lines come at the multiples of 100 above learning_starts: the i-th at first + 100 i.
    times = [t for t, text in lines if text.startswith("SPS:")]
    first_step = (warmup // CLEANRL_SPS_EVERY + 1) * CLEANRL_SPS_EVERY
    expected = len(range(first_step, total, CLEANRL_SPS_EVERY))
    if len(times) < 2:
        fail("CleanRL dqn_atari.py printed fewer than two SPS lines;", rc, lines)
    last_step = first_step + CLEANRL_SPS_EVERY * (len(times) - 1)
    wall = times[-1] - times[0]
    own = [text for _, text in lines if text.startswith("SPS:")][-1]
    launcher = [text for _, text in lines if text.startswith("LAUNCHER")]
    return {
        "algo": "cleanrl_dqn",
        "script": "cleanrl/dqn_atari.py (unmodified)",
        "env": CLEANRL_ENV,
        "num_envs": 1,
        "precision": "fp32",
        "threads": threads,
        "launcher": launcher[0] if launcher else None,
        "device": device,
        "warmup": warmup,
        "learning_starts": warmup,
        "exploration_fraction": fraction,
        "window_first_step": first_step,
        "measured_steps": last_step - first_step,
        "window_seconds": round(wall, 3),
        "sps": round((last_step - first_step) / wall, 2),
        "sps_lines": len(times),
        "sps_lines_expected": expected,
        # it prints the SPS line of a step before that step's target copy
        "target_syncs_in_window": sum(
            1 for s in range(first_step, last_step) if s % target_every == 0
        ),
        "its_own_last_cumulative_sps": own,
        "buffer_size": SPEED_BUFFER,
        "peak_rss_bytes": rss,
        "load_average_1min": [round(load_before, 2), round(os.getloadavg()[0], 2)],
        "command": " ".join(["python", "-u", "cleanrl/dqn_atari.py", *args])
        + f"  (through benchmarks.atari_sps.cleanrl_launch, torch threads {threads})",
    }


# ------------------------------------------------------------------------------------------
# The benchmark
# ------------------------------------------------------------------------------------------


def median_sps(rows: list[dict[str, Any]]) -> float | None:
    return round(statistics.median(r["sps"] for r in rows), 2) if rows else None


def ratio(a: float | None, b: float | None) -> float | None:
    return round(a / b, 3) if a is not None and b else None


def meets(value: float | None, goal: float) -> bool | None:
    return None if value is None else value >= goal


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--device", choices=["cpu", "cuda"], default="cpu")
    p.add_argument("--algos", nargs="+", default=["ddqn", "bdqn", "farsighter"])
    p.add_argument(
        "--num-envs", type=int, nargs="+", help="E values (default: 1 4 on CPU, 1 8 16 on CUDA)"
    )
    p.add_argument("--precision", nargs="+", choices=["fp32", "bf16"], default=["fp32", "bf16"])
    p.add_argument("--threads", type=int, default=2, help="torch threads (CleanRL's too)")
    p.add_argument(
        "--cuda-graph",
        choices=["auto", "on", "off"],
        default="auto",
        help="RuntimeConfig.cuda_graph",
    )
    p.add_argument("--warmup", type=int, help="steps before the window (2,000 CPU, 10,000 CUDA)")
    p.add_argument("--learning-starts", type=int, help="<= warmup (default: warmup)")
    p.add_argument("--measure", type=int, help="steps in the window (4,000 CPU, 30,000 CUDA)")
    p.add_argument("--target-update-every", type=int, default=1_000)
    p.add_argument(
        "--backend",
        choices=["auto", "gymnasium", "envpool"],
        help="Atari backend (default: gymnasium on CPU, as CleanRL steps; envpool on CUDA)",
    )
    p.add_argument(
        "--compile",
        nargs="+",
        choices=["off", "on"],
        default=["off"],
        help="RuntimeConfig.compile: measure eager, compiled, or both (table keys end in _compiled)",
    )
    p.add_argument(
        "--overlap-env",
        choices=["auto", "on", "off"],
        default="auto",
        help="RuntimeConfig.overlap_env (on needs --backend envpool)",
    )
    p.add_argument(
        "--gpu-replay", choices=["auto", "off"], default="auto", help="RuntimeConfig.gpu_replay"
    )
    p.add_argument(
        "--target-cache", choices=["auto", "off"], default="auto", help="RuntimeConfig.target_cache"
    )
    p.add_argument("--repeats", type=int, default=1, help="rounds over all configurations")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--cleanrl", type=Path, help="CleanRL checkout to measure beside ours")
    p.add_argument("--memory", action="store_true", help="also a Farsighter run with a big buffer")
    p.add_argument("--buffer-size", type=int, default=1_000_000, help="replay of --memory")
    p.add_argument("--name", help="result file name (default: atari_sps, atari_sps_gpu on CUDA)")
    p.add_argument("--one", help=argparse.SUPPRESS)  # internal: one measurement, JSON spec
    p.add_argument("--cleanrl-launch", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
    return p.parse_args()


def main() -> None:
    args = parse_args()
    if args.one is not None:
        result = run_one(json.loads(args.one))
        print(RESULT_TAG + json.dumps(result), flush=True)
        return
    if args.cleanrl_launch is not None:
        threads, script, *rest = args.cleanrl_launch
        cleanrl_launch(int(threads), script, rest)
        return

    gpu = args.device == "cuda"
    warmup = args.warmup if args.warmup is not None else (10_000 if gpu else 2_000)
    steps = args.measure if args.measure is not None else (30_000 if gpu else 4_000)
    learning_starts = args.learning_starts if args.learning_starts is not None else warmup
    num_envs = args.num_envs or ([1, 16, 32, 64] if gpu else [1, 4])
    backend = args.backend or ("envpool" if gpu else "gymnasium")
    if learning_starts > warmup:
        raise SystemExit("--learning-starts must not exceed --warmup: the window must train")
    if steps < args.target_update_every:
        print(
            f"warning: --measure {steps} < --target-update-every {args.target_update_every}: "
            "the window may hold no target copy",
            file=sys.stderr,
        )
    base = {
        "device": args.device,
        "threads": args.threads,
        "warmup": warmup,
        "learning_starts": learning_starts,
        "measure": steps,
        "target_update_every": args.target_update_every,
        "backend": backend,
        "seed": args.seed,
        "cuda_graph": args.cuda_graph,
        "overlap_env": args.overlap_env,
        "gpu_replay": args.gpu_replay,
        "target_cache": args.target_cache,
    }
    compiled = [c == "on" for c in args.compile]
    configs = [
        {
            **base,
            "algo": a,
            "num_envs": e,
            "precision": p,
            "compile": c,
            "buffer_size": SPEED_BUFFER,
        }
        for a in args.algos
        for e in num_envs
        for p in args.precision
        for c in compiled
    ]
    rows: list[dict[str, Any]] = []
    cleanrl_rows: list[dict[str, Any]] = []
    for rnd in range(args.repeats):
        if args.cleanrl is not None:  # first, so it runs right beside Farsighter's E=1 figure
            print(f"[round {rnd + 1}] cleanrl dqn_atari.py", file=sys.stderr, flush=True)
            cleanrl_rows.append(
                measure_cleanrl(
                    args.cleanrl,
                    warmup,
                    steps,
                    args.threads,
                    args.device,
                    args.target_update_every,
                    args.seed,
                )
            )
            print(f"  {cleanrl_rows[-1]['sps']} steps/s", file=sys.stderr, flush=True)
        for spec in configs:
            label = f"{spec['algo']} E={spec['num_envs']} {spec['precision']}"
            label += " compiled" if spec["compile"] else ""
            print(f"[round {rnd + 1}] {label}", file=sys.stderr, flush=True)
            rows.append({**measure(spec), "round": rnd + 1})
            print(f"  {rows[-1]['sps']} steps/s", file=sys.stderr, flush=True)
    memory = None
    if args.memory:
        spec = {
            **base,
            "algo": "farsighter",
            "num_envs": 1,
            "precision": "fp32",
            "buffer_size": args.buffer_size,
        }
        print(f"memory: farsighter, buffer {args.buffer_size}", file=sys.stderr, flush=True)
        row = measure(spec)
        memory = {
            "algo": "farsighter",
            "num_envs": 1,
            "buffer_size": args.buffer_size,
            "steps_written": warmup + steps,
            "peak_rss_bytes": row["peak_rss_bytes"],
            "replay_allocated_bytes": row["replay_allocated_bytes"],
            "replay_allocated_bytes_per_transition": (
                row["replay_allocated_bytes"] / args.buffer_size
                if row["replay_allocated_bytes"]
                else None
            ),
            "note": "peak RSS counts only the pages touched: the replay's arrays are allocated "
            "zeroed and lazily mapped, and this run wrote warmup + measure frames into them, "
            "not a full buffer; a full buffer adds about replay_allocated_bytes to the RSS "
            "(replay_memory.json measures a written 1M buffer)",
            "raw": row,
        }

    def pick(algo: str, e: int, precision: str, c: bool = False) -> list[dict[str, Any]]:
        return [
            r
            for r in rows
            if r["algo"] == algo
            and r["num_envs"] == e
            and r["precision"] == precision
            and r["compile"] == c
        ]

    table = {
        a: {
            f"E{e}_{p}" + ("_compiled" if c else ""): median_sps(pick(a, e, p, c))
            for e in num_envs
            for p in args.precision
            for c in compiled
        }
        for a in args.algos
    }
    fars_fp32 = median_sps(pick("farsighter", 1, "fp32"))
    fars_bf16 = median_sps(pick("farsighter", 1, "bf16"))
    fars_fp32_c = median_sps(pick("farsighter", 1, "fp32", True))
    fars_bf16_c = median_sps(pick("farsighter", 1, "bf16", True))
    cleanrl = median_sps(cleanrl_rows)
    figures: dict[str, Any] = {"env": ENV, "device": args.device}
    if gpu:
        fars = [r for r in rows if r["algo"] == "farsighter"]
        best = max(table.get("farsighter", {}).items(), key=lambda kv: kv[1] or 0, default=None)
        figures["farsighter_breakout_gpu_sps"] = best[1] if best else None
        figures["farsighter_breakout_gpu_config"] = best[0] if best else None
        figures["goal_gpu_sps"] = GOAL_GPU_SPS
        figures["meets_gpu_goal"] = bool(best and best[1] and best[1] >= GOAL_GPU_SPS)
        figures["gpu_note"] = (
            f"best Farsighter configuration of {len(fars)} measurements at replay ratio 1/4"
        )
    else:
        figures["farsighter_breakout_cpu_sps"] = fars_fp32
        figures["farsighter_breakout_cpu_config"] = f"E1_fp32, {args.threads} torch threads"
    figures.update(
        {
            "cleanrl_dqn_sps": cleanrl,
            "farsighter_over_cleanrl": ratio(fars_fp32, cleanrl),
            "farsighter_bf16_over_cleanrl": ratio(fars_bf16, cleanrl),
            "farsighter_compiled_over_cleanrl": ratio(fars_fp32_c, cleanrl),
            "farsighter_bf16_compiled_over_cleanrl": ratio(fars_bf16_c, cleanrl),
            "goal_fp32_ratio": GOAL_FP32_RATIO,
            "goal_bf16_ratio": GOAL_BF16_RATIO,
            "sps_table": table,
            "settings": {
                "algos": args.algos,
                "num_envs": num_envs,
                "precision": args.precision,
                "threads": args.threads,
                "warmup": warmup,
                "learning_starts": learning_starts,
                "measure": steps,
                "train_every": TRAIN_EVERY,
                "replay_ratio": 1 / TRAIN_EVERY,
                "epsilon": EPSILON,
                "target_update_every": args.target_update_every,
                "buffer_size": SPEED_BUFFER,
                "backend": backend,
                "cuda_graph": args.cuda_graph,
                "compile": args.compile,
                "overlap_env": args.overlap_env,
                "gpu_replay": args.gpu_replay,
                "target_cache": args.target_cache,
                "repeats": args.repeats,
                "seed": args.seed,
                "statistic": "median over rounds",
            },
            "notes": [
                "sps: environment steps (summed over E environments) per wall second over the "
                "window; the Atari preset otherwise (Table 1 Atari column), with eps_start = "
                "eps_end = 0.01, train_every 4 and target_update_every as in settings",
                "bdqn and farsighter keep the Atari preset's posterior refresh every "
                "blr.posterior_every = 100k steps: posterior_refreshes_in_window counts those "
                "that fell in the window (0 unless warmup + measure > 100k)",
                "farsighter samples its minibatches from the latest N = target_update_every "
                f"transitions (sample_recent), so N = {args.target_update_every:,} here (the "
                "preset's 10k otherwise) narrows that window; a sample costs the same",
                "peak_rss_bytes: ru_maxrss of the measurement's own process (wait4), with "
                f"a {SPEED_BUFFER:,}-transition replay (lazily mapped: only touched pages count)",
                "cpu_per_wall: process CPU seconds per wall second in the window",
                "CleanRL dqn_atari.py differs in method, not only speed: Adam and MSE against "
                "our centered RMSProp and Huber with a gradient clip, a max target against our "
                "double-Q target, and it stores s and s' (SB3 buffer, optimize_memory_usage) "
                "against our one frame per step",
            ],
            "cpu_features": cpu_features(),
            "measurements": rows,
            "cleanrl": cleanrl_rows,
            "memory": memory,
        }
    )
    if not gpu:
        figures["meets_fp32_goal"] = meets(figures["farsighter_over_cleanrl"], GOAL_FP32_RATIO)
        figures["meets_bf16_goal"] = meets(figures["farsighter_bf16_over_cleanrl"], GOAL_BF16_RATIO)
        figures["meets_fp32_goal_compiled"] = meets(
            figures["farsighter_compiled_over_cleanrl"], GOAL_FP32_RATIO
        )
        figures["meets_bf16_goal_compiled"] = meets(
            figures["farsighter_bf16_compiled_over_cleanrl"], GOAL_BF16_RATIO
        )
    name = args.name or ("atari_sps_gpu" if gpu else "atari_sps")
    print(f"wrote {write_result(name, figures)}", file=sys.stderr)


if __name__ == "__main__":
    main()
