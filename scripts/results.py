"""Regenerate the published study results under docs/results/ from the current code.

    python scripts/results.py --list              # what it makes, and what each took last
    python scripts/results.py                     # all of them (about 3 hours on 2 cores)
    python scripts/results.py --only maze k-study # some of them

Each study runs into ``results-build/<folder>`` (resumable: an interrupted call continues
where it stopped, so the long ones can be run in parts), then its outputs (report, tables,
figures, study.json with the commit that made it, and the small files of its runs: no
checkpoints, policies, replays or TensorBoard files) replace ``docs/results/<folder>``. The wall
time of each study (summed over the calls that ran parts of it) is written to
``docs/results/walltimes.json``, and the table of docs/results/README.md is rewritten from this
list and those times.
"""

from __future__ import annotations

import argparse
import json
import shlex
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "docs" / "results"
BUILD = ROOT / "results-build"
TIMES = RESULTS / "walltimes.json"
KEEP = (".csv", ".json", ".md", ".png", ".npy")  # a study's outputs and its runs' small files
SKIP_DIRS = {"checkpoints", "tb", "tensorboard"}
MAX_FILE = 2 << 20  # bytes: a larger file is not published


@dataclass(frozen=True)
class Entry:
    folder: str
    args: str  # the command after `farsighter`, without --out (split as a shell would)
    note: str
    earlier: int  # seconds it took when made by hand at an earlier commit (docs/results/README)


ENTRIES = (
    Entry(
        "maze",
        "maze --agents all --workers 2",
        "9 agents x 5 seeds x 40k steps on the bridge maze (paper section 5.1); "
        "`farsighter maze --plot-only docs/results/maze` redraws it",
        972,
    ),
    Entry(
        "k-study",
        "k-study --workers 2",
        "Farsighter at k = 1, 10, 50, 150, 500 and adaptive k on the bridge maze, 5 seeds x 40k "
        "steps (Figure 4)",
        408,
    ),
    Entry(
        "minatar",
        "atari --games minatar --agents DDQN BDQN Farsighter --seeds 1 2 --steps 50000 "
        "--eval-every 10000 --eval-episodes 10",
        "3 agents x 5 MinAtar games x 2 seeds x 50k steps",
        3415,
    ),
    Entry(
        "atari100k",
        "atari --games Boxing Freeway --agents Farsighter --seeds 1 --steps 100000 "
        "--preset atari100k --eval-every 25000 --eval-episodes 5",
        "Atari-100k, 2 games, 1 seed",
        2796,
    ),
    Entry(
        "walker2d",
        "robotics --env Walker2d-v5 --steps 30000 --seeds 1 2 3 --workers 2",
        "the four continuous agents on Walker2d-v5 at a small budget",
        583,
    ),
    Entry(
        "fetchpickandplace",
        "robotics --env FetchPickAndPlace-v4 --seeds 1 2 --steps 15000 --eval-every 1500 "
        "--eval-episodes 10",
        "goal task with HER, a tiny fraction of the paper's budget",
        253,
    ),
    Entry(
        "handmanipulateblock",
        "robotics --env HandManipulateBlock-v1 --seeds 1 2 --steps 5000 --eval-every 1000 "
        "--eval-episodes 5",
        "goal task with HER, a tiny fraction of the paper's budget",
        122,
    ),
)


def publish(build: Path, dest: Path) -> None:
    """Replace ``dest`` with ``build``'s outputs and its runs' small files."""
    if dest.exists():
        shutil.rmtree(dest)
    for file in sorted(build.rglob("*")):
        rel = file.relative_to(build)
        if not file.is_file() or SKIP_DIRS & set(rel.parts) or file.suffix not in KEEP:
            continue
        if file.stat().st_size > MAX_FILE:
            continue
        (dest / rel).parent.mkdir(parents=True, exist_ok=True)
        if file.suffix in (".md", ".json", ".csv"):  # paths as where the files now live
            with open(file, newline="") as f:  # line endings as written (csv's are CRLF)
                text = f.read().replace(str(build), dest.relative_to(ROOT).as_posix())
            with open(dest / rel, "w", newline="") as f:
                f.write(text)
        else:
            shutil.copy2(file, dest / rel)


def readme_table(times: dict[str, float]) -> str:
    rows = ["| folder | command | wall time |", "|---|---|---|"]
    for e in ENTRIES:
        command = f"farsighter {e.args}"
        took = (
            f"{times[e.folder]:.0f} s"
            if e.folder in times
            else f"not rerun yet ({e.earlier} s at the commit that added it)"
        )
        rows.append(f"| `{e.folder}/` | `{command}` ({e.note}) | {took} |")
    return "\n".join(rows)


def write_readme(times: dict[str, float]) -> None:
    readme = RESULTS / "README.md"
    text = readme.read_text()
    start, end = "<!-- results table -->", "<!-- end of the results table -->"
    head, rest = text.split(start, 1)
    _, tail = rest.split(end, 1)
    readme.write_text(f"{head}{start}\n{readme_table(times)}\n{end}{tail}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="*", default=None, help="folders (default: all)")
    parser.add_argument("--list", action="store_true", help="print the studies and stop")
    args = parser.parse_args()
    times = json.loads(TIMES.read_text()) if TIMES.exists() else {}
    folders = [e.folder for e in ENTRIES]
    unknown = sorted(set(args.only or ()) - set(folders))
    if unknown:
        print(f"unknown folder(s) {', '.join(unknown)}; accepted: {', '.join(folders)}")
        return 2
    if args.list:
        print(readme_table(times))
        return 0
    for e in ENTRIES:
        if args.only is not None and e.folder not in args.only:
            continue
        build = BUILD / e.folder
        cmd = [sys.executable, "-m", "farsighter", *shlex.split(e.args), "--out", str(build)]
        print(f"$ farsighter {e.args} --out {build}", flush=True)
        spent = build / "wall_seconds.txt"  # over every call that ran part of it
        before = float(spent.read_text()) if spent.exists() else 0.0
        start = time.perf_counter()
        subprocess.run(cmd, check=True, cwd=ROOT)
        times[e.folder] = round(before + time.perf_counter() - start, 1)
        spent.write_text(f"{times[e.folder]}\n")
        publish(build, RESULTS / e.folder)
        TIMES.write_text(json.dumps(times, indent=2) + "\n")
        write_readme(times)
    return 0


if __name__ == "__main__":
    sys.exit(main())
