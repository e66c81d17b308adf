"""Ray stays where it belongs (issue #27 item 4): a local Ray listens on loopback only, without
the dashboard, and a malformed or unreachable --address fails in seconds with one line and exit
code 2, before the sweep or study directory is touched. Every address here is 127.0.0.1."""

from __future__ import annotations

import ipaddress
import os
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from farsighter.cli import main as cli_main
from farsighter.sweep.engine import Backend, ray_init

ray = pytest.importorskip("ray", reason="the ray extra is installed by scripts/setup.sh")

SWEEP = """
name = "tiny"
[grid]
agent = ["ddqn"]
env = ["CartPole-v1"]
seed = [1]
[set]
total_steps = 300
"""


def _loopback(ip: str) -> bool:
    address = ipaddress.ip_address(ip.split("%")[0])
    if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
        address = address.ipv4_mapped  # ::ffff:127.0.0.1
    return address.is_loopback


def test_a_local_ray_listens_on_loopback_only() -> None:
    psutil = pytest.importorskip("psutil")  # Ray ships it
    if ray.is_initialized():
        ray.shutdown()
    ray_init(Backend(ray=True).address)
    try:

        @ray.remote(num_cpus=0)
        def pid() -> int:
            return os.getpid()

        worker = ray.get(pid.remote())  # a worker process is up (and listening) too
        processes = [psutil.Process(), *psutil.Process().children(recursive=True)]
        listening = []
        for proc in processes:
            try:
                sockets = proc.net_connections(kind="inet")
                name = proc.name()
            except psutil.NoSuchProcess:
                continue
            listening += [
                (name, s.laddr.ip, s.laddr.port) for s in sockets if s.status == psutil.CONN_LISTEN
            ]
    finally:
        ray.shutdown()
    assert worker in {p.pid for p in processes}
    # the GCS and the raylet were seen listening: the check below is not vacuous
    assert {"gcs_server", "raylet"} <= {name for name, _, _ in listening}, listening
    outside = [entry for entry in listening if not _loopback(entry[1])]
    assert not outside, f"Ray listens beyond loopback: {outside}"
    assert 8265 not in {port for _, _, port in listening}  # no dashboard


def _free_port() -> int:
    """A loopback port that nothing listens on (bound, then closed)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture
def silent_port() -> Iterator[int]:
    """A loopback port that accepts connections and never answers (open, but not Ray)."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(64)
    held: list[socket.socket] = []

    def accept() -> None:
        while True:
            try:
                held.append(server.accept()[0])
            except OSError:
                return

    thread = threading.Thread(target=accept, daemon=True)
    thread.start()
    yield int(server.getsockname()[1])
    server.close()
    for conn in held:
        conn.close()


def _cli(*args: str, cwd: Path) -> tuple[subprocess.CompletedProcess[str], float]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")}
    # Ray maps a 127.0.0.1 address to this machine's network address unless this is off: keep
    # every connection it makes on loopback (and a regression here hangs on loopback too)
    env["RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"] = "0"
    t0 = time.perf_counter()
    res = subprocess.run(
        [sys.executable, "-m", "farsighter", *args],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    return res, time.perf_counter() - t0


def _one_line(res: subprocess.CompletedProcess[str], *needles: str) -> str:
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("farsighter: error: "), res.stderr
    for needle in needles:
        assert needle in lines[0], res.stderr
    return lines[0]


@pytest.mark.parametrize(
    "command",
    [["sweep", "sweep.toml"], ["maze", "--quick"]],
    ids=["sweep", "study"],
)
@pytest.mark.parametrize("scheme", ["", "ray://"], ids=["gcs", "client"])
def test_nothing_listening_at_address_fails_in_seconds(
    tmp_path: Path, command: list[str], scheme: str
) -> None:
    (tmp_path / "sweep.toml").write_text(SWEEP)
    port = _free_port()
    address = f"{scheme}127.0.0.1:{port}"
    res, wall = _cli(*command, "--ray", "--address", address, "--out", "out", cwd=tmp_path)
    _one_line(
        res,
        f"--address {address}",
        f"tried a TCP connection to 127.0.0.1:{port}",
        "connection refused",
    )
    assert wall < 30
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("scheme", ["", "ray://"], ids=["gcs", "client"])
def test_an_address_that_is_not_ray_fails_within_30_s(
    tmp_path: Path, silent_port: int, scheme: str
) -> None:
    (tmp_path / "sweep.toml").write_text(SWEEP)
    address = f"{scheme}127.0.0.1:{silent_port}"
    res, wall = _cli("sweep", "sweep.toml", "--address", address, "--out", "out", cwd=tmp_path)
    _one_line(
        res,
        f"--address {address}",
        f"127.0.0.1:{silent_port} accepts TCP connections but joining failed",
        "Ray's last message: ",
    )
    assert wall < 30, f"took {wall:.0f} s"
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    "address",
    ["127.0.0.1", "127.0.0.1:0", "127.0.0.1:70000", "http://127.0.0.1:6379", "auto", ""],
)
@pytest.mark.parametrize("dry_run", [False, True], ids=["run", "dry-run"])
def test_a_malformed_address_is_one_line_naming_the_forms(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], address: str, dry_run: bool
) -> None:
    (tmp_path / "sweep.toml").write_text(SWEEP)
    out = tmp_path / "out"
    args = ["sweep", str(tmp_path / "sweep.toml"), "--address", address, "--out", str(out)]
    assert cli_main(args + ["--dry-run"] * dry_run) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("farsighter: error:") and "\n" not in err
    assert f"--address {address!r} is not HOST:PORT" in err and "ray://HOST:PORT" in err
    assert not out.exists()


def test_a_study_checks_the_address_form_too(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli_main(["maze", "--quick", "--ray", "--address", "127.0.0.1"]) == 2
    assert "--address '127.0.0.1' is not HOST:PORT" in capsys.readouterr().err


def test_a_failed_join_names_rays_last_message_and_the_token_when_asked_for() -> None:
    from farsighter.sweep.engine import _join_hint, _last_message

    said = [
        "2026-12-01 18:36:08,551\tINFO worker.py:1841 -- Connecting to existing Ray cluster...",
        "[2026-12-01 18:46:49,122 W 19815 19815] gcs_client.cc:210: Failed to get cluster ID "
        "from GCS server: Unauthenticated: RPC error: InvalidAuthToken: Authentication token is "
        "missing or incorrect",
        "",
    ]
    assert _last_message(said) == (
        "; Ray's last message: gcs_client.cc:210: Failed to get cluster ID from GCS server: "
        "Unauthenticated: RPC error: InvalidAuthToken: Authentication token is missing or "
        "incorrect"
    )
    assert "RAY_AUTH_MODE=token" in _join_hint(said)
    warning = [
        "/x/ray/util/client/worker.py:335: UserWarning: Ray Client connection timed out.",
        "  warnings.warn(",
    ]
    assert (
        _last_message(warning)
        == "; Ray's last message: UserWarning: Ray Client connection timed out."
    )
    assert "ray://HOST:10001" in _join_hint(warning) and _last_message([]) == ""
