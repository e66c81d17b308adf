"""The study commands' flags: the command lines in use parse as before, and bad input answers
with one line and exit code 2 before anything is written (as ``farsighter train`` does)."""

from __future__ import annotations

import dataclasses
import json
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from farsighter.cli import main
from farsighter.errors import ConfigError, FarsighterError
from farsighter.studies import maze, robotics
from farsighter.studies.runner import Agent, Study, check, out_dir, parse, settings_from

ROOT = Path(__file__).resolve().parents[2]


def _resolved(study: Study, line: str) -> tuple[object, Path]:
    args = parse(study, shlex.split(line))
    settings = settings_from(study, args)
    return settings, out_dir(study, settings, args)


def test_maze_command_lines_in_use() -> None:
    # README.md, scripts/main.sh and docs/results/README.md
    assert _resolved(maze.STUDY, "--quick") == (maze.QUICK, Path("studies/maze-quick"))
    assert _resolved(maze.STUDY, "") == (maze.StudyConfig(), Path("studies/maze"))
    everything = maze.StudyConfig(agents=tuple(a.label for a in maze.AGENTS), workers=2)
    line = "--agents all --workers 2 --out studies/maze-all"
    assert _resolved(maze.STUDY, line) == (everything, Path("studies/maze-all"))
    line = "--seeds 1 2 3 --steps 60000 --workers 2 --out studies/maze-long"
    long = maze.StudyConfig(seeds=(1, 2, 3), steps=60_000, workers=2)
    assert _resolved(maze.STUDY, line) == (long, Path("studies/maze-long"))
    line = "--agents BDQN 'Farsighter (k=10)' 'Farsighter (adaptive k)' --workers 1"
    three = ("BDQN", "Farsighter (k=10)", "Farsighter (adaptive k)")
    assert _resolved(maze.STUDY, line)[0] == maze.StudyConfig(agents=three, workers=1)
    args = parse(maze.STUDY, shlex.split("--quick --out /tmp/q --no-progress --overwrite"))
    assert (args.quick, args.out, args.progress, args.overwrite) == (True, "/tmp/q", False, True)
    assert parse(maze.STUDY, ["--plot-only", "studies/maze"]).plot_only == "studies/maze"
    # the committed study's settings are saved as today: it resumes and redraws
    saved = json.loads((ROOT / "docs/results/maze/study.json").read_text())
    saved.pop("made_by", None)  # the code that made it
    assert saved == json.loads(json.dumps(dataclasses.asdict(everything)))


def test_robotics_command_lines_in_use() -> None:
    settings, out = _resolved(robotics.STUDY, "--env Walker2d-v5 --steps 30000 --seeds 1 2 3")
    assert settings == robotics.StudyConfig()
    assert out == Path("studies/robotics-walker2d-v5")
    settings, out = _resolved(robotics.STUDY, "--env FetchPickAndPlace-v4 --quick")
    assert settings == dataclasses.replace(robotics.QUICK, env="FetchPickAndPlace-v4")
    assert out == Path("studies/robotics-fetchpickandplace-v4-quick")
    line = (
        "--env FetchPickAndPlace-v4 --seeds 1 2 --steps 15000 --eval-every 1500 --eval-episodes 10"
    )
    settings, _ = _resolved(robotics.STUDY, line)
    assert (settings.seeds, settings.steps, settings.eval_every, settings.eval_episodes) == (
        (1, 2),
        15_000,
        1_500,
        10,
    )
    # without --eval-every at least two evaluations: at most half of --steps
    assert _resolved(robotics.STUDY, "--steps 200")[0].eval_every == 100
    saved = json.loads((ROOT / "docs/results/walker2d/study.json").read_text())
    saved.pop("made_by", None)
    walker = dataclasses.replace(robotics.StudyConfig(), workers=2)
    assert saved == json.loads(json.dumps(dataclasses.asdict(walker)))


