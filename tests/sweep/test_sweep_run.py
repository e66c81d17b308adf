"""farsighter sweep: trials run, finished ones are skipped, a killed worker resumes from its
checkpoint (local processes and local Ray), and bad input is one line with exit code 2."""

from __future__ import annotations

import csv
import json
import os
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from farsighter.cli import main as cli_main
from farsighter.stats import fmt
from farsighter.sweep import engine
from farsighter.sweep.engine import Backend
from farsighter.sweep.run import attempts, attempts_log, run_sweep
from farsighter.sweep.spec import load_spec

TINY = """
name = "tiny"
[grid]
agent = {agents}
env = ["CartPole-v1"]
seed = {seeds}
[set]
total_steps = {steps}
learning_starts = 200
eval_every = {eval_every}
eval_episodes = 1
eval_max_steps = 100
checkpoint_every = 500
buffer_size = 5000
hidden_sizes = [16]
"blr.posterior_every" = 200
[resources]
retries = 2
"""


def _spec(tmp_path: Path, agents: str, seeds: str, steps: int, eval_every: int = 500) -> Path:
    file = tmp_path / "sweep.toml"
    file.write_text(TINY.format(agents=agents, seeds=seeds, steps=steps, eval_every=eval_every))
    return file


def test_sweep_runs_every_trial_then_skips_finished_ones(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    spec = load_spec(_spec(tmp_path, '["ddqn", "farsighter"]', "[1, 2]", 600))
    out = tmp_path / "out"
    run_sweep(spec, out, Backend(workers=1), show_progress=False)
    with open(out / "results.csv") as f:
        rows = list(csv.DictReader(f))
    assert sorted((r["agent"], r["seed"]) for r in rows) == [
        ("ddqn", "1"),
        ("ddqn", "2"),
        ("farsighter", "1"),
        ("farsighter", "2"),
    ]
    assert all(int(r["steps"]) == 600 and r["attempts"] == "1" for r in rows)
    for name in ("aggregate/aggregate.csv", "aggregate/aggregate.md", "report.md"):
        assert (out / name).stat().st_size > 0
    assert (out / "figures" / "curves.png").stat().st_size > 1000
    report = (out / "report.md").read_text()
    for agent in ("ddqn", "farsighter"):  # the table states results.csv's returns, 3 digits
        returns = np.array([float(r["final_eval_return"]) for r in rows if r["agent"] == agent])
        cell = f"{fmt(float(returns.mean()))} ± {fmt(float(returns.std(ddof=1)))}"
        assert f"| {agent} | CartPole-v1 | 2 | {cell} |" in report

    def no_run(*args: object, **kwargs: object) -> None:
        raise AssertionError("a finished trial was run again")

    monkeypatch.setattr("farsighter.sweep.run.execute", no_run)
    run_sweep(spec, out, Backend(workers=1), show_progress=False)  # everything finished
    assert all(attempts(out / "trials" / t.name) == 1 for t in spec.trials)


def test_a_directory_of_another_sweep_is_refused(tmp_path: Path) -> None:
    out = tmp_path / "out"
    run_sweep(load_spec(_spec(tmp_path, '["ddqn"]', "[1]", 300)), out, Backend(workers=1), False)
    other = load_spec(_spec(tmp_path, '["ddqn"]', "[1, 2]", 300))
    with pytest.raises(engine.FarsighterError, match="holds another sweep"):
        run_sweep(other, out, Backend(workers=1), show_progress=False)


def _kill_after_first_checkpoint(run_dir: Path, killed: list[int]) -> None:
    """Kill the trial's worker (SIGKILL) once its first checkpoint is on disk."""
    log = attempts_log(run_dir)
    deadline = time.time() + 120
    while time.time() < deadline:
        if (run_dir / "checkpoint.pt").exists() and log.exists():
            pid = int(log.read_text().split()[3])
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)
            return
        time.sleep(0.05)


