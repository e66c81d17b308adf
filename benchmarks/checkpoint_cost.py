"""What a checkpoint costs a small run: bytes on disk and seconds to write, with its replay.

A small task's replay is allocated for the whole run (the general preset: 100k transitions), but a
checkpoint before the buffer fills holds only the slots written so far
(:meth:`farsighter.replay.ReplayBuffer.streams_state`). Each task trains one short run with the
library's defaults (checkpoints every ``--every`` steps, the last one at the end), timing every
checkpoint the run writes; then, side by side in the same process, writes the run's replay once
in the layout of earlier versions (every slot of the preallocated arrays) and once as it is saved
now, and times both.

    python -m benchmarks.checkpoint_cost [--tasks deepsea cartpole] [--steps 10000] [--every 2500]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path
from typing import Any

import torch

from benchmarks.common import write_result

TASKS = {"deepsea": "farsighter/DeepSea20-v0", "cartpole": "CartPole-v1"}


def _timed_write(state: Any, path: Path) -> tuple[float, int]:
    """Seconds to ``torch.save`` the state, and the file's bytes."""
    start = time.perf_counter()
    torch.save(state, path)
    return time.perf_counter() - start, path.stat().st_size


def measure(task: str, steps: int, every: int, algo: str) -> dict[str, Any]:
    import farsighter.session as session
    from farsighter import make_config, train
    from farsighter.replay.buffer import SLOT_ARRAYS

    saves: list[float] = []
    agents: list[Any] = []
    save_run = session.save_run

    def timed(path: Path, cfg: Any, state: Any, agent: Any, envs: Any, obs: Any) -> None:
        start = time.perf_counter()
        save_run(path, cfg, state, agent, envs, obs)
        saves.append(time.perf_counter() - start)
        agents[:] = [agent]

    session.save_run = timed  # type: ignore[assignment]
    try:
        with tempfile.TemporaryDirectory() as tmp:
            cfg = make_config(
                algo,
                TASKS[task],
                total_steps=steps,
                checkpoint_every=every,
                eval_every=0,
                eval_episodes=1,
                progress=False,
                device="cpu",
                torch_threads=1,
                run_dir=f"{tmp}/run",
            )
            start = time.perf_counter()
            train(cfg)
            wall = time.perf_counter() - start
            checkpoint_bytes = (Path(tmp) / "run" / "checkpoint.pt").stat().st_size
            replay = agents[0].replay
            cut = replay.state_dict()
            full = {**cut, **{key: getattr(replay, key) for key in SLOT_ARRAYS}}
            cut_s, cut_bytes = _timed_write(cut, Path(tmp) / "cut.pt")
            full_s, full_bytes = _timed_write(full, Path(tmp) / "full.pt")
    finally:
        session.save_run = save_run  # type: ignore[assignment]
    return {
        "task": task,
        "env": TASKS[task],
        "algo": algo,
        "steps": steps,
        "replay_capacity": int(replay.capacity * replay.num_envs),
        "run_wall_s": round(wall, 2),
        "checkpoints": len(saves),
        "checkpoint_s": [round(s, 3) for s in saves],
        "checkpoint_share_of_run": round(sum(saves) / wall, 4),
        "final_checkpoint_mb": round(checkpoint_bytes / 2**20, 2),
        "replay_as_saved": {"mb": round(cut_bytes / 2**20, 2), "write_s": round(cut_s, 3)},
        "replay_every_slot": {"mb": round(full_bytes / 2**20, 2), "write_s": round(full_s, 3)},
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--tasks", nargs="+", choices=tuple(TASKS), default=["deepsea", "cartpole"])
    p.add_argument("--algo", default="farsighter")
    p.add_argument("--steps", type=int, default=10_000)
    p.add_argument("--every", type=int, default=2_500, help="steps between checkpoints")
    p.add_argument("--name", default="checkpoint_cost")
    args = p.parse_args()
    torch.set_num_threads(1)
    runs = [measure(task, args.steps, args.every, args.algo) for task in args.tasks]
    write_result(args.name, {"runs": runs})


if __name__ == "__main__":
    main()
