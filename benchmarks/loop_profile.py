"""Where a training step's time goes in the real loop: cProfile over a steady-state window, or
(``--phases``) wall-clock timers around the loop's phases without a profiler.

The same run as one ``benchmarks.atari_sps`` measurement (Breakout, epsilon at its final value,
replay ratio 1/4, the Atari preset), with Python's cProfile switched on for the window only. On a
GPU every host-device synchronisation shows up as time inside the call that waits (``.cpu()``,
``.item()``, a copy to the host), so the table says both what the host computes and where it
waits. The JSON gives each listed function's own and cumulative milliseconds per environment
step, and the table is printed.

``--phases`` times, per environment step, ``agent.act`` (on a GPU it includes waiting for the
updates queued before it: the acting forward reads the weights they write), the environments'
``step`` and inside it the emulator (envpool's own ``step`` call), ``agent.observe`` and
``agent.learn`` (replay sampling, copies and the update launches), and the rest of the loop
(logging, callbacks). No profiler runs, so the steps/s it reports is the real one.

    python -m benchmarks.loop_profile [--algo farsighter] [--device cuda] [--num-envs 16] [--phases]
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import gymnasium as gym
import torch

from benchmarks.atari_sps import Window, steady_state_config
from benchmarks.common import write_result


class ProfiledWindow(Window):
    """``Window`` with cProfile on from its first step to step ``end`` (the final evaluation and
    checkpoint after it stay out)."""

    def __init__(self, start: int, end: int) -> None:
        super().__init__(start)
        self.end = end
        self.profiler = cProfile.Profile()
        self.on = False

    def on_step(self, global_step: int, info: dict[str, Any], agent: Any) -> None:
        if self.on and global_step >= self.end:
            self.profiler.disable()
            self.on = False
        super().on_step(global_step, info, agent)
        if self.first is not None and self.first["step"] == global_step:
            self.profiler.enable()
            self.on = True


class PhaseTimer:
    """Wall-clock seconds spent in named calls while ``on`` (the window)."""

    def __init__(self) -> None:
        self.on = False
        self.seconds: dict[str, float] = {}
        self.calls: dict[str, int] = {}

    def wrap(self, name: str, fn: Callable[..., Any]) -> Callable[..., Any]:
        def timed(*args: Any, **kwargs: Any) -> Any:
            if not self.on:
                return fn(*args, **kwargs)
            t0 = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - t0
                self.calls[name] = self.calls.get(name, 0) + 1

        return timed


class _TimedPool:
    """envpool's pool with its ``step``, ``reset``, ``send`` and ``recv`` timed (the emulator, or
    with ``overlap_env`` the wait for it, and envpool's own Python conversion)."""

    def __init__(self, pool: Any, timer: PhaseTimer) -> None:
        self._pool = pool
        for name in ("step", "reset", "send", "recv"):
            setattr(self, name, timer.wrap("env.emulator", getattr(pool, name)))

    def __getattr__(self, name: str) -> Any:
        return getattr(self._pool, name)


@contextmanager
def phase_timers(algo: str, timer: PhaseTimer) -> Iterator[None]:
    """Wrap the agent class's act/observe/learn and the vector env's step for the block."""

    from farsighter.agents import loop_class
    from farsighter.envs.envpool_vec import EnvpoolAtariVector
    from farsighter.envs.vector import LeanSyncVectorEnv

    cls = loop_class(algo)
    patched: list[tuple[Any, str, Any]] = []
    for name in ("act", "observe", "learn"):
        patched.append((cls, name, getattr(cls, name)))
        setattr(cls, name, timer.wrap(f"agent.{name}", getattr(cls, name)))
    steps = [(EnvpoolAtariVector, n) for n in ("step", "step_async", "step_wait")]
    for owner, name in [*steps, (gym.vector.SyncVectorEnv, "step"), (LeanSyncVectorEnv, "step")]:
        patched.append((owner, name, getattr(owner, name)))
        setattr(owner, name, timer.wrap("env.step", getattr(owner, name)))
    make_pool = EnvpoolAtariVector._make_pool

    def timed_make_pool(self: Any, seed: int) -> Any:
        pool = make_pool(self, seed)
        self._pool = _TimedPool(pool, timer)
        return self._pool

    patched.append((EnvpoolAtariVector, "_make_pool", make_pool))
    EnvpoolAtariVector._make_pool = timed_make_pool  # type: ignore[method-assign]
    try:
        yield
    finally:
        for owner, name, original in reversed(patched):
            setattr(owner, name, original)


