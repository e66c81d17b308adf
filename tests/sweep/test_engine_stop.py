"""The local engine's workers end with the study that started them: a SIGTERM to the study stops
them through its clean-up, and after a SIGKILL (no clean-up) each worker, and the manager process
that carries their progress, notices that its parent is gone and exits."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]

STUDY = """
import os, sys, time
from pathlib import Path
from farsighter.sweep.engine import Backend, execute

def job(folder, name, progress):
    Path(folder, name).write_text(str(os.getpid()))
    time.sleep(120)  # a long run

if __name__ == "__main__":
    jobs = [(sys.argv[1], "a"), (sys.argv[1], "b")]
    backend = Backend(workers=2, retries=0)
    execute(job, jobs, steps=[1, 1], backend=backend, desc="stop", show_progress=False)
"""


def _stat(pid: int) -> list[str] | None:
    """The fields of /proc/PID/stat after the command's name (state, ppid, ...), or None."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return text[text.rindex(")") + 2 :].split()


def _alive(pid: int) -> bool:
    fields = _stat(pid)
    return fields is not None and fields[0] != "Z"  # a zombie has ended


def _children(pid: int) -> set[int]:
    out = set()
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            fields = _stat(int(entry.name))
            if fields is not None and int(fields[1]) == pid and fields[0] != "Z":
                out.add(int(entry.name))
    return out


def _wait(condition: object, seconds: float) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if condition():  # type: ignore[operator]
            return True
        time.sleep(0.1)
    return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads processes from /proc")
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_workers_and_their_manager_end_with_a_stopped_study(
    tmp_path: Path, sig: signal.Signals
) -> None:
    script = tmp_path / "study.py"
    script.write_text(STUDY)
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    study = subprocess.Popen([sys.executable, str(script), str(tmp_path)], cwd=REPO, env=env)
    children: set[int] = set()
    try:
        started = _wait(lambda: all((tmp_path / n).exists() for n in "ab"), 90)
        assert started, "the workers did not start"
        time.sleep(0.2)  # the pid files are written; their contents too
        workers = {int((tmp_path / n).read_text()) for n in "ab"}
        children = _children(study.pid)
        assert workers < children  # the workers and the manager process (at least)
        os.kill(study.pid, sig)
        code = study.wait(30)
        # SIGTERM: the study's clean-up ran and it exited with 128 + 15; SIGKILL: killed
        assert code == (-signal.SIGKILL if sig == signal.SIGKILL else 128 + signal.SIGTERM)
        assert _wait(lambda: not any(_alive(p) for p in children), 20), [
            p for p in children if _alive(p)
        ]
    finally:
        study.kill()
        for pid in children:
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)
