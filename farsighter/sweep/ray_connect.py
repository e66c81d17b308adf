"""Starting or joining Ray for the engine's Ray backend (:mod:`farsighter.sweep.engine`, which
re-exports these): the address's form and a fast TCP check of it, a local Ray on loopback only,
and one-line errors from Ray's own output when joining fails."""

from __future__ import annotations

import ipaddress
import os
import re
import socket
import sys
import tempfile
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import IO, Any

from farsighter.errors import FarsighterError

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


def ray_init(address: str | None = None) -> Any:
    """Start or join Ray, once per process (one line and exit code 2 when it is not installed,
    the address is malformed or nothing there answers as Ray).

    Without an address: a new local Ray (``RAY_ADDRESS`` is not followed) that listens on
    127.0.0.1 only, without the dashboard. With one: it is checked first (:func:`check_address`,
    at most a few seconds), then joined with Ray's connect timeouts shortened
    (:data:`JOIN_TIMEOUTS`: about 20 s in all when Ray was not imported before). ``address``:
    a backend's ``address`` (:class:`farsighter.sweep.engine.Backend`)."""
    if "ray" in sys.modules and sys.modules["ray"].is_initialized():
        return sys.modules["ray"]
    if address:
        check_address(address)
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
    if address:
        host, port = parse_address(address)
        said: list[str] = []
        try:
            with _ray_messages_kept_unless_it_fails(said):
                ray.init(address=address, log_to_driver=False)
        except (OSError, RuntimeError, ValueError) as exc:
            raise FarsighterError(
                f"cannot join the Ray cluster at --address {address}: "
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
