"""``farsighter train --resume`` continues a run with its saved config; how train reads its flags."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from farsighter.cli import train_config
from farsighter.config import make_config, save_config
from farsighter.errors import ConfigError, RunDirError
from farsighter.train import train
from tests.interface.test_cli import run_cli

FIRST = [
    "--algo",
    "ddqn",
    "--env",
    "CartPole-v1",
    "--preset",
    "cartpole",
    "--total-steps",
    "300",
    "--learning-starts",
    "100",
    "--eval-every",
    "0",
    "--checkpoint-every",
    "100",
    "--buffer-size",
    "1000",
    "--batch-size",
    "16",  # non-default values the resume must keep
    "--lr",
    "0.002",
    "--hidden-sizes",
    "16",
    "16",
    "--torch-threads",
    "1",
    "--no-progress",
]


def one_line_error(res: subprocess.CompletedProcess[str], needle: str) -> None:
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("farsighter: error: "), res.stderr
    assert needle in lines[0], res.stderr


def test_resume_alone_continues_with_the_saved_config(tmp_path: Path) -> None:
    res = run_cli("train", "--run-dir", "run", *FIRST, cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout)["global_step"] == 300
    before = json.loads((tmp_path / "run" / "config.json").read_text())
    assert before["lr"] == 0.002 and before["batch_size"] == 16 and before["total_steps"] == 300

    res = run_cli("train", "--run-dir", "run", "--resume", "--total-steps", "600", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout)["global_step"] == 600
    after = json.loads((tmp_path / "run" / "config.json").read_text())
    assert after == {**before, "total_steps": 600}  # the new budget is recorded, nothing else

    # a flag that changes a field a resume may not change is refused, naming it
    res = run_cli("train", "--run-dir", "run", "--resume", "--lr", "0.1", cwd=tmp_path)
    one_line_error(res, "lr (saved 0.002, given 0.1)")
    res = run_cli("train", "--run-dir", "run", "--resume", "--preset", "control", cwd=tmp_path)
    one_line_error(res, "preset (saved 'cartpole', given 'control')")
    # repeating the original flags still works (the old way)
    res = run_cli(
        "train", "--run-dir", "run", *FIRST, "--total-steps", "700", "--resume", cwd=tmp_path
    )
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout)["global_step"] == 700
    assert json.loads((tmp_path / "run" / "config.json").read_text())["total_steps"] == 700

    res = run_cli("train", "--run-dir", "nowhere", "--resume", cwd=tmp_path)
    one_line_error(res, "cannot resume: nowhere holds no run (no config.json)")
    assert not (tmp_path / "nowhere").exists()


def test_resume_as_another_algo_or_env_is_refused_first(tmp_path: Path) -> None:
    res = run_cli("train", "--run-dir", "run", *FIRST, "--algo", "farsighter", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    saved = (tmp_path / "run" / "config.json").read_text()
    # the saved run holds a value ddqn refuses: the message must be about the algorithm
    assert json.loads(saved)["k_target"] == "max"
    res = run_cli("train", "--algo", "ddqn", "--resume", "--run-dir", "run", cwd=tmp_path)
    one_line_error(
        res, "cannot resume the run in run as another run: algo (saved 'farsighter', given 'ddqn')"
    )
    assert "k_target" not in res.stderr
    res = run_cli("train", "--resume", "--run-dir", "run", "--env", "Acrobot-v1", cwd=tmp_path)
    one_line_error(res, "as another run: env (saved 'CartPole-v1', given 'Acrobot-v1')")
    res = run_cli(
        "train", "--resume", "--run-dir", "run", "--algo=bdqn", "--env=Acrobot-v1", cwd=tmp_path
    )
    one_line_error(res, "algo (saved 'farsighter', given 'bdqn'); env (saved 'CartPole-v1'")
    assert (tmp_path / "run" / "config.json").read_text() == saved  # nothing recorded
    # the library's train() too, before validate and before any environment is made
    cfg = make_config("ddqn", "CartPole-v1", run_dir=str(tmp_path / "run"), resume=True)
    with pytest.raises(RunDirError, match=r"algo \(saved 'farsighter', given 'ddqn'\)"):
        train(cfg)


def test_resume_finds_the_default_run_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    run = tmp_path / "runs" / "CartPole-v1__farsighter__s2"
    run.mkdir(parents=True)
    saved = make_config("farsighter", "CartPole-v1", "cartpole", seed=2, lr=0.001, k=7)
    save_config(saved, run / "config.json")
    cfg = train_config(["--resume", "--algo", "farsighter", "--seed", "2", "--total-steps", "9"])
    assert cfg.resume and cfg.total_steps == 9
    assert cfg.lr == 0.001 and cfg.k == 7 and cfg.preset == "cartpole" and cfg.seed == 2
    assert cfg.resolved_run_dir == Path("runs/CartPole-v1__farsighter__s2")
    # given again, the preset is compared by its resolved name
    assert (
        train_config(["--resume", "--algo=farsighter", "--seed=2", "--preset", "cartpole"]).preset
        == "cartpole"
    )
    with pytest.raises(RunDirError, match=r"runs/CartPole-v1__farsighter__s3 holds no run"):
        train_config(["--resume", "--algo", "farsighter", "--seed", "3"])
    with pytest.raises(RunDirError, match=r"runs/CartPole-v1__ddqn__s1 holds no run"):
        train_config(["--resume"])


def test_algo_env_preset_choose_the_defaults() -> None:
    cfg = train_config(
        ["--algo=farsighter", "--env", "CartPole-v1", "--preset=cartpole", "--k", "3"]
    )
    assert cfg == make_config("farsighter", "CartPole-v1", "cartpole", k=3)
    assert train_config(["--algo", "farsighter", "--preset=cartpole", "--k=3"]) == cfg
    # auto is stored resolved, given or not
    assert train_config(["--preset", "auto"]).preset == "general"
    assert train_config([]).preset == "general"
    assert train_config(["--algo", "naf", "--env", "Pendulum-v1"]).preset == "continuous"
    # flags the first pass leaves alone: nested fields, negative numbers, lists, bool flags
    cfg = train_config(
        ["--blr.prior-std", "0.5", "--lr", "-1", "--hidden-sizes", "8", "8", "--no-progress"]
    )
    assert cfg.blr.prior_std == 0.5 and cfg.lr == -1 and cfg.hidden_sizes == (8, 8)
    assert not cfg.progress and cfg.algo == "ddqn"
    with pytest.raises(ConfigError, match="unknown algorithm 'nope'"):
        train_config(["--algo", "nope"])


def test_train_help_lists_every_field(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        train_config(["--algo", "bdqn", "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for flag in ("--algo", "--resume", "--total-steps", "--blr.prior-std", "--adaptive-k.k-max"):
        assert flag in out
    assert "farsighter train" in out


@pytest.mark.parametrize("args", [["--seed", "abc"], ["--no-such-flag"], ["--algo"], ["stray"]])
def test_parse_errors_exit_2_without_traceback(args: list[str]) -> None:
    res = subprocess.run(
        [sys.executable, "-m", "farsighter", "train", *args],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr


def test_a_config_saved_before_the_runtime_section_loads_its_runtime_fields() -> None:
    from farsighter.config import config_from_dict, config_to_dict, make_config

    cfg = make_config("farsighter", "CartPole-v1", device="cpu", torch_threads=3, precision="bf16")
    assert (cfg.runtime.device, cfg.runtime.torch_threads) == ("cpu", 3)  # plain names work
    flat = config_to_dict(cfg)
    runtime = flat.pop("runtime")
    flat.update(runtime)  # the layout of a run directory written before the section existed
    assert config_from_dict(flat) == cfg
    assert config_from_dict(config_to_dict(cfg)) == cfg


def test_a_resume_to_no_more_steps_than_done_changes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--resume --total-steps N`` with N at or below the steps done: one line saying so, exit
    0, and no file of the run directory written (no evaluation, summary.json as it was)."""
    from farsighter.cli import main

    run = tmp_path / "run"
    assert main(["train", "--run-dir", str(run), *FIRST]) == 0
    capsys.readouterr()

    def files() -> dict[str, tuple[bytes, int]]:
        return {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in sorted(run.iterdir())}

    before = files()
    for total in ("300", "200"):
        assert main(["train", "--run-dir", str(run), "--resume", "--total-steps", total]) == 0
        err = capsys.readouterr().err.strip().splitlines()
        assert err == [
            f"farsighter: the run in {run} has finished its 300 steps; nothing to do (give a "
            "larger --total-steps to continue it)"
        ]
        assert files() == before
    # a run stopped past the steps asked (no summary of its own): the same, nothing written
    (run / "summary.json").unlink()
    before = files()
    assert main(["train", "--run-dir", str(run), "--resume", "--total-steps", "200"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "has done 300 steps, more than --total-steps 200; nothing" in err[0]
    assert files() == before
