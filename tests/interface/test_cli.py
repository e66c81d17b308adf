"""The command line: a tiny run end to end, and one clear line + exit 2 for bad input."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import pytest

TINY = [
    "--total-steps",
    "400",
    "--learning-starts",
    "100",
    "--eval-every",
    "200",
    "--eval-episodes",
    "1",
    "--no-progress",
    "--hidden-sizes",
    "16",
    "16",
]


def run_cli(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "farsighter", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_train_eval_and_presets(tmp_path: Path) -> None:
    res = run_cli(
        "train",
        "--algo",
        "farsighter",
        "--env",
        "CartPole-v1",
        "--preset",
        "cartpole",
        "--k",
        "5",
        "--blr.prior-std",
        "0.5",
        "--run-dir",
        "run",
        *TINY,
        cwd=tmp_path,
    )
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout)
    assert summary["global_step"] == 400
    saved = json.loads((tmp_path / "run" / "config.json").read_text())
    assert saved["k"] == 5 and saved["blr"]["prior_std"] == 0.5 and saved["preset"] == "cartpole"
    assert saved["optimizer"] == "adam"  # from the preset, not overridden
    res = run_cli("eval", "run", "--episodes", "2", "--seed", "7", "--device", "cpu", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert len(json.loads(res.stdout)["returns"]) == 2
    res = run_cli("eval", "run", "--episodes", "0", cwd=tmp_path)
    assert res.returncode == 2 and res.stderr.strip() == (
        "farsighter: error: --episodes must be >= 1 (got 0)"
    )
    res = run_cli("plot", "run", "--out", "curve.png", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "curve.png").stat().st_size > 0
    res = run_cli("presets", cwd=tmp_path)
    assert "Table 1" in res.stdout and "kazizzad/BDQN-MxNet-Gluon" in res.stdout


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--algo", "dqn-x"], "unknown algorithm 'dqn-x'; accepted: ddqn"),
        (["--env", "NoSuchEnv-v0"], "cannot make environment 'NoSuchEnv-v0'"),
        (["--env", "nosuchmodule:Foo-v0"], "cannot make environment"),
        (["--k", "0"], "k must be an integer >= 1"),
        (["--lr", "-1"], "lr must be > 0"),
        (["--buffer-size", "0"], "buffer_size must be > 0"),
        (["--batch-size", "64", "--buffer-size", "32"], "must not exceed buffer_size"),
        (["--env", "Pendulum-v1"], "needs a discrete action space"),
        (["--preset", "nope"], "unknown preset 'nope'; accepted: auto"),
        # integer fields the loop divides by or counts down to: refused, not a ZeroDivisionError
        (["--num-envs", "0"], "num_envs must be >= 1 (got 0)"),
        (["--num-envs", "-2"], "num_envs must be >= 1 (got -2)"),
        (["--total-steps", "0"], "total_steps must be > 0 (got 0)"),
        (["--batch-size", "0"], "batch_size must be > 0 (got 0)"),
        (["--buffer-size", "-5"], "buffer_size must be > 0 (got -5)"),
        (["--train-every", "0"], "train_every must be >= 1 (got 0)"),
        (["--target-update-every", "0"], "target_update_every must be >= 1 (got 0)"),
        (["--eval-episodes", "0"], "eval_episodes must be >= 1"),
        (["--eval-every", "-1"], "eval_every must be >= 0 (0: no periodic evaluation; got -1)"),
        (["--eval-max-steps", "0"], "eval_max_steps must be >= 1 (got 0)"),
        (["--log-every", "0"], "log_every must be >= 1 (got 0)"),
        (["--max-episode-steps", "-1"], "max_episode_steps must be >= 0"),
        (["--env-kwargs", "slippery"], "env_kwargs takes NAME=VALUE items"),
        (["--env-kwargs", "render_mode=human"], "env_kwargs cannot set render_mode"),
        (
            ["--env", "FrozenLake-v1", "--env-kwargs", "map_name=9x9"],
            "cannot make environment 'FrozenLake-v1' with map_name=9x9: no entry '9x9'",
        ),
        (
            ["--env", "ALE/Pong-v5", "--max-episode-steps", "100"],
            "max_episode_steps is for non-ALE",
        ),
    ],
)
def test_bad_input_is_one_line_exit_2(tmp_path: Path, args: list[str], needle: str) -> None:
    res = run_cli(
        "train", "--run-dir", "run", "--total-steps", "10", "--no-progress", *args, cwd=tmp_path
    )
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], res.stderr
    assert "Traceback" not in res.stderr
    assert not (tmp_path / "run").exists()  # nothing created


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (
            ["train", "--totl-steps", "5"],
            "Unrecognized options: --totl-steps, 5; did you mean --total-steps?",
        ),
        (["train", "--optimizer", "sgd"], "Expected one of ('rmsprop', 'adam')"),
        (["train", "--seed", "1.5"], "'1.5' is not an integer (expected --seed INT)"),
        (["train", "--algo", "ddqn", "--lr"], "Missing value for argument '--lr'"),
        (["train", "--seeds", "1", "2", "--num-envs", "x"], "(expected --num-envs INT)"),
        (["suite", "--sett", "all"], "did you mean --set?"),
        (["eval", "run", "--episodes", "z"], "(expected --episodes INT)"),
        (["inspect", "action-gaps", "--bogus"], "Unrecognized options: --bogus"),
        (["sweep"], "missing FILE: The sweep file. (required)"),
        (["plot"], "missing RUN_DIR: Run directory written by"),
        # a switch given a value: how switches are written, not "Unrecognized options: False"
        (
            ["train", "--progress", "False"],
            "--progress takes no value (got --progress False): write --progress to turn it on "
            "or --no-progress to turn it off",
        ),
        (["train", "--progress=false"], "or --no-progress to turn it off"),
        (["train", "--blr.center-sample", "true"], "or --blr.no-center-sample to turn it off"),
        (["presets", "--all", "True"], "--all takes no value (got --all True)"),
        # the same words after a flag that is no switch, or no flag at all, keep tyro's message
        (["train", "--k", "False"], "'False' is not an integer (expected --k INT)"),
        (["train", "--bogus", "False"], "Unrecognized options: --bogus, False"),
    ],
)
def test_flags_tyro_cannot_read_are_one_line_exit_2(
    args: list[str], needle: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """An unknown flag, a value of the wrong type, a missing value: tyro's framed message comes
    out as one line naming the flag (and the one meant), exit 2, for every command."""
    from farsighter.cli import main

    assert main(args) == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("farsighter: error: "), err
    assert needle in lines[0] and lines[0].endswith(
        f"{' '.join(args[: 2 if args[0] == 'inspect' else 1])} --help lists the flags"
    ), err


def test_integer_flags_take_integral_scientific_notation() -> None:
    from farsighter.cli import train_config

    cfg = train_config(["--total-steps", "2e3", "--hidden-sizes", "32", "1e2", "--k", "5"])
    assert (cfg.total_steps, cfg.hidden_sizes, cfg.k) == (2000, (32, 100), 5)
    assert all(type(v) is int for v in (cfg.total_steps, *cfg.hidden_sizes, cfg.k))


def test_env_kwargs_from_the_command_line() -> None:
    from farsighter.cli import train_config
    from farsighter.envs import make_env

    argv = ["--env", "FrozenLake-v1", "--env-kwargs", "is_slippery=False", "map_name=8x8"]
    cfg = train_config(argv)
    assert cfg.env_kwargs == ("is_slippery=False", "map_name=8x8")
    assert make_env(cfg, seed=0, training=True).observation_space.shape == (64,)


def test_eval_on_the_runs_environment_made_otherwise(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """farsighter eval --env-kwargs: the run's environment with other constructor arguments (the
    lake with slipping, for a run trained without); arguments that change what the agent
    observes are refused in one line."""
    from farsighter import make_config, train
    from farsighter.cli import main

    run = tmp_path / "lake"
    cfg = make_config("ddqn", "FrozenLake-v1", env_kwargs={"is_slippery": False})
    train(dataclasses.replace(cfg, total_steps=300, learning_starts=100, run_dir=str(run)))
    capsys.readouterr()
    for given, kwargs in ([], ["is_slippery=False"]), (["is_slippery=True"], ["is_slippery=True"]):
        flags = ["--env-kwargs", *given] if given else []
        assert main(["eval", str(run), "--episodes", "2", *flags]) == 0
        assert json.loads(capsys.readouterr().out)["env_kwargs"] == kwargs
    assert main(["eval", str(run), "--env-kwargs", "map_name=8x8"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(
        "farsighter: error: with --env-kwargs map_name=8x8 the environment "
        "observes Box(0.0, 1.0, (64,), float32); the run's agent takes"
    )
    assert len(err.splitlines()) == 1


def test_a_reader_that_leaves_early_ends_the_output_quietly(tmp_path: Path) -> None:
    """`farsighter presets | head -1`: the pipe closes before the listing is written; exit
    141 (128 + SIGPIPE) and nothing on stderr, not a BrokenPipeError traceback."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "farsighter", "presets", "--algo", "farsighter"],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.close()  # before the import has finished: the first write finds no reader
    assert proc.wait(timeout=300) == 141
    assert proc.stderr.read() == b""