BAD = [
    ("maze", "--workers -1", "--workers must be >= 0"),
    ("maze", "--steps 0", "--steps must be >= 1"),
    ("maze", "--steps 999", "--steps must be >= 1000"),
    ("maze", "--seeds", "--seeds must name at least one seed"),
    ("maze", "--seeds 1 -2", "--seeds must be >= 0 (got 1 -2)"),
    ("maze", "--seeds 1 1", "--seeds name a seed twice (1 1)"),
    ("maze", "--agents Nope", "unknown maze agent(s) ['Nope']; accepted: DDQN, BDQN, OB2I"),
    ("maze", "--agents DDQN DDQN", "--agents name an agent twice"),
    ("maze", "--agents", "--agents must name at least one of: DDQN"),
    ("robotics", "--workers -3", "--workers must be >= 0"),
    ("robotics", "--eval-every 0", "--eval-every must be >= 1"),
    ("robotics", "--eval-episodes 0", "--eval-episodes must be >= 1"),
    ("robotics", "--agents NAF Nope", "unknown robotics agent(s) ['Nope']"),
    ("robotics", "--env NoSuchEnv-v0", "NoSuchEnv-v0"),
]


@pytest.mark.parametrize(("command", "line", "message"), BAD)
def test_bad_input_is_one_line_and_exit_2(
    command: str, line: str, message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "study"
    assert main([command, *shlex.split(line), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("farsighter: error: ") and err.count("\n") == 1, err
    assert message in err and "Traceback" not in err
    assert not out.exists()  # checked before anything is written


def test_bad_input_leaves_an_overwritten_study_alone(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "study"
    out.mkdir()
    assert main(["maze", "--workers", "-1", "--out", str(out), "--overwrite"]) == 2
    assert out.exists()


def test_plot_only_takes_no_other_flag(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["maze", "--plot-only", str(tmp_path), "--out", str(tmp_path / "x")]) == 2
    assert "--plot-only DIR redraws the study in DIR" in capsys.readouterr().err
    assert main(["robotics", "--plot-only", str(tmp_path), "--steps", "10", "--quick"]) == 2
    assert "(got --quick, --steps)" in capsys.readouterr().err


def test_a_bad_value_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    for line, needle in (
        ("--workers many", "Error parsing --workers: 'many' is not an integer"),
        ("--no-such-flag", "Unrecognized options: --no-such-flag"),
    ):
        assert main(["maze", *line.split()]) == 2
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and needle in err, err


def test_each_run_config_is_validated_before_any_run() -> None:
    bad = dataclasses.replace(maze.STUDY, agents=(Agent("Broken", "farsighter", {"k": 0}),))
    with pytest.raises(ConfigError, match=r"^maze agent 'Broken': k must be an integer >= 1"):
        check(bad, dataclasses.replace(maze.QUICK, agents=("Broken",)))
    with pytest.raises(FarsighterError, match="probe_every must be >= 1"):
        check(maze.STUDY, dataclasses.replace(maze.QUICK, probe_every=0))


def test_the_command_line_answers_with_one_line() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "farsighter", "maze", "--workers", "-1"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 2
    assert result.stderr.splitlines() == [
        "farsighter: error: --workers must be >= 0 (0: one per core; got -1)"
    ]


def test_every_command_of_the_results_script_parses_and_checks() -> None:
    """scripts/results.py regenerates docs/results/ with these command lines: each must parse,
    name only known agents and pass its study's checks (a typo would fail hours in)."""
    import importlib.util

    from farsighter.studies import atari, explore, kstudy

    spec = importlib.util.spec_from_file_location("results_script", ROOT / "scripts/results.py")
    assert spec is not None and spec.loader is not None
    script = importlib.util.module_from_spec(spec)
    sys.modules["results_script"] = script  # dataclasses look their module up
    spec.loader.exec_module(script)
    studies = {
        "maze": maze.STUDY,
        "k-study": kstudy.STUDY,
        "explore": explore.STUDY,
        "atari": atari.STUDY,
        "robotics": robotics.STUDY,
    }
    folders = [e.folder for e in script.ENTRIES]
    assert len(set(folders)) == len(folders)
    for entry in script.ENTRIES:
        command, *args = shlex.split(entry.args)
        settings = settings_from(studies[command], parse(studies[command], args))
        study = studies[command]
        check(study, settings)
        assert (ROOT / "docs/results" / entry.folder).is_dir(), entry.folder
