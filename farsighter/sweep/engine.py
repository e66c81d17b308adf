"""Run many training runs: in this process, on local worker processes, or on a Ray cluster.

One engine for every study and sweep. It calls ``fn(*job, progress)`` for each job, where
``progress`` is a mapping the job sets to its current step (and to -1 when done), and draws one
progress bar over all jobs. Where the jobs run is a :class:`Backend`:

* ``workers == 1`` without Ray: one after another in this process (no interpreter start-up).
* local processes (the default): each job in a fresh spawned interpreter, ``workers`` at once.
  A job whose process dies (killed, out of memory) or raises is started again, up to
  ``retries`` times; an input error (:class:`~farsighter.errors.FarsighterError`) is not retried.
  The workers end with this process (stopped by SIGTERM, or killed).
* Ray (``ray=True``): each job a Ray task with ``cpus`` and ``gpus`` of its own, at most
  ``workers`` in flight (0: as many as the cluster's resources allow). Ray restarts a task whose
  worker died or that raised, up to ``retries`` times.

A restarted job calls ``fn`` again from the start: the job itself decides what a restart means
(a sweep's trial resumes from its last checkpoint; a study's run starts afresh, because its
callbacks' state is not checkpointed). A job that fails for good stops the whole run with
:class:`TrialError`, after the others in flight are stopped.

Starting or joining Ray (:func:`ray_init`, the address checks) lives in
:mod:`farsighter.sweep.ray_connect` and is re-exported here.
"""

from __future__ import annotations

import multiprocessing as mp
import multiprocessing.managers
import os
import signal
import sys
import threading
import time
import traceback
from collections import deque
from collections.abc import (
    Callable,
    Hashable,
    Iterable,
    Iterator,
    Mapping,
    MutableMapping,
    Sequence,
)
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from farsighter.errors import FarsighterError
from farsighter.sweep.ray_connect import (  # noqa: F401  (re-exported)
    JOIN_TIMEOUTS,
    PROBE_SECONDS,
    _join_hint,
    _last_message,
    check_address,
    parse_address,
    ray_init,
)

T = TypeVar("T")

FATAL_EXIT = 3
"""Exit code of a worker whose job raised an input error: not retried."""


class TrialError(RuntimeError):
    """A job failed on every attempt."""


@dataclass(frozen=True)
class Backend:
    """Where and how the jobs run."""

    workers: int = 0
    """Jobs at once (0: one per core locally; as the cluster's resources allow on Ray). Without
    Ray, 1 runs the jobs one after another in this process."""
    retries: int = 2
    """Restarts of a job whose process died or raised (not for input errors)."""
    ray: bool = False
    """Run the jobs as Ray tasks."""
    address: str | None = None
    """Ray cluster to join (``ray://host:10001`` or ``host:6379``); None starts a local Ray that
    listens on 127.0.0.1 only (:func:`ray_init`)."""
    cpus: float = 1.0
    """CPUs per job on Ray (each run uses one torch thread unless its config says otherwise)."""
    gpus: float = 0.0
    """GPU fraction per job on Ray."""

    def describe(self) -> str:
        if self.ray:
            where = self.address or "local Ray"
            limit = f"at most {self.workers} at once" if self.workers else "as resources allow"
            return f"{where}, {self.cpus:g} CPU + {self.gpus:g} GPU per run, {limit}"
        if self.workers == 1:
            return "this process"
        return f"{self.local_workers} worker processes"

    @property
    def local_workers(self) -> int:
        """Worker processes of the local engine (``workers``, else one per CPU)."""
        return self.workers or os.cpu_count() or 1


class Progress:
    """Read-only training callback: tells the parent how far a run is (-1 when done). ``runs``:
    the runs of a seed batch this one speaks for (they step together), whose steps it reports."""

    def __init__(
        self, progress: MutableMapping[str, int], key: str, every: int = 500, runs: int = 1
    ) -> None:
        self.progress, self.key, self.every, self.next = progress, key, every, 0
        self.runs = runs

    def on_step(self, global_step: int, info: dict[str, Any], agent: Any) -> None:
        if global_step >= self.next:
            self.next = global_step + self.every
            self.progress[self.key] = global_step * self.runs

    def on_finish(self, run_dir: Path, agent: Any) -> None:
        self.progress[self.key] = -1


def chunk_by(items: Sequence[T], key: Callable[[T], Hashable], size: int) -> list[list[T]]:
    """``items`` in groups of at most ``size`` that share a ``key``, each group where its first
    item stands (one process may take a group: the seeds of one run trained together)."""
    open_groups: dict[Hashable, list[T]] = {}
    groups: list[list[T]] = []
    for item in items:
        group = open_groups.get(key(item))
        if group is None or len(group) == size:
            group = open_groups[key(item)] = []
            groups.append(group)
        group.append(item)
    return groups


