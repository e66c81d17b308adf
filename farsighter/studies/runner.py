"""Run a study's jobs in worker processes (or in this one) with one progress bar."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Any


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
