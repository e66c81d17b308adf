"""Where a training step's time goes in the real loop: cProfile over a steady-state window.

The same run as one ``benchmarks.atari_sps`` measurement (Breakout, epsilon at its final value,
replay ratio 1/4, the Atari preset), with Python's cProfile switched on for the window only. On a
GPU every host-device synchronisation shows up as time inside the call that waits (``.cpu()``,
``.item()``, a copy to the host), so the table says both what the host computes and where it
waits. The JSON gives each listed function's own and cumulative milliseconds per environment
step, and the table is printed.

    python -m benchmarks.loop_profile [--algo farsighter] [--device cuda] [--num-envs 16]
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import tempfile
from typing import Any

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
    }
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
            "algo": args.algo,
            "device": args.device,
            "num_envs": args.num_envs,
            "precision": args.precision,
            "threads": args.threads,
            "steps": steps,
            "sps_under_profiler": round(steps / wall, 2),
            "ms_per_step_under_profiler": round(1000 * wall / steps, 4),
            "top_by_own_time": rows[: args.top],
            "top_by_cumulative_time": sorted(rows, key=lambda r: -r["cumulative_ms_per_step"])[
                : args.top
            ],
        },
    )


if __name__ == "__main__":
    main()