def execute(
    fn: Callable[..., Any],
    jobs: Sequence[tuple[Any, ...]],
    *,
    steps: Sequence[int],
    backend: Backend,
    desc: str,
    show_progress: bool,
    done_before: int = 0,
) -> None:
    """Call ``fn(*job, progress)`` for every job (job i is ``steps[i]`` steps long), on
    ``backend``. A job's last element names it (its run directory), in messages and as its key
    in ``progress``. A job's final error is raised here as :class:`TrialError` (or as the input
    error it was)."""
    from tqdm import tqdm

    total = done_before + sum(steps)
    bar = tqdm(
        total=total,
        initial=done_before,
        unit="step",
        disable=not show_progress,
        dynamic_ncols=True,
        desc=f"{desc} ({len(jobs)} runs, {backend.describe()})",
    )
    try:
        if backend.ray:
            _on_ray(fn, jobs, steps, backend, bar, done_before)
        elif backend.workers == 1:
            _in_process(fn, jobs, steps, backend, bar)
        else:
            _on_processes(fn, jobs, steps, backend, bar, done_before)
        bar.n = total
    finally:
        bar.close()


def _say(bar: Any, message: str) -> None:
    bar.write(message, file=sys.stderr)


def _failed(job: tuple[Any, ...], attempts: int, why: object) -> TrialError:
    return TrialError(f"run {job[-1]} failed {attempts} times: {why}")


def _show(
    bar: Any,
    done: int,
    progress: Mapping[str, int],
    running: Iterable[tuple[tuple[Any, ...], int]],
) -> None:
    """The bar at ``done`` finished steps plus the steps the running ``(job, steps)`` report; a
    job that reported -1 (done) while its process is still ending counts all its steps."""
    bar.n = done + sum(
        steps if (reported := progress.get(str(job[-1]), 0)) < 0 else reported
        for job, steps in running
    )
    bar.refresh()


def _in_process(
    fn: Callable[..., Any],
    jobs: Sequence[tuple[Any, ...]],
    steps: Sequence[int],
    backend: Backend,
    bar: Any,
) -> None:
    local: dict[str, int] = {}
    for job, n in zip(jobs, steps, strict=True):
        for attempt in range(backend.retries + 1):
            try:
                fn(*job, local)
                break
            except FarsighterError:
                raise
            except Exception as exc:
                if attempt == backend.retries:
                    raise _failed(job, attempt + 1, exc) from exc
                _say(bar, f"run {job[-1]} raised {exc!r}; restarting it ({attempt + 1})")
        bar.update(n)


PARENT_GONE_EXIT = 4
"""Exit code of a worker (or the manager process) that ended because the process that started
it is gone."""

PARENT_WATCH_SECONDS = 1.0
"""How often a worker checks that the process that started it is still there."""


def exit_with_parent(parent: int) -> None:
    """End this process (exit code :data:`PARENT_GONE_EXIT`) once the process ``parent`` that
    started it is gone, killed even by SIGKILL, which runs no clean-up there: a worker (and the
    manager process that carries the progress) does not run on as an orphan, training a run
    nobody waits for. A daemon thread polls the parent's pid every
    :data:`PARENT_WATCH_SECONDS`."""

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(PARENT_WATCH_SECONDS)
        os._exit(PARENT_GONE_EXIT)

    threading.Thread(target=watch, name="farsighter-parent-watch", daemon=True).start()


def _child(
    fn: Callable[..., Any],
    job: tuple[Any, ...],
    progress: MutableMapping[str, int],
    errors: MutableMapping[int, str],
    index: int,
    parent: int,
) -> None:
    """A worker process: one job; its error goes to the parent as text; it ends with its parent."""
    exit_with_parent(parent)
    try:
        fn(*job, progress)
    except FarsighterError as exc:
        errors[index] = str(exc)
        sys.exit(FATAL_EXIT)
    except BaseException:
        errors[index] = traceback.format_exc()
        raise


