"""Where one Double-DQN update's time goes: Nature CNN, batch 32, 4x84x84 uint8 frames already on
the device, centered RMSProp (the Atari preset: lr 0.0025, decay 0.95, eps 0.01), Huber loss,
gradient-norm clip 10: the update of farsighter.agents.ddqn, without the replay sampling.

Three layouts of the same network (same initial weights):

* ``fp32_nchw``: plain convolutions (NCHW weights and inputs);
* ``fp32_channels_last``: the library's NatureCNN (NHWC weights, inputs converted);
* ``bf16``: the library's NatureCNN under bfloat16 autocast (``set_precision``).

For each: the median milliseconds of a whole update (``--repeats`` after ``--warmup``; on CUDA
also captured as a CUDA graph and replayed, ``update_ms_cuda_graph``; with ``--compile`` also
through ``torch.compile``, ``update_ms_compiled``), and of
its phases timed one by one (with a device synchronisation at each boundary on CUDA):
``forward_s`` (Q(s) with grad), ``targets_s_next`` (online and target Q(s') without grad, the
double-Q target), ``backward`` (loss, zero_grad, backward) and ``optimizer`` (clip and RMSProp
step). Farsighter's extra cost per environment step, for one state: the acting forward pass
(torso), a Thompson draw (``BLRHead.q_sample``, and ``sample_weights(1)`` for held draws) and the
whole acting call from a numpy frame to a numpy action, beside DDQN's. ``--profile-steps`` whole
updates also go through torch.profiler: the top operators by self CPU (and CUDA) time.

The process keeps freed memory as training does (``farsighter.runtime.keep_heap``); ``--heap
default`` measures with glibc's own thresholds, and ``page_faults_per_update`` shows the
difference.

    python -m benchmarks.update_profile [--threads 2] [--device cpu|cuda] [--repeats 100]
"""

from __future__ import annotations

import argparse
import copy
import resource
import statistics
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import torch
from torch import nn

from benchmarks.common import cpu_features, median_ms, write_result
from farsighter import make_config
from farsighter.agents.common import make_optimizer, obs_tensor, td_loss
from farsighter.agents.cuda_graph import GraphedStep, set_capturable
from farsighter.networks import NatureCNN, set_precision
from farsighter.ops.blr import BLRHead
from farsighter.ops.targets import double_q_target
from farsighter.runtime import keep_heap

LAYOUTS = ("fp32_nchw", "fp32_channels_last", "bf16")
ISSUE_MS = {"fp32_nchw": 20.3, "fp32_channels_last": 17.2, "bf16": 12.1}  # quiet, 2 threads
BATCH = 32
FAULT_UPDATES = 20  # updates over which page faults are counted
FRAMES = (4, 84, 84)


class PlainNatureCNN(NatureCNN):
    """The Nature CNN with plain NCHW convolutions: weights converted back to the contiguous
    (NCHW) format and inputs not converted to channels-last."""

    def __init__(self, in_channels: int, screen: int = 84) -> None:
        super().__init__(in_channels, screen)
        for layer in self.conv:
            if isinstance(layer, nn.Conv2d):
                layer.weight.data = layer.weight.data.contiguous()

    def prepare(self, obs_BCHW: torch.Tensor) -> torch.Tensor:
        return obs_BCHW.float() / 255.0


class QNet(nn.Module):
    def __init__(self, torso: NatureCNN, num_actions: int) -> None:
        super().__init__()
        self.torso = torso
        self.head = nn.Linear(torso.out_dim, num_actions)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.head(self.torso(obs))


def build(layout: str, num_actions: int, device: torch.device) -> QNet:
    torch.manual_seed(0)  # the same weights in every layout
    torso = PlainNatureCNN(FRAMES[0]) if layout == "fp32_nchw" else NatureCNN(FRAMES[0])
    net = QNet(torso, num_actions).to(device)
    set_precision(net, "bf16" if layout == "bf16" else "fp32")
    return net


