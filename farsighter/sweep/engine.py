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
"""

from __future__ import annotations

import ipaddress
import multiprocessing as mp
import multiprocessing.managers
import os
import re
import signal
import socket
import sys
import tempfile
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
from typing import IO, Any, TypeVar

from farsighter.errors import FarsighterError

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


PROBE_SECONDS = 5.0
"""How long the TCP check of ``--address`` waits for a connection (name lookup included)."""

JOIN_TIMEOUTS = {
    # Ray's own connect retries for minutes against a port that is open but is not Ray (20
    # attempts of up to 40 s to a head's GCS port; 5 + 10 + 15 s to a Ray Client port). These
    # bound one attempt to about 16 s. Ray reads the first and the Ray Client pair when it is
    # imported, so they hold when ray_init is the first to import Ray (the command line);
    # a value the user set wins.
    "RAY_py_gcs_connect_timeout_s": "5",
    "RAY_gcs_server_port_wait_time_s": "1",
    "RAY_CLIENT_INITIAL_CONNECTION_TIMEOUT_S": "5",
    "RAY_CLIENT_MAX_CONNECTION_TIMEOUT_S": "5",
}

_ADDRESS = re.compile(
    r"(?:ray://)?"  # Ray Client
    r"(?:\[(?P<ipv6>[0-9A-Fa-f:.]+)\]|(?P<host>[A-Za-z0-9_.-]+))"  # [IPv6] or a name / IPv4
    r":(?P<port>[0-9]{1,5})"
)


def parse_address(address: str) -> tuple[str, int]:
    """``(host, port)`` of a Ray address: ``HOST:PORT`` (a head's GCS port) or
    ``ray://HOST:PORT`` (Ray Client); anything else is an input error naming the forms."""
    match = _ADDRESS.fullmatch(address)
    port = int(match["port"]) if match else 0
    if match is None or not 1 <= port <= 65535:
        raise FarsighterError(
            f"--address {address!r} is not HOST:PORT (a Ray head's GCS port, e.g. "
            "10.0.0.5:6379) or ray://HOST:PORT (Ray Client, e.g. ray://10.0.0.5:10001); leave "
            "it out to start a local Ray"
        )
    return match["ipv6"] or match["host"], port


def check_address(address: str, timeout: float = PROBE_SECONDS) -> None:
    """Fail fast, before Ray is asked (its connect retries for minutes): ``address`` must be
    well formed and its host must accept a TCP connection within ``timeout`` seconds."""
    host, port = parse_address(address)
    outcome: list[BaseException | None] = []

    def connect() -> None:
        try:
            socket.create_connection((host, port), timeout=timeout).close()
            outcome.append(None)
        except BaseException as exc:  # handed to the caller below
            outcome.append(exc)

    # a thread, because the name lookup in create_connection has no timeout of its own
    thread = threading.Thread(target=connect, name="farsighter-address-check", daemon=True)
    thread.start()
    thread.join(timeout + 1.0)
    if outcome and outcome[0] is None:
        return
    exc = outcome[0] if outcome else None
    if exc is None or isinstance(exc, TimeoutError):
        why = f"no answer within {timeout:g} s"
    elif isinstance(exc, ConnectionRefusedError):
        why = "connection refused: nothing listens there"
    elif isinstance(exc, socket.gaierror):
        why = f"cannot resolve {host!r}: {exc.strerror}"
    else:
        why = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
    raise FarsighterError(
        f"cannot join the Ray cluster at --address {address}: tried a TCP connection to "
        f"{_hostport(host, port)}: {why}; start the Ray head there (ray start --head) or fix "
        "the address"
    )


def _hostport(host: str, port: int) -> str:
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"


@contextmanager
def _loopback_node() -> Iterator[None]:
    """While a local Ray starts: its node address is 127.0.0.1, so the GCS, the raylet, the
    workers and the agents listen on loopback only. Ray uses the machine's network address
    (it maps a requested 127.0.0.1 to it too) unless ENABLE_RAY_CLUSTER is off, which Ray reads
    from RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER when it is imported: both are set for the start (the
    variable for the processes it spawns) and restored after, so a later join of a cluster by
    this process is Ray's usual one."""
    from ray._private import ray_constants

    name, flag = ray_constants.ENABLE_RAY_CLUSTERS_ENV_VAR, ray_constants.ENABLE_RAY_CLUSTER
    saved = os.environ.get(name)
    os.environ[name] = "0"
    ray_constants.ENABLE_RAY_CLUSTER = False
    try:
        yield
    finally:
        ray_constants.ENABLE_RAY_CLUSTER = flag
        if saved is None:
            os.environ.pop(name, None)
        else:
            os.environ[name] = saved


def ray_init(backend: Backend) -> Any:
    """Start or join Ray, once per process (one line and exit code 2 when it is not installed,
    the address is malformed or nothing there answers as Ray).

    Without an address: a new local Ray (``RAY_ADDRESS`` is not followed) that listens on
    127.0.0.1 only, without the dashboard. With one: it is checked first (:func:`check_address`,
    at most a few seconds), then joined with Ray's connect timeouts shortened
    (:data:`JOIN_TIMEOUTS`: about 20 s in all when Ray was not imported before)."""
    if "ray" in sys.modules and sys.modules["ray"].is_initialized():
        return sys.modules["ray"]
    if backend.address:
        check_address(backend.address)
        for key, value in JOIN_TIMEOUTS.items():
            os.environ.setdefault(key, value)
    try:
        import ray
    except ImportError:
        raise FarsighterError(
            "--ray needs Ray: pip install 'farsighter[ray]' (or run without --ray on local "
            "worker processes)"
        ) from None
    os.environ.setdefault("RAY_DEDUP_LOGS", "0")
    if backend.address:
        host, port = parse_address(backend.address)
        said: list[str] = []
        try:
            with _ray_messages_kept_unless_it_fails(said):
                ray.init(address=backend.address, log_to_driver=False)
        except (OSError, RuntimeError, ValueError) as exc:
            raise FarsighterError(
                f"cannot join the Ray cluster at --address {backend.address}: "
                f"{_hostport(host, port)} accepts TCP connections but joining failed "
                f"({_first_line(exc)}{_last_message(said)}); {_join_hint(said)}"
            ) from None
        return ray
    try:
        with _loopback_node():
            ray.init(address="local", include_dashboard=False, log_to_driver=False)
    except (OSError, RuntimeError, ValueError) as exc:
        raise FarsighterError(f"could not start a local Ray: {_first_line(exc)}") from None
    node = ray.util.get_node_ip_address()
    if not ipaddress.ip_address(node).is_loopback:  # a Ray that no longer heeds the switch
        ray.shutdown()
        raise FarsighterError(
            f"a local Ray came up on {node}, not on loopback only; refusing to run on it (Ray "
            f"{ray.__version__} needs another way to keep its ports on 127.0.0.1)"
        )
    return ray


def _first_line(exc: BaseException) -> str:
    return (str(exc).strip().splitlines() or [type(exc).__name__])[0]


@contextmanager
def _ray_messages_kept_unless_it_fails(said: list[str]) -> Iterator[None]:
    """Ray's own output while it connects (its retries' warnings, from C++ and Python) goes to a
    temporary file: written to stderr after a connect that worked; after one that failed, its
    lines are left in ``said`` for the caller's one-line error."""
    sys.stdout.flush()
    sys.stderr.flush()
    try:
        saved = os.dup(2)
    except OSError:  # no stderr to redirect
        yield
        return
    with tempfile.TemporaryFile() as held:
        os.dup2(held.fileno(), 2)
        try:
            yield
        except BaseException:
            said += _read(held).splitlines()
            raise
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
        sys.stderr.write(_read(held))


def _read(file: IO[bytes]) -> str:
    sys.stderr.flush()
    file.seek(0)
    return file.read().decode(errors="replace")


_LOG_PREFIX = re.compile(
    r"^(?:\[[^]]*\]\s*"  # [2026-01-01 10:00:00,000 W 123 123] (Ray's C++ log)
    r"|\d{4}-\d\d-\d\d [\d:,.]+\s+\w+\s+\S+ -- "  # 2026-01-01 10:00:00,000 INFO worker.py:1 --
    r"|\S+\.py:\d+: )"  # /path/worker.py:335: (a Python warning)
)


def _last_message(said: list[str]) -> str:
    """``; Ray's last message: ...`` from Ray's output, or nothing."""
    lines = [line for line in said if line.strip() and not line[0].isspace()]
    if not lines:
        return ""
    return "; Ray's last message: " + _LOG_PREFIX.sub("", lines[-1]).strip()


def _join_hint(said: list[str]) -> str:
    if any("Unauthenticated" in line or "InvalidAuthToken" in line for line in said):
        return (
            "the cluster uses Ray's token authentication: set RAY_AUTH_MODE=token and give "
            "its token (RAY_AUTH_TOKEN, RAY_AUTH_TOKEN_PATH or ~/.ray/auth_token)"
        )
    return "give a Ray head's GCS port (HOST:6379) or its Ray Client port (ray://HOST:10001)"


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