@contextmanager
def _terminate_raises_exit() -> Iterator[None]:
    """SIGTERM (``kill``, a scheduler's stop) raises SystemExit in this process while the block
    runs, so that its clean-up (the workers stopped, the manager shut down) runs, which Python's
    default SIGTERM skips. Only in the main thread, where Python delivers signals; the previous
    handler is restored after."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def stop(signum: int, frame: Any) -> None:
        raise SystemExit(128 + signum)

    previous = signal.signal(signal.SIGTERM, stop)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _on_processes(
    fn: Callable[..., Any],
    jobs: Sequence[tuple[Any, ...]],
    steps: Sequence[int],
    backend: Backend,
    bar: Any,
    done_before: int,
) -> None:
    """Each job in its own spawned interpreter (nothing shared by accident, and a dead process
    harms no other job), ``workers`` at once, restarted when it dies or raises. A SIGTERM to
    this process stops the workers before it exits; killed outright, its workers and manager
    process end by themselves (:func:`exit_with_parent`)."""
    ctx = mp.get_context("spawn")
    workers = backend.local_workers
    parent = os.getpid()
    manager = multiprocessing.managers.SyncManager(ctx=ctx)
    manager.start(exit_with_parent, (parent,))  # the progress's process, ended with this one
    with manager, _terminate_raises_exit():
        shared, errors = manager.dict(), manager.dict()
        todo: deque[int] = deque(range(len(jobs)))
        running: dict[int, Any] = {}
        attempts = [0] * len(jobs)
        finished = 0
        try:
            while todo or running:
                while todo and len(running) < workers:
                    i = todo.popleft()
                    attempts[i] += 1
                    proc = ctx.Process(
                        target=_child, args=(fn, jobs[i], shared, errors, i, parent), daemon=False
                    )
                    proc.start()
                    running[i] = proc
                time.sleep(0.5)
                for i, proc in list(running.items()):
                    if proc.is_alive():
                        continue
                    proc.join()
                    del running[i]
                    if proc.exitcode == 0:
                        finished += steps[i]
                        continue
                    message = errors.pop(i, "")
                    if proc.exitcode == FATAL_EXIT:
                        raise FarsighterError(message)
                    why = f"exit code {proc.exitcode}" + (
                        " (killed)" if proc.exitcode and proc.exitcode < 0 else ""
                    )
                    if attempts[i] > backend.retries:
                        tail = message.strip().splitlines()[-1:] or [why]
                        raise _failed(jobs[i], attempts[i], tail[0])
                    _say(bar, f"run {jobs[i][-1]}: worker ended with {why}; restarting it")
                    todo.appendleft(i)
                _show(bar, done_before + finished, shared, ((jobs[i], steps[i]) for i in running))
        finally:
            for proc in running.values():
                proc.terminate()
            for proc in running.values():
                proc.join()


# ------------------------------------------------------------------------------------------------
# Ray
# ------------------------------------------------------------------------------------------------


class _RemoteProgress:
    """The ``progress`` mapping of a Ray task: writes go to the driver's progress actor."""

    def __init__(self, actor: Any) -> None:
        self.actor = actor

    def __setitem__(self, key: str, value: int) -> None:
        self.actor.set.remote(key, value)


def _ray_call(fn: Callable[..., Any], job: tuple[Any, ...], actor: Any) -> None:
    fn(*job, _RemoteProgress(actor))


def _on_ray(
    fn: Callable[..., Any],
    jobs: Sequence[tuple[Any, ...]],
    steps: Sequence[int],
    backend: Backend,
    bar: Any,
    done_before: int,
) -> None:
    ray = ray_init(backend.address)

    @ray.remote(num_cpus=0)
    class ProgressActor:
        def __init__(self) -> None:
            self.steps: dict[str, int] = {}

        def set(self, key: str, value: int) -> None:
            self.steps[key] = value

        def get(self) -> dict[str, int]:
            return self.steps

    actor = ProgressActor.remote()  # type: ignore[attr-defined]
    task = ray.remote(_ray_call).options(
        num_cpus=backend.cpus,
        num_gpus=backend.gpus,
        max_retries=backend.retries,
        retry_exceptions=True,
    )
    todo: deque[int] = deque(range(len(jobs)))
    in_flight: dict[Any, int] = {}
    finished = 0
    try:
        while todo or in_flight:
            while todo and (not backend.workers or len(in_flight) < backend.workers):
                i = todo.popleft()
                in_flight[task.remote(fn, jobs[i], actor)] = i
            done, _ = ray.wait(list(in_flight), num_returns=1, timeout=1.0)
            for ref in done:
                i = in_flight.pop(ref)
                try:
                    ray.get(ref)
                except ray.exceptions.RayError as exc:
                    task_error = isinstance(exc, ray.exceptions.RayTaskError)
                    cause = exc.as_instanceof_cause() if task_error else exc
                    if isinstance(cause, FarsighterError):
                        raise FarsighterError(str(cause).splitlines()[-1]) from None
                    raise _failed(jobs[i], backend.retries + 1, cause) from None
                finished += steps[i]
            current = ray.get(actor.get.remote())
            running = ((jobs[i], steps[i]) for i in in_flight.values())
            _show(bar, done_before + finished, current, running)
    finally:
        for ref in in_flight:
            ray.cancel(ref, force=True)
