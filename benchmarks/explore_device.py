"""The exploration suite's runs on another device: do the defaults learn on a GPU as on a CPU?

``farsighter explore`` runs every run on one CPU thread (many small runs, one per core). A user
with a GPU who trains with the defaults (``farsighter train``, ``runtime.device auto``) runs on
CUDA instead: other arithmetic (cuBLAS sums in another order, CUDA graphs of the update where
the agent allows them), so other trajectories. This runs a study of ``farsighter explore`` with
every run's ``runtime.device`` set to ``--device`` (the study's configs otherwise unchanged)
and writes each run's verdicts (greedy solved and held, bsuite's criterion, the first reward)
as JSON, so that a CPU study and a GPU study of the same tasks and seeds can be set side by side:

    python -m benchmarks.explore_device --device cuda --json OUT.json -- \\
        --families deepsea --sizes 10 14 --agents Farsighter --workers 4 --seeds-per-batch 1 \\
        --out DIR --no-progress

Everything after ``--`` is ``farsighter explore``'s own flags. The verdicts are counted by the
suite's own measures (``explore.per_run``). Runs are spread over worker processes that each use
the device, so on a GPU they share it (one CUDA context each).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any

DEVICE_VAR = "FARSIGHTER_EXPLORE_DEVICE"


def _run_config(agent: Any, study: Any, seed: int, run_dir: Path, task: Any) -> Any:
    """The study's own config of a run with ``runtime.device`` from :data:`DEVICE_VAR` (a
    module-level function: it is pickled to the study's worker processes, which inherit the
    variable)."""
    from farsighter.studies import explore

    cfg = explore.run_config(agent, study, seed, run_dir, task)
    runtime = dataclasses.replace(cfg.runtime, device=os.environ[DEVICE_VAR])
    return dataclasses.replace(cfg, runtime=runtime)


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", required=True, help="cpu, cuda or cuda:N")
    parser.add_argument("--json", required=True, help="where the runs' verdicts go")
    parser.add_argument("explore", nargs=argparse.REMAINDER, help="-- farsighter explore's flags")
    args = parser.parse_args(argv)
    flags = args.explore[1:] if args.explore[:1] == ["--"] else args.explore
    if "--out" not in flags:
        parser.error("give the study directory (--out DIR) among explore's flags")
    import torch

    from farsighter.studies import explore, runner

    if args.device.startswith("cuda") and not torch.cuda.is_available():
        parser.error(f"--device {args.device}: torch sees no CUDA device")
    os.environ[DEVICE_VAR] = args.device
    study = dataclasses.replace(explore.STUDY, run_config=_run_config)
    t0 = time.perf_counter()
    code = runner.main(study, flags)
    wall = time.perf_counter() - t0
    out = Path(flags[flags.index("--out") + 1])
    _, runs = runner.load_runs(study, out)
    rows = explore.per_run(runs)
    result = {
        "device": args.device,
        "device_name": torch.cuda.get_device_name(0) if args.device.startswith("cuda") else None,
        "cpu": platform.processor() or platform.machine(),
        "torch": torch.__version__,
        "explore_flags": flags,
        "wall_seconds": round(wall, 1),
        "runs": [{k: v for k, v in r.items() if k != "env"} for r in rows],
    }
    Path(args.json).write_text(json.dumps(result, indent=1, default=float) + "\n")
    for r in rows:
        print(
            f"{args.device} {r['family']} {r['size']} seed {r['seed']}: solved {r['solved']} "
            f"held {r['held']} bsuite {r['bsuite_solved']} first reward "
            f"{r['episodes_to_first_reward']}"
        )
    return code


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
