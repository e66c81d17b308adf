"""Run a study's jobs in worker processes (or in this one) with one progress bar."""

from __future__ import annotations

import argparse
import shutil
import time
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from pathlib import Path
from typing import Any

from farsighter.errors import FarsighterError


def add_study_arguments(
    parser: argparse.ArgumentParser, *, quick_help: str, out_help: str, agents_help: str
) -> None:
    """The arguments every study command shares (the study adds its own)."""
    parser.add_argument("--quick", action="store_true", help=quick_help)
    parser.add_argument("--out", default=None, help=out_help)
    parser.add_argument("--seeds", type=int, nargs="+", default=None)
    parser.add_argument("--steps", type=int, default=None)
    parser.add_argument(
        "--workers",
        type=int,
        default=0,
        help="worker processes (0: one per core; 1: runs in this process)",
    )
    parser.add_argument("--agents", nargs="+", default=None, help=agents_help)
    parser.add_argument(
        "--plot-only",
        metavar="DIR",
        default=None,
        help="redraw figures, table and report of an existing study",
    )
    parser.add_argument("--overwrite", action="store_true", help="delete --out first")
    parser.add_argument("--no-progress", action="store_true")


def redraw(path: Path, kind: str, write_outputs: Callable[[Path], None]) -> int:
    """--plot-only: figures, table and report again from a study directory's saved files."""
    if not (path / "study.json").exists():
        raise FarsighterError(f"{path} holds no {kind} study (no study.json)")
    write_outputs(path)
    print(f"report: {path / 'report.md'}")
    return 0


def run_and_report(out: Path, overwrite: bool, kind: str, run: Callable[[], object]) -> int:
    """Delete ``out`` first if asked, run the study, say where its outputs are."""
    if overwrite and out.exists():
        shutil.rmtree(out)
    t0 = time.perf_counter()
    run()
    print(f"{kind} study done in {time.perf_counter() - t0:.0f} s")
    print(f"report: {out / 'report.md'}")
    print(f"figures: {out / 'figures'}")
    return 0


def execute(
    fn: Callable[..., Any],
    jobs: Sequence[tuple[Any, ...]],
    *,
    steps: int,
    workers: int,
    desc: str,
    show_progress: bool,
    done_before: int = 0,
) -> None:
    """Call ``fn(*job, progress)`` for every job, where ``progress`` maps a run key to its current
    step (a run sets it, and -1 when done); each job is ``steps`` steps long. ``workers == 1``
    runs in this process (no interpreter start-up); otherwise fresh spawned interpreters, so
    nothing is shared by accident. A worker's error is re-raised here."""
    import multiprocessing as mp

    from tqdm import tqdm

    total = done_before + len(jobs) * steps
    bar = tqdm(
        total=total,
        initial=done_before,
        unit="step",
        disable=not show_progress,
        dynamic_ncols=True,
        desc=f"{desc} ({len(jobs)} runs, {workers} workers)",
    )
    try:
        if workers == 1:
            local: dict[str, int] = {}
            for i, job in enumerate(jobs):
                fn(*job, local)
                bar.n = done_before + (i + 1) * steps
                bar.refresh()
            return
        ctx = mp.get_context("spawn")
        with ctx.Manager() as manager:
            shared = manager.dict()
            finished = 0
            with ProcessPoolExecutor(workers, mp_context=ctx) as pool:
                pending = {pool.submit(fn, *job, shared) for job in jobs}
                while pending:
                    done, pending = wait(pending, timeout=1.0, return_when=FIRST_COMPLETED)
                    for fut in done:
                        fut.result()
                        finished += steps
                    running = sum(v for v in shared.values() if v > 0)
                    bar.n = done_before + finished + running
                    bar.refresh()
        bar.n = total
    finally:
        bar.close()
