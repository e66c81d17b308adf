"""A run's logs: held between flushes, all on disk after a flush, scalars with the wall time
they were logged at, and everything up to a checkpoint on disk before the checkpoint is."""

from __future__ import annotations

import csv
import time
from pathlib import Path

import pytest
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from farsighter import rundir
from farsighter.rundir import METRICS_FILE, RunLogger


def _rows(file: Path) -> list[dict[str, str]]:
    with file.open() as fh:
        return list(csv.DictReader(fh))


def _scalars(path: Path, tag: str) -> list[tuple[int, float, float]]:
    events = EventAccumulator(str(path))
    events.Reload()
    if tag not in events.Tags()["scalars"]:
        return []
    return [(e.step, e.value, e.wall_time) for e in events.Scalars(tag)]


def test_logs_are_held_until_a_flush(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(rundir, "FLUSH_SECONDS", 3600.0)
    log = RunLogger(tmp_path, resume_step=None)
    before = time.time()
    for step in (10, 20, 30):
        log.metrics.write({"global_step": step, "episode": step // 10, "episodic_return": 1.5})
        log.scalar("charts/episodic_return", 1.5 * step, step)
    assert _rows(tmp_path / METRICS_FILE) == []  # the header only: nothing flushed yet
    assert _scalars(tmp_path, "charts/episodic_return") == []
    log.flush()
    assert [r["global_step"] for r in _rows(tmp_path / METRICS_FILE)] == ["10", "20", "30"]
    got = _scalars(tmp_path, "charts/episodic_return")
    assert [(s, v) for s, v, _ in got] == [(10, 15.0), (20, 30.0), (30, 45.0)]
    assert all(before - 1 <= t <= time.time() + 1 for _, _, t in got)  # when logged, not flushed
    log.scalar("charts/episodic_return", 60.0, 40)
    log.close()  # close flushes
    assert [s for s, _, _ in _scalars(tmp_path, "charts/episodic_return")] == [10, 20, 30, 40]


def test_logs_flush_on_their_own_every_few_seconds(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(rundir, "FLUSH_SECONDS", 0.0)
    log = RunLogger(tmp_path, resume_step=None)
    log.metrics.write({"global_step": 5, "episode": 1, "episodic_return": 2.0})
    log.scalar("charts/episodic_return", 2.0, 5)  # past FLUSH_SECONDS: written through
    assert [r["global_step"] for r in _rows(tmp_path / METRICS_FILE)] == ["5"]
    assert [s for s, _, _ in _scalars(tmp_path, "charts/episodic_return")] == [5]
    log.close()


def test_a_checkpoint_finds_the_logs_before_it_on_disk(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A kill right after a checkpoint leaves every episode before it in metrics.csv (a resume
    keeps those rows and never writes them again)."""
    from farsighter import make_config
    from farsighter.train import train

    monkeypatch.setattr(rundir, "FLUSH_SECONDS", 3600.0)
    seen: list[int] = []
    save_checkpoint = rundir.save_checkpoint

    def checking(path: Path, payload: dict) -> None:
        step = payload["loop"]["global_step"]
        rows = _rows(path / METRICS_FILE)
        episodes = payload["loop"]["episodes"]
        assert len(rows) == episodes and all(int(r["global_step"]) <= step for r in rows)
        seen.append(step)
        save_checkpoint(path, payload)

    monkeypatch.setattr("farsighter.session.save_checkpoint", checking)
    cfg = make_config(
        "ddqn",
        "CartPole-v1",
        total_steps=600,
        learning_starts=100,
        checkpoint_every=200,
        eval_every=0,
        eval_episodes=1,
        run_dir=str(tmp_path / "run"),
        progress=False,
        device="cpu",
    )
    train(cfg)
    assert seen == [200, 400, 600]