@pytest.mark.parametrize("use_ray", [False, True], ids=["processes", "ray"])
def test_a_killed_worker_is_restarted_from_its_checkpoint(tmp_path: Path, use_ray: bool) -> None:
    if use_ray:
        pytest.importorskip("ray", reason="the ray extra is installed by scripts/setup.sh")
    spec = load_spec(_spec(tmp_path, '["ddqn"]', "[1]", 3_000, eval_every=1_500))
    out = tmp_path / "out"
    run_dir = out / "trials" / spec.trials[0].name
    killed: list[int] = []
    watcher = threading.Thread(target=_kill_after_first_checkpoint, args=(run_dir, killed))
    watcher.start()
    try:
        backend = Backend(workers=1 if use_ray else 2, retries=2, ray=use_ray)
        run_sweep(spec, out, backend, show_progress=False)
    finally:
        watcher.join()
        if use_ray:
            import ray

            ray.shutdown()
    assert len(killed) == 1
    lines = attempts_log(run_dir).read_text().splitlines()
    assert [line.split()[-1] for line in lines] == ["fresh", "resume"]
    assert int(lines[1].split()[3]) != killed[0]
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["global_step"] == 3_000
    with open(run_dir / "eval.csv") as f:  # evaluations before the kill are kept, none twice
        steps = [int(r["global_step"]) for r in csv.DictReader(f)]
    assert steps == [1_500, 3_000]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            'name = "x"\n[grid]\nagent = ["ddqn"]\nenv = ["CartPole-v1"]\nseed = [1]\nfoo = [1]\n',
            "unknown config field",
        ),
        (
            'name = "x"\n[grid]\nagent = ["dqnn"]\nenv = ["CartPole-v1"]\nseed = [1]\n',
            "unknown agent",
        ),
        ('name = "x"\n[grid]\nagent = ["ddqn"]\nenv = ["CartPole-v1"]\nseed = []\n', "empty"),
        ('name = "x"\n[grid\n', "sweep.toml"),
    ],
)
def test_bad_sweep_files_are_one_line_and_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, message: str
) -> None:
    file = tmp_path / "sweep.toml"
    file.write_text(text)
    assert cli_main(["sweep", str(file), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("farsighter: error:") and message in err and "\n" not in err
    assert not (tmp_path / "o").exists()


SWEEPS = sorted((Path(__file__).resolve().parents[2] / "benchmarks" / "sweeps").glob("*.toml"))


@pytest.mark.parametrize("file", SWEEPS, ids=[f.stem for f in SWEEPS])
def test_the_shipped_sweep_files_expand_into_valid_trials(file: Path) -> None:
    spec = load_spec(file)  # every trial's config is built and validated
    assert spec.trials and spec.description


def test_a_study_refuses_address_without_ray(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli_main(["maze", "--quick", "--address", "localhost:6379"]) == 2
    assert "--address joins a Ray cluster and needs --ray" in capsys.readouterr().err


def test_atari_sweeps_are_human_normalised() -> None:
    from farsighter.sweep.run import normalization, score_table

    assert normalization(["ALE/Breakout-v5", "ALE/Pong-v5"]) == "human"
    assert normalization(["CartPole-v1"]) == "raw"
    assert normalization(["CartPole-v1", "ALE/Pong-v5"]) == "minmax"
    # Breakout's random and human scores are 1.7 and 30.5
    rows = [
        {"variant": "a", "env": "ALE/Breakout-v5", "seed": s, "final_eval_return": r}
        for s, r in ((1, 1.7), (2, 30.5))
    ]
    table, envs = score_table(rows, "human")
    assert envs == ["ALE/Breakout-v5"]
    assert table["a"][:, 0].tolist() == pytest.approx([0.0, 1.0])


def test_the_progress_bar_counts_a_job_that_reported_done_while_it_exits() -> None:
    from types import SimpleNamespace

    from farsighter.sweep.engine import _show

    bar = SimpleNamespace(n=0, refresh=lambda: None)
    jobs = [("a",), ("b",), ("c",)]
    # a: finished and reaped (in done); b: reported done, its process still ending; c: running
    _show(bar, 600, {"a": -1, "b": -1, "c": 250}, [(jobs[1], 600), (jobs[2], 600)])
    assert bar.n == 600 + 600 + 250
    _show(bar, 600, {}, [(jobs[1], 600)])  # nothing reported yet
    assert bar.n == 600


def test_seeds_sharing_a_process_train_as_they_do_alone(tmp_path: Path) -> None:
    """``resources.seeds_per_process = 2``: the ddqn trials of seeds 1-3 run as a batch of two and
    one alone, farsighter's in turn in one process; every trial's results equal those of the sweep
    run trial by trial (ddqn's batched seeds bit for bit), and each keeps its attempts log."""
    import torch

    plain = load_spec(_spec(tmp_path, '["ddqn", "farsighter"]', "[1, 2, 3]", 600))
    file = _spec(tmp_path, '["ddqn", "farsighter"]', "[1, 2, 3]", 600)
    file.write_text(file.read_text() + "seeds_per_process = 2\n")
    shared = load_spec(file)
    assert shared.resources.seeds_per_process == 2
    run_sweep(plain, tmp_path / "plain", Backend(workers=1), show_progress=False)
    run_sweep(shared, tmp_path / "shared", Backend(workers=1), show_progress=False)
    for trial in plain.trials:
        a = torch.load(tmp_path / "plain" / "trials" / trial.name / "policy.pt", weights_only=False)
        b = torch.load(
            tmp_path / "shared" / "trials" / trial.name / "policy.pt", weights_only=False
        )
        assert _tensors(a).keys() == _tensors(b).keys()
        assert all(torch.equal(t, _tensors(b)[k]) for k, t in _tensors(a).items()), trial.name
        assert attempts(tmp_path / "shared" / "trials" / trial.name) == 1
    with open(tmp_path / "shared" / "results.csv") as f:
        assert len(list(csv.DictReader(f))) == 6


@pytest.mark.parametrize("value", ["0", "1.5", "true"])
def test_seeds_per_process_must_be_a_whole_number_from_1(tmp_path: Path, value: str) -> None:
    file = _spec(tmp_path, '["ddqn"]', "[1]", 300)
    file.write_text(file.read_text() + f"seeds_per_process = {value}\n")
    with pytest.raises(engine.FarsighterError, match="seeds_per_process must be an integer >= 1"):
        load_spec(file)


def _tensors(state: object, prefix: str = "") -> dict[str, object]:
    """Every tensor in a nested state, by its path."""
    import torch

    if isinstance(state, torch.Tensor):
        return {prefix: state}
    if isinstance(state, dict):
        out: dict[str, object] = {}
        for key, value in state.items():
            out.update(_tensors(value, f"{prefix}/{key}"))
        return out
    return {}
