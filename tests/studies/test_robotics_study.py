"""The robotics study end to end at a tiny size (Walker2d-v5 and a goal task): outputs, the
paper's Table 3 beside ours, resume skips finished runs, --plot-only redraws."""

from __future__ import annotations

import inspect
import os
from pathlib import Path

from farsighter.cli import main
from farsighter.config import make_config
from farsighter.studies import robotics
from farsighter.studies.robotics import AGENTS, PAPER_TABLE3, QUICK, _claims, run_config


def test_tiny_walker_study_resume_and_plot_only(tmp_path: Path) -> None:
    out = tmp_path / "walker"
    args = [
        "robotics",
        "--env",
        "Walker2d-v5",
        "--steps",
        "200",
        "--seeds",
        "1",
        "--eval-every",
        "100",
        "--eval-episodes",
        "1",
        "--workers",
        "1",
        "--out",
        str(out),
        "--no-progress",
        "--agents",
        "NAF",
        "Farsighter",
    ]
    assert main(args) == 0
    for name in ("report.md", "table.csv", "table.md", "study.json", "figures/curves.png"):
        assert (out / name).exists(), name
    table = (out / "table.md").read_text()
    assert "230.2 ± 566.8" in table and "-75.8 ± 631.0" in table  # paper's Table 3 beside ours
    report = (out / "report.md").read_text()
    assert "holds in this run" in report or "does NOT hold" in report

    finished = out / "runs" / "naf__s1" / "summary.json"
    stamp = finished.stat().st_mtime_ns
    (out / "runs" / "farsighter__s1" / "summary.json").unlink()  # as if killed before the end
    assert main(args) == 0
    assert finished.stat().st_mtime_ns == stamp
    assert (out / "runs" / "farsighter__s1" / "summary.json").exists()

    os.remove(out / "figures" / "curves.png")
    assert main(["robotics", "--plot-only", str(out)]) == 0
    assert (out / "figures" / "curves.png").stat().st_size > 10_000


def test_goal_task_reports_success_rates(tmp_path: Path) -> None:
    out = tmp_path / "point"
    args = [
        "robotics",
        "--env",
        "tests.goal_env:PointGoal-v0",
        "--steps",
        "300",
        "--seeds",
        "1",
        "--eval-every",
        "150",
        "--eval-episodes",
        "2",
        "--workers",
        "2",  # the parallel path (worker processes)
        "--out",
        str(out),
        "--no-progress",
        "--agents",
        "Bayesian NAF",
    ]
    assert main(args) == 0
    assert "success rate" in (out / "table.md").read_text()
    assert "n/a" in (out / "table.md").read_text()  # no paper number for this task


def test_run_configs_are_the_continuous_preset_with_the_study_budget(tmp_path: Path) -> None:
    for agent in AGENTS:
        assert run_config(agent, QUICK, 2, tmp_path) == make_config(
            agent.algo,
            QUICK.env,
            preset="continuous",
            seed=2,
            total_steps=QUICK.steps,
            eval_every=QUICK.eval_every,
            eval_episodes=QUICK.eval_episodes,
            learning_starts=1_000,
            checkpoint_every=0,
            run_dir=str(tmp_path),
            progress=False,
            torch_threads=1,
            device="cpu",
            overwrite=True,
        )


def test_robotics_borrows_nothing_from_the_maze_study() -> None:
    assert "studies.maze" not in inspect.getsource(robotics)


def test_agents_and_paper_numbers() -> None:
    assert [a.algo for a in AGENTS] == ["naf", "knaf", "bnaf", "farsighter-naf"]
    assert set(PAPER_TABLE3["Walker2d"]) == {a.label for a in AGENTS}


def test_bad_input_exits_2(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    assert main(["robotics", "--plot-only", str(tmp_path)]) == 2
    assert "holds no robotics study" in capsys.readouterr().err
    assert main(["robotics", "--agents", "Nope", "--out", str(tmp_path / "x")]) == 2
    assert main(["robotics", "--env", "NoSuchEnv-v0", "--out", str(tmp_path / "y")]) == 2
    assert not (tmp_path / "y").exists()


def test_claims_call_a_tie_undecided() -> None:
    tied = {"NAF": 0.05, "Bayesian NAF": 0.05, "Farsighter": 0.05}
    lines = _claims(tied, "success rate")
    assert all("not decided" in line for line in lines) and len(lines) == 2
    assert not any("does NOT hold" in line or "holds in this run" in line for line in lines)
    ahead = _claims({"NAF": 100.0, "Bayesian NAF": 200.0, "Farsighter": 300.0}, "return")
    assert "**Farsighter**" in ahead[0] and "holds in this run" in ahead[0]
    assert ahead[1].endswith("holds in this run.")
    behind = _claims({"NAF": 300.0, "Bayesian NAF": 200.0, "Farsighter": 100.0}, "return")
    assert "does NOT hold" in behind[0] and "does NOT hold" in behind[1]
