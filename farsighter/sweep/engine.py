"""Run many training runs: in this process, on local worker processes, or on a Ray cluster.

One engine for every study and sweep. It calls ``fn(*job, progress)`` for each job, where
``progress`` is a mapping the job sets to its current step (and to -1 when done), and draws one
progress bar over all jobs. Where the jobs run is a :class:`Backend`:

* ``workers == 1`` without Ray: one after another in this process (no interpreter start-up).
* local processes (the default): each job in a fresh spawned interpreter, ``workers`` at once.
  A job whose process dies (killed, out of memory) or raises is started again, up to
  ``retries`` times; an input error (:class:`~farsighter.errors.FarsighterError`) is not retried.
* Ray (``ray=True``): each job a Ray task with ``cpus`` and ``gpus`` of its own, at most
  ``workers`` in flight (0: as many as the cluster's resources allow). Ray restarts a task whose
  worker died or that raised, up to ``retries`` times.

A restarted job calls ``fn`` again from the start: the job itself decides what a restart means
(a sweep's trial resumes from its last checkpoint; a study's run starts afresh, because its
callbacks' state is not checkpointed). A job that fails for good stops the whole run with
:class:`TrialError`, after the others in flight are stopped.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import sys
import time
import traceback
from collections import deque
from collections.abc import Callable, Iterable, Mapping, MutableMapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from farsighter.errors import FarsighterError

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
    """Ray cluster to join (``ray://host:10001`` or ``host:6379``); None starts a local Ray."""
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
    """Read-only training callback: tells the parent how far a run is (-1 when done)."""

    def __init__(self, progress: MutableMapping[str, int], key: str, every: int = 500) -> None:
        self.progress, self.key, self.every, self.next = progress, key, every, 0

    def on_step(self, global_step: int, info: dict[str, Any], agent: Any) -> None:
        if global_step >= self.next:
            self.next = global_step + self.every
            self.progress[self.key] = global_step

    def on_finish(self, run_dir: Path, agent: Any) -> None:
        self.progress[self.key] = -1


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


def _child(
    fn: Callable[..., Any],
    job: tuple[Any, ...],
    progress: MutableMapping[str, int],
    errors: MutableMapping[int, str],
    index: int,
) -> None:
    """A worker process: one job; its error goes to the parent as text."""
    try:
        fn(*job, progress)
    except FarsighterError as exc:
        errors[index] = str(exc)
        sys.exit(FATAL_EXIT)
    except BaseException:
        errors[index] = traceback.format_exc()
        raise


def _on_processes(
    fn: Callable[..., Any],
    jobs: Sequence[tuple[Any, ...]],
    steps: Sequence[int],
    backend: Backend,
    bar: Any,
    done_before: int,
) -> None:
    """Each job in its own spawned interpreter (nothing shared by accident, and a dead process
    harms no other job), ``workers`` at once, restarted when it dies or raises."""
    ctx = mp.get_context("spawn")
    workers = backend.local_workers
    with ctx.Manager() as manager:
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
                        target=_child, args=(fn, jobs[i], shared, errors, i), daemon=False
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


def ray_init(backend: Backend) -> Any:
    """Start or join Ray (one line and exit code 2 when it is not installed or unreachable)."""
    try:
        import ray
    except ImportError:
        raise FarsighterError(
            "--ray needs Ray: pip install 'farsighter[ray]' (or run without --ray on local "
            "worker processes)"
        ) from None
    if not ray.is_initialized():
        os.environ.setdefault("RAY_DEDUP_LOGS", "0")
        try:
            if backend.address:
                ray.init(address=backend.address, log_to_driver=False)
            else:
                ray.init(include_dashboard=False, log_to_driver=False)
        except (ConnectionError, RuntimeError, ValueError) as exc:
            where = backend.address or "a local Ray"
            raise FarsighterError(f"could not start or join {where}: {exc}") from None
    return ray


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
    ray = ray_init(backend)

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
