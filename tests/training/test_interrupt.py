"""Ctrl-C and SIGTERM during ``farsighter train`` save a checkpoint after the step in progress
and exit 130 / 143; ``--resume`` continues with no row repeated or lost (issue #64)."""

from __future__ import annotations

import csv
import re
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
import torch

import farsighter
from farsighter.errors import Interrupted
from farsighter.interrupt import requested, stop_on_signal
from farsighter.rundir import CHECKPOINT_FILE
from tests.conftest import tiny
from tests.interface.test_cli import run_cli
from tests.training.test_training import metric_rows, weights


def _default_sigint() -> None:
    """SIGINT as an interactive shell leaves it: a process started in the background (nohup,
    ``cmd &``) inherits it ignored, and a run keeps an ignored signal ignored."""
    signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.fixture(autouse=True)
def _sigint_delivered() -> Any:
    """These tests send SIGINT to this process or a child: deliver it whatever the test runner
    inherited."""
    previous = signal.getsignal(signal.SIGINT)
    _default_sigint()
    yield
    signal.signal(signal.SIGINT, previous)


LONG = [
    *("--algo", "ddqn", "--env", "CartPole-v1", "--preset", "control"),
    *("--total-steps", "1000000", "--learning-starts", "100", "--checkpoint-every", "1000000"),
    *("--eval-every", "300", "--eval-episodes", "1", "--buffer-size", "5000"),
    *("--hidden-sizes", "16", "16", "--torch-threads", "1", "--no-progress"),
]


def column(file: Path, name: str) -> list[int]:
    with file.open() as fh:
        return [int(float(row[name])) for row in csv.DictReader(fh)]


@pytest.mark.parametrize(("signum", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_saves_a_checkpoint_and_the_resume_continues_it(
    tmp_path: Path, signum: int, code: int
) -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "farsighter", "train", "--run-dir", "run", *LONG],
        preexec_fn=_default_sigint,  # the child's SIGINT as a shell's
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    run, deadline = tmp_path / "run", time.monotonic() + 120
    try:  # training (episode rows on disk) before the first periodic checkpoint
        while not (run / "metrics.csv").exists() or len(column(run / "metrics.csv", "episode")) < 2:
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "no episode rows within 120 s"
            time.sleep(0.2)
        proc.send_signal(signum)
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == code, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    name = signal.Signals(signum).name
    match = re.fullmatch(
        rf"farsighter: interrupted \({name}\) at step ([\d,]+); saved a checkpoint in run; "
        "continue the run with --resume",
        lines[0],
    )
    assert match, lines[0]
    done = int(match[1].replace(",", ""))
    saved = torch.load(run / CHECKPOINT_FILE, map_location="cpu", weights_only=False)
    assert saved["loop"]["global_step"] == done and saved["agent"]["replay"] is not None
    episodes = column(run / "metrics.csv", "episode")

    more = str(done + 400)
    res = run_cli("train", "--run-dir", "run", "--resume", "--total-steps", more, cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert (run / "summary.json").exists()
    steps = column(run / "metrics.csv", "global_step")
    assert steps == sorted(set(steps)) and steps[-1] <= done + 400  # none repeated
    after = column(run / "metrics.csv", "episode")
    assert after == list(range(1, len(after) + 1)) and len(after) > len(episodes)  # none lost
    evals = column(run / "eval.csv", "global_step")
    assert evals == sorted(set(evals)) and evals[-1] == done + 400


class SignalAt:
    """Sends this process ``signum`` at ``step`` (a Ctrl-C in the middle of the loop)."""

    def __init__(self, step: int, signum: int = signal.SIGINT) -> None:
        self.step, self.signum = step, signum

    def on_step(self, global_step: int, info: dict[str, Any], agent: Any) -> None:
        if global_step == self.step:
            signal.raise_signal(self.signum)

    def on_finish(self, run_dir: Path, agent: Any) -> None:
        pass


def test_an_interrupted_run_resumes_as_if_never_stopped(tmp_path: Path) -> None:
    """Stopped at step 700 (between the periodic checkpoints at 500 and 1,000), resumed: the
    same episode and evaluation rows and the same weights as a run never stopped."""
    full, cut = tmp_path / "full", tmp_path / "cut"
    farsighter.train(tiny("ddqn", full, total_steps=1_000, checkpoint_every=500))
    with stop_on_signal(), pytest.raises(Interrupted) as stopped:
        farsighter.train(
            tiny("ddqn", cut, total_steps=1_000, checkpoint_every=500), callbacks=[SignalAt(700)]
        )
    assert stopped.value.signum == signal.SIGINT and "at step 700;" in str(stopped.value)
    assert requested() == 0 and signal.getsignal(signal.SIGINT) is signal.default_int_handler
    saved = torch.load(cut / CHECKPOINT_FILE, map_location="cpu", weights_only=False)
    assert saved["loop"]["global_step"] == 700
    farsighter.train(tiny("ddqn", cut, total_steps=1_000, checkpoint_every=500, resume=True))
    assert metric_rows(full) == metric_rows(cut)
    assert (full / "eval.csv").read_text() == (cut / "eval.csv").read_text()
    wf, wc = weights(full), weights(cut)
    assert all(torch.equal(wf[k], wc[k]) for k in wf)


def test_an_interrupted_seed_batch_saves_every_seed(tmp_path: Path) -> None:
    """Seeds training as one batch: each seed's checkpoint is at the step of the interrupt, and
    the batch resumed ends as an uninterrupted one."""
    from farsighter.seeds import seed_configs, train_seeds

    def run(name: str, **values: Any) -> list[Any]:
        return seed_configs(tiny("ddqn", tmp_path / name, total_steps=1_000, **values), [3, 5])

    train_seeds(run("full"))
    with stop_on_signal(), pytest.raises(Interrupted) as stopped:
        train_seeds(run("cut"), callbacks=[[SignalAt(700, signal.SIGTERM)], []])
    assert stopped.value.signum == signal.SIGTERM and "at step 700;" in str(stopped.value)
    for seed in (3, 5):
        saved = torch.load(tmp_path / "cut" / f"s{seed}" / CHECKPOINT_FILE, weights_only=False)
        assert saved["loop"]["global_step"] == 700
    train_seeds(run("cut", resume=True))
    for seed in (3, 5):
        assert metric_rows(tmp_path / "full" / f"s{seed}") == metric_rows(
            tmp_path / "cut" / f"s{seed}"
        )
        wf, wc = weights(tmp_path / "full" / f"s{seed}"), weights(tmp_path / "cut" / f"s{seed}")
        assert all(torch.equal(wf[k], wc[k]) for k in wf)


def test_an_interrupt_before_the_first_step_writes_nothing(tmp_path: Path) -> None:
    with stop_on_signal(), pytest.raises(Interrupted, match="before training started"):
        signal.raise_signal(signal.SIGINT)  # as if pressed while the environments were made
        farsighter.train(tiny("ddqn", tmp_path / "run"))
    assert not (tmp_path / "run").exists()
    with stop_on_signal(), pytest.raises(Interrupted, match=r"SIGINT\) again, before"):
        signal.raise_signal(signal.SIGINT)
        signal.raise_signal(signal.SIGINT)  # a second one stops where the program is