class PhasedWindow(Window):
    """``Window`` that switches a :class:`PhaseTimer` on from its first step to step ``end``."""

    def __init__(self, start: int, end: int, timer: PhaseTimer) -> None:
        super().__init__(start)
        self.end, self.timer = end, timer

    def on_step(self, global_step: int, info: dict[str, Any], agent: Any) -> None:
        if self.timer.on and global_step >= self.end:
            self.timer.on = False
        super().on_step(global_step, info, agent)
        if self.first is not None and self.first["step"] == global_step:
            self.timer.on = True


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--algo", default="farsighter")
    p.add_argument("--device", choices=["cpu", "cuda"], default="cpu")
    p.add_argument("--num-envs", type=int, default=1)
    p.add_argument("--precision", choices=["fp32", "bf16"], default="fp32")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--warmup", type=int, default=2_000)
    p.add_argument("--measure", type=int, default=4_000)
    p.add_argument("--backend", choices=["auto", "gymnasium", "envpool"], default="auto")
    p.add_argument("--cuda-graph", choices=["auto", "on", "off"], default="auto")
    p.add_argument("--top", type=int, default=30)
    p.add_argument("--phases", action="store_true", help="phase timers instead of cProfile")
    p.add_argument("--overlap-env", choices=["auto", "on", "off"], default="auto")
    p.add_argument("--gpu-replay", choices=["auto", "off"], default="auto")
    p.add_argument("--target-cache", choices=["auto", "off"], default="auto")
    p.add_argument("--name", help="result file (default: loop_profile_<algo>_<device>_e<E>)")
    args = p.parse_args()

    from farsighter import train

    torch.set_num_threads(args.threads)
    spec = {
        "algo": args.algo,
        "seed": 1,
        "warmup": args.warmup,
        "measure": args.measure,
        "learning_starts": args.warmup,
        "num_envs": args.num_envs,
        "target_update_every": 1_000,
        "buffer_size": 100_000,
        "threads": args.threads,
        "device": args.device,
        "precision": args.precision,
        "cuda_graph": args.cuda_graph,
        "backend": args.backend,
        "overlap_env": args.overlap_env,
        "gpu_replay": args.gpu_replay,
        "target_cache": args.target_cache,
    }
    if args.phases:
        phases(args, spec)
        return
    with tempfile.TemporaryDirectory() as tmp:
        cfg = steady_state_config(spec, f"{tmp}/run")
        window = ProfiledWindow(args.warmup, args.warmup + args.measure)
        train(cfg, callbacks=[window])
    assert window.first is not None and window.last is not None
    steps = window.last["step"] - window.first["step"]
    wall = window.last["wall"] - window.first["wall"]
    stats = pstats.Stats(window.profiler)
    text = io.StringIO()
    pstats.Stats(window.profiler, stream=text).sort_stats("tottime").print_stats(args.top)
    print(
        f"{args.algo} {args.device} E={args.num_envs} {args.precision}: "
        f"{steps / wall:.1f} steps/s over {steps} steps (under cProfile)"
    )
    print(text.getvalue())
    rows = []
    for (file, line, func), (_, calls, own, cum, _) in stats.stats.items():  # type: ignore[attr-defined]
        rows.append(
            {
                "function": f"{file.rsplit('/', 2)[-1] if '/' in file else file}:{line}:{func}",
                "calls_per_step": round(calls / steps, 3),
                "own_ms_per_step": round(1000 * own / steps, 4),
                "cumulative_ms_per_step": round(1000 * cum / steps, 4),
            }
        )
    rows.sort(key=lambda r: -r["own_ms_per_step"])
    name = args.name or f"loop_profile_{args.algo}_{args.device}_e{args.num_envs}"
    write_result(
        name,
        {
            **run_fields(args),
            "steps": steps,
            "sps_under_profiler": round(steps / wall, 2),
            "ms_per_step_under_profiler": round(1000 * wall / steps, 4),
            "top_by_own_time": rows[: args.top],
            "top_by_cumulative_time": sorted(rows, key=lambda r: -r["cumulative_ms_per_step"])[
                : args.top
            ],
        },
    )


def run_fields(args: argparse.Namespace) -> dict[str, Any]:
    """What a result file records of the run it profiled."""
    return {
        "algo": args.algo,
        "device": args.device,
        "num_envs": args.num_envs,
        "precision": args.precision,
        "cuda_graph": args.cuda_graph,
        "target_cache": args.target_cache,
        "threads": args.threads,
    }


def phases(args: argparse.Namespace, spec: dict[str, Any]) -> None:
    from farsighter import train

    timer = PhaseTimer()
    with tempfile.TemporaryDirectory() as tmp, phase_timers(args.algo, timer):
        cfg = steady_state_config(spec, f"{tmp}/run")
        window = PhasedWindow(args.warmup, args.warmup + args.measure, timer)
        train(cfg, callbacks=[window])
    assert window.first is not None and window.last is not None
    steps = window.last["step"] - window.first["step"]
    wall = window.last["wall"] - window.first["wall"]
    ms = {name: 1000 * sec / steps for name, sec in timer.seconds.items()}
    timed = sum(v for k, v in ms.items() if k != "env.emulator")
    ms["loop.rest"] = 1000 * wall / steps - timed
    if "env.emulator" in ms and cfg.runtime.overlap_env == "off":
        ms["env.wrapper"] = ms.get("env.step", 0.0) - ms["env.emulator"]
    table = {k: round(v, 4) for k, v in sorted(ms.items())}
    per_batch = {k: round(v * args.num_envs, 3) for k, v in table.items()}
    print(f"{args.algo} {args.device} E={args.num_envs}: {steps / wall:.1f} steps/s")
    for k, v in table.items():
        print(f"  {k:14s} {v:8.4f} ms/step  {per_batch[k]:8.3f} ms per vector step")
    name = args.name or f"loop_phases_{args.algo}_{args.device}_e{args.num_envs}"
    write_result(
        name,
        {
            **run_fields(args),
            "steps": steps,
            "sps": round(steps / wall, 2),
            "ms_per_env_step": table,
            "ms_per_vector_step": per_batch,
            "calls": timer.calls,
            "overlap_env": cfg.runtime.overlap_env,
            "note": "agent.act includes, on a GPU, waiting for the updates queued before it; "
            "env.emulator: envpool's calls (without overlap inside env.step, env.wrapper = "
            "env.step - env.emulator; with overlap on envpool's step thread, beside agent.learn, "
            "and env.step is the loop's time in step_async + step_wait); "
            "loop.rest = wall - act - step - observe - learn",
        },
    )


if __name__ == "__main__":
    main()
