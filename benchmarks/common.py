"""Helpers for benchmark scripts: machine description and JSON output."""

from __future__ import annotations

import json
import os
import platform
import shlex
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path, PurePath
from typing import Any

import torch

RESULTS = Path(__file__).resolve().parent / "results"
REPO = Path(__file__).resolve().parent.parent


def relative_command(
    argv: Sequence[str], root: PurePath, executable: str = "python", module: bool | None = None
) -> str:
    """The command line ``argv`` written relative to the repository ``root``.

    ``argv[0]`` inside the root becomes ``-m package.module`` when the script ran as a module
    (``module``; by default, when ``argv[0]`` is absolute, as ``python -m`` makes it), else its
    relative path; every other absolute path inside the root (``--out=/repo/x`` too) becomes
    relative. Pure: no file system access.
    """

    def inside(arg: str) -> PurePath | None:
        path = PurePath(arg)
        if path.is_absolute() and path.is_relative_to(root):
            return path.relative_to(root)
        return None

    def rel(arg: str) -> str:
        flag, eq, value = arg.partition("=")
        if eq and flag.startswith("-"):
            return flag + eq + rel(value)
        relative = inside(arg)
        return arg if relative is None else relative.as_posix()

    if not argv:
        return executable
    script, *rest = argv
    relative = inside(script)
    if relative is not None and relative.suffix == ".py" and module is not False:
        parts = list(relative.with_suffix("").parts)
        if parts[-1] == "__main__" and len(parts) > 1:
            parts.pop()
        head = ["-m", ".".join(parts)]
    else:
        head = [rel(script)]
    return shlex.join([executable, *head, *(rel(a) for a in rest)])


def machine() -> dict[str, Any]:
    return {
        "cpu_count": os.cpu_count(),
        "torch_threads": torch.get_num_threads(),
        "torch": torch.__version__,
        "cuda": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None,
        "python": platform.python_version(),
        "platform": platform.platform(),
        # other work on the machine when the result was written (1, 5, 15 min); figures taken
        # with a load above the core count are lower bounds
        "load_average": [round(x, 2) for x in os.getloadavg()],
    }


def write_result(name: str, figures: dict[str, Any]) -> Path:
    RESULTS.mkdir(parents=True, exist_ok=True)
    payload = {
        # relative to the repository: the same line runs from any checkout
        "command": relative_command(
            [os.path.realpath(sys.argv[0]), *sys.argv[1:]]
            if os.path.isfile(sys.argv[0])
            else sys.argv,
            REPO,
            executable=Path(sys.executable).name,
            module=getattr(sys.modules["__main__"], "__spec__", None) is not None,
        ),
        "date": time.strftime("%Y-%m-%d %H:%M:%S"),
        "machine": machine(),
        **figures,
    }
    out = RESULTS / f"{name}.json"
    out.write_text(json.dumps(payload, indent=2) + "\n")
    print(json.dumps(payload, indent=2))
    return out


def cpu_model() -> str:
    """The CPU's model name (``lscpu``'s), from /proc/cpuinfo."""
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "unknown"


def median_ms(
    fn: Callable[[], Any], repeats: int, warmup: int = 5, sync: Callable[[], None] = lambda: None
) -> float:
    """The median milliseconds of ``repeats`` calls of ``fn`` after ``warmup`` (``sync`` waits
    for a device after each call: ``torch.cuda.synchronize`` on a GPU)."""
    for _ in range(warmup):
        fn()
    sync()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        sync()
        times.append(time.perf_counter() - t0)
    return statistics.median(times) * 1e3


def cpu_features() -> dict[str, Any]:
    """What decides bf16 speed on a CPU: torch's dispatch level and the bf16 instruction flags."""
    flags: set[str] = set()
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("flags"):
                    flags = set(line.split(":", 1)[1].split())
                    break
    except OSError:
        pass
    wanted = ("avx2", "avx512f", "avx512_bf16", "amx_bf16", "amx_tile")
    return {
        "torch_cpu_capability": torch.backends.cpu.get_cpu_capability(),
        "flags": [f for f in wanted if f in flags],
    }


def train_deep_sea(
    size: int, episodes: int, seed: int, eval_every: int, **overrides: Any
) -> tuple[Any, Any, list[float]]:
    """Train Farsighter (the library's defaults plus ``overrides``) on bsuite's deep sea N =
    ``size`` for ``episodes`` episodes (N steps each) in a temporary run directory, one torch
    thread, no checkpoints; returns (config, trained agent, each episode's return)."""
    import csv
    import tempfile

    from farsighter import make_config, train

    torch.set_num_threads(1)
    seen: dict[str, Any] = {}

    class Keep:  # the trained agent, read after the run
        def on_step(self, global_step: int, info: dict[str, Any], agent: Any) -> None:
            pass

        def on_finish(self, run_dir: Path, agent: Any) -> None:
            seen["agent"] = agent

    with tempfile.TemporaryDirectory() as tmp:
        cfg = make_config(
            "farsighter",
            f"farsighter/DeepSea{size}-v0",
            seed=seed,
            total_steps=size * episodes,
            eval_every=eval_every,
            eval_episodes=1,
            progress=False,
            checkpoint_every=0,
            save_replay=False,
            run_dir=f"{tmp}/run",
            torch_threads=1,
            **overrides,
        )
        train(cfg, [Keep()])
        with (Path(tmp) / "run" / "metrics.csv").open() as fh:
            returns = [float(r["episodic_return"]) for r in csv.DictReader(fh)]
    return cfg, seen["agent"], returns