def test_run_dir_that_cannot_be_created_is_one_line_exit_2(tmp_path: Path) -> None:
    (tmp_path / "afile").write_text("not a directory")
    for run_dir, needle in [
        ("afile/run", "cannot create run directory afile/run: Not a directory"),
        ("afile", "cannot create run directory afile: a file of that name exists"),
    ]:
        res = run_cli(
            "train", "--run-dir", run_dir, "--total-steps", "10", "--no-progress", cwd=tmp_path
        )
        assert res.returncode == 2, res.stderr
        lines = res.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0] == f"farsighter: error: {needle}", res.stderr
    assert (tmp_path / "afile").read_text() == "not a directory"
    res = run_cli("train", "--run-dir", "afile", "--resume", cwd=tmp_path)
    assert res.returncode == 2 and res.stderr.strip() == (
        "farsighter: error: cannot resume: afile holds no run (no config.json)"
    )


def test_diverged_training_is_one_line_exit_2(tmp_path: Path) -> None:
    """A config whose updates blow up (DDQN with lr 1e12) stops at the log interval where the TD
    loss left the floating-point range, with one line naming it, not a traceback."""
    res = run_cli(
        "train",
        *("--algo", "ddqn", "--env", "CartPole-v1", "--lr", "1e12", "--total-steps", "3000"),
        *("--learning-starts", "500", "--run-dir", "run", "--no-progress"),
        cwd=tmp_path,
    )
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "training diverged: the TD loss is nan at step" in lines[0], lines
    assert "Traceback" not in res.stderr


@pytest.mark.parametrize("command", [["eval", "missing"], ["plot", "missing"], ["eval"]])
def test_eval_and_plot_bad_input_exit_2(tmp_path: Path, command: list[str]) -> None:
    res = run_cli(*command, cwd=tmp_path)
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr


def test_existing_run_dir_is_never_overwritten_without_asking(tmp_path: Path) -> None:
    assert run_cli("train", "--run-dir", "run", *TINY, cwd=tmp_path).returncode == 0
    before = (tmp_path / "run" / "metrics.csv").read_text()
    res = run_cli("train", "--run-dir", "run", *TINY, cwd=tmp_path)
    assert res.returncode == 2 and "already exists" in res.stderr
    assert (tmp_path / "run" / "metrics.csv").read_text() == before
    (tmp_path / "run" / "checkpoint.pt").write_bytes(b"\x00garbage")
    res = run_cli("train", "--run-dir", "run", *TINY, "--resume", cwd=tmp_path)
    assert res.returncode == 2 and "corrupt" in res.stderr and "Traceback" not in res.stderr
    res = run_cli("train", "--run-dir", "run", *TINY, "--overwrite", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