def profile_layout(
    layout: str, args: argparse.Namespace, device: torch.device, sync: Callable[[], None]
) -> dict[str, Any]:
    cfg = make_config("ddqn", "ALE/Breakout-v5")
    net = build(layout, args.actions, device)
    target = copy.deepcopy(net).requires_grad_(False)
    opt = make_optimizer(net.parameters(), cfg)
    gen = torch.Generator(device="cpu").manual_seed(1)
    obs = torch.randint(0, 256, (BATCH, *FRAMES), dtype=torch.uint8, generator=gen).to(device)
    next_obs = torch.randint(0, 256, (BATCH, *FRAMES), dtype=torch.uint8, generator=gen).to(device)
    actions = torch.randint(0, args.actions, (BATCH,), generator=gen).to(device)
    returns = torch.randn(BATCH, generator=gen).to(device)
    bootstrap = torch.full((BATCH,), cfg.gamma, device=device)
    params = list(net.parameters())

    def forward_s() -> torch.Tensor:
        return net(obs).gather(1, actions.unsqueeze(1)).squeeze(1)

    @torch.no_grad()
    def targets() -> torch.Tensor:
        return double_q_target(returns, bootstrap, net(next_obs), target(next_obs))

    def backward(q_B: torch.Tensor, y_B: torch.Tensor) -> None:
        loss = td_loss(q_B, y_B, cfg.loss)
        opt.zero_grad(set_to_none=True)
        loss.backward()

    def optimizer() -> None:
        nn.utils.clip_grad_norm_(params, cfg.max_grad_norm)
        opt.step()

    def update() -> None:  # the order of DDQNAgent.update
        q_B = forward_s()
        backward(q_B, targets())
        optimizer()

    whole = median_ms(update, args.repeats, args.warmup, sync)
    faults0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(FAULT_UPDATES):
        update()
    sync()
    faults = (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - faults0) / FAULT_UPDATES
    graphed = None
    if (
        device.type == "cuda"
    ):  # the same update captured once and replayed (RuntimeConfig.cuda_graph)

        def step_fn(_: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
            update()
            return {}

        set_capturable(opt, True)
        step = GraphedStep(step_fn)
        graphed = round(median_ms(lambda: step({}), args.repeats, args.warmup, sync), 3)
        set_capturable(opt, False)
    compiled = None
    if (
        args.compile
    ):  # the same update through torch.compile (RuntimeConfig.compile); compiles first
        compiled_update = torch.compile(update, dynamic=False)
        compiled = round(median_ms(compiled_update, args.repeats, args.warmup, sync), 3)

    phases: dict[str, list[float]] = {
        "forward_s": [],
        "targets_s_next": [],
        "backward": [],
        "optimizer": [],
    }
    for i in range(args.warmup + args.repeats):
        sync()
        t0 = time.perf_counter()
        q_B = forward_s()
        sync()
        t1 = time.perf_counter()
        y_B = targets()
        sync()
        t2 = time.perf_counter()
        backward(q_B, y_B)
        sync()
        t3 = time.perf_counter()
        optimizer()
        sync()
        t4 = time.perf_counter()
        if i >= args.warmup:
            for name, dt in zip(phases, (t1 - t0, t2 - t1, t3 - t2, t4 - t3), strict=True):
                phases[name].append(dt)
    phase_ms = {name: round(statistics.median(v) * 1e3, 3) for name, v in phases.items()}

    # Farsighter's per-step extras, one state (E = 1), no grad.
    head = BLRHead(num_actions=args.actions, dim=net.torso.out_dim, device=device)
    draw_gen = torch.Generator(device=device).manual_seed(2)
    frame_np = np.random.default_rng(3).integers(0, 256, (1, *FRAMES), dtype=np.uint8)
    frame = obs_tensor(frame_np, device)
    with torch.no_grad():
        phi_1D = net.torso(frame)

        def act_forward() -> None:
            net.torso(frame)

        def q_sample() -> None:
            head.q_sample(phi_1D, generator=draw_gen)

        def sample_weights() -> None:
            head.sample_weights(1, generator=draw_gen)

        def farsighter_act() -> None:
            phi = net.torso(obs_tensor(frame_np, device))
            head.q_sample(phi, generator=draw_gen).argmax(dim=1).cpu().numpy()

        def ddqn_act() -> None:
            net(obs_tensor(frame_np, device)).argmax(dim=1).cpu().numpy()

        extras = {
            name: round(median_ms(fn, args.repeats, args.warmup, sync), 4)
            for name, fn in (
                ("acting_forward_torso", act_forward),
                ("thompson_q_sample", q_sample),
                ("thompson_sample_weights", sample_weights),
                ("farsighter_act_total", farsighter_act),
                ("ddqn_act_total", ddqn_act),
            )
        }
    extras["farsighter_extra_per_step"] = round(
        extras["farsighter_act_total"] - extras["ddqn_act_total"], 4
    )

    top = profile_ops(update, sync, args, device) if args.profile_steps > 0 else None
    return {
        "update_ms": round(whole, 3),
        "update_ms_cuda_graph": graphed,
        "update_ms_compiled": compiled,
        "page_faults_per_update": round(faults, 1),
        "phases_ms": phase_ms,
        "phases_sum_ms": round(sum(phase_ms.values()), 3),
        "per_step_extras_ms": extras,
        "issue_update_ms": ISSUE_MS[layout],
        "top_ops": top,
    }


def profile_ops(
    update: Callable[[], None],
    sync: Callable[[], None],
    args: argparse.Namespace,
    device: torch.device,
) -> list[dict[str, Any]]:
    from torch.profiler import ProfilerActivity, profile

    activities = [ProfilerActivity.CPU]
    if device.type == "cuda":
        activities.append(ProfilerActivity.CUDA)
    n = args.profile_steps
    with profile(activities=activities) as prof:
        for _ in range(n):
            update()
        sync()
    events = prof.key_averages()

    def self_device(e: Any) -> float:
        return float(getattr(e, "self_device_time_total", getattr(e, "self_cuda_time_total", 0)))

    key = self_device if device.type == "cuda" else (lambda e: float(e.self_cpu_time_total))
    rows = []
    for e in sorted(events, key=key, reverse=True)[: args.top]:
        row = {
            "op": e.key,
            "calls_per_update": round(e.count / n, 2),
            "self_cpu_ms_per_update": round(e.self_cpu_time_total / 1e3 / n, 4),
        }
        if device.type == "cuda":
            row["self_cuda_ms_per_update"] = round(self_device(e) / 1e3 / n, 4)
        rows.append(row)
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--device", choices=["cpu", "cuda"], default="cpu")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--layouts", nargs="+", choices=LAYOUTS, default=list(LAYOUTS))
    p.add_argument("--warmup", type=int, default=20)
    p.add_argument("--repeats", type=int, default=100)
    p.add_argument("--actions", type=int, default=4, help="Breakout's action set: 4")
    p.add_argument("--profile-steps", type=int, default=20, help="updates under torch.profiler")
    p.add_argument("--top", type=int, default=12, help="operators listed per layout")
    p.add_argument(
        "--compile",
        action="store_true",
        help="also time each layout's update through torch.compile (update_ms_compiled)",
    )
    p.add_argument(
        "--heap",
        choices=["keep", "default"],
        default="keep",
        help="keep: freed memory stays in the process, as in training (farsighter.runtime); "
        "default: glibc's own thresholds",
    )
    p.add_argument("--name", help="result file (default: update_profile, _gpu on CUDA)")
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    heap_kept = args.heap == "keep" and keep_heap()
    device = torch.device(args.device)
    if device.type == "cuda":
        if not torch.cuda.is_available():
            raise SystemExit("--device cuda: torch sees no CUDA device")

        def sync() -> None:
            torch.cuda.synchronize()
    else:

        def sync() -> None:
            pass

    layouts = {}
    for layout in args.layouts:
        print(f"{layout} ...", file=sys.stderr, flush=True)
        layouts[layout] = profile_layout(layout, args, device, sync)
        print(f"  update {layouts[layout]['update_ms']} ms", file=sys.stderr, flush=True)
    base = layouts.get("fp32_nchw", {}).get("update_ms")
    speedup = {k: round(base / v["update_ms"], 3) for k, v in layouts.items()} if base else None
    figures = {
        "device": args.device,
        "threads": args.threads,
        "batch": BATCH,
        "frames": list(FRAMES),
        "num_actions": args.actions,
        "warmup": args.warmup,
        "repeats": args.repeats,
        "statistic": "median ms",
        "heap": "kept (farsighter.runtime.keep_heap)" if heap_kept else "glibc default",
        "update_ms": {k: v["update_ms"] for k, v in layouts.items()},
        "update_ms_cuda_graph": {k: v["update_ms_cuda_graph"] for k, v in layouts.items()},
        "update_ms_compiled": {k: v["update_ms_compiled"] for k, v in layouts.items()},
        "speedup_over_fp32_nchw": speedup,
        "issue_update_ms": {k: ISSUE_MS[k] for k in layouts},
        "issue_note": "the issue's figures, a quiet machine at 2 threads (machine.load_average "
        "says how quiet this one was)",
        "optimizer": "RMSprop(lr=0.0025, alpha=0.95, eps=0.01, centered=True), clip 10, Huber",
        "notes": [
            "update_ms: one whole update, synchronised only at its end; phases_ms: the same "
            "update with a synchronisation at each phase boundary (on CPU they are the same "
            "thing; their sum may differ from update_ms by timer overhead)",
            "per_step_extras_ms: one state (E = 1); farsighter_extra_per_step = "
            "farsighter_act_total - ddqn_act_total, paid at every environment step (an update "
            "comes every 4)",
            f"page_faults_per_update: minor page faults of the process over {FAULT_UPDATES} "
            "whole updates after the timed ones (memory the allocator had given back and "
            "touched again)",
            "the Thompson draw runs at the prior covariance (dense, as after a refresh): its "
            "cost does not depend on the values",
        ],
        "cpu_features": cpu_features(),
        "layouts": layouts,
    }
    name = args.name or ("update_profile_gpu" if device.type == "cuda" else "update_profile")
    print(f"wrote {write_result(name, figures)}", file=sys.stderr)


if __name__ == "__main__":
    main()
