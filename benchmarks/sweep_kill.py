"""A sweep with a worker killed mid-run: does every trial still finish, from its checkpoint?

Runs ``farsighter sweep SPEC --ray`` (or local processes with ``--local``) in a subprocess, waits
until one trial has written its first checkpoint, kills that trial's worker with SIGKILL, waits
for the sweep to end, and records the wall time, the restarts per trial (each trial's attempts
log), whether every trial reached its budget, and the aggregate table.
    python -m benchmarks.sweep_kill [--spec benchmarks/sweeps/ray-demo.toml] [--local]
"""

from __future__ import annotations

import argparse
import csv
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

from benchmarks.common import REPO, write_result
from farsighter.sweep.run import attempts_log
from farsighter.sweep.spec import load_spec


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--spec", default=str(REPO / "benchmarks/sweeps/ray-demo.toml"))
    parser.add_argument("--out", default="/tmp/farsighter-sweep-kill")
    parser.add_argument("--local", action="store_true", help="local processes instead of Ray")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    spec = load_spec(args.spec)
    out = Path(args.out)
    shutil.rmtree(out, ignore_errors=True)
    cmd = [sys.executable, "-m", "farsighter", "sweep", args.spec, "--out", str(out)]
    cmd += ["--workers", str(args.workers), "--no-progress"]
    cmd.append("--local" if args.local else "--ray")
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=REPO)
    victim, killed_pid, killed_at = None, None, None
    while proc.poll() is None:
        if victim is None:
            for trial in spec.trials:
                run_dir = out / "trials" / trial.name
                log = attempts_log(run_dir)
                if (run_dir / "checkpoint.pt").exists() and log.exists():
                    killed_pid = int(log.read_text().split()[3])
                    os.kill(killed_pid, signal.SIGKILL)
                    victim, killed_at = trial.name, time.perf_counter() - t0
                    print(f"killed the worker of {victim} (pid {killed_pid}) at {killed_at:.0f} s")
                    break
        time.sleep(0.2)
    wall = time.perf_counter() - t0
    starts = {
        t.name: attempts_log(out / "trials" / t.name).read_text().split("\n")[:-1]
        for t in spec.trials
    }
    with open(out / "results.csv") as f:
        rows = list(csv.DictReader(f))
    budget = {t.name: t.config("").total_steps for t in spec.trials}
    write_result(
        "sweep_kill" + ("_local" if args.local else "_ray"),
        {
            "spec": os.path.relpath(args.spec, REPO),
            "backend": "local processes" if args.local else "local Ray",
            "workers": args.workers,
            "exit_code": proc.returncode,
            "wall_seconds": round(wall, 1),
            "killed_trial": victim,
            "killed_pid": killed_pid,
            "killed_at_seconds": None if killed_at is None else round(killed_at, 1),
            "restarts": {name: len(lines) - 1 for name, lines in starts.items() if len(lines) > 1},
            "victim_starts": starts.get(victim or "", []),
            "every_trial_finished": len(rows) == len(spec.trials)
            and all(int(r["steps"]) == budget[r["trial"]] for r in rows),
            "aggregate_md": (out / "aggregate" / "aggregate.md").read_text(),
            "results": rows,
        },
    )


if __name__ == "__main__":
    main()
