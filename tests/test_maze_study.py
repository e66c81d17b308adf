"""The maze study end to end at a tiny size: every output exists, resume skips finished runs,
--plot-only redraws from the saved files."""

from __future__ import annotations

import os
from pathlib import Path

from farsighter.cli import main
from farsighter.studies.maze import AGENTS, DEFAULT_AGENTS, StudyConfig, _agent_labels


def test_tiny_study_resume_and_plot_only(tmp_path: Path) -> None:
    out = tmp_path / "maze"
    args = [
        "maze",
        "--steps",
        "1200",
        "--seeds",
        "1",
        "--workers",
        "2",
        "--out",
        str(out),
        "--no-progress",
        "--agents",
        "DDQN",
        "Farsighter (k=10)",
    ]
    assert main(args) == 0
    for name in ("report.md", "table.csv", "table.md", "study.json"):
        assert (out / name).exists(), name
    for fig in ("learning_curves", "q_estimate", "heatmaps", "posterior_variance"):
        assert (out / "figures" / f"{fig}.png").stat().st_size > 10_000
    report = (out / "report.md").read_text()
    assert "Q* = 75" in report or "exactly 75" in report
    assert "holds in this run" in report or "does NOT hold in this run" in report

    # a finished run is not redone: its files keep their modification time
    run = out / "runs" / "ddqn__s1" / "summary.json"
    stamp = run.stat().st_mtime_ns
    unfinished = out / "runs" / "farsighter-k-10__s1"
    (unfinished / "probe.csv").unlink()  # as if killed before it finished
    assert main(args) == 0
    assert run.stat().st_mtime_ns == stamp
    assert (unfinished / "probe.csv").exists()

    os.remove(out / "figures" / "heatmaps.png")
    assert main(["maze", "--plot-only", str(out)]) == 0
    assert (out / "figures" / "heatmaps.png").exists()


def test_agents_are_the_library_agents() -> None:
    assert {a.algo for a in AGENTS} == {"ddqn", "bdqn", "ob2i", "farsighter", "rnd", "krnd"}
    labels = [a.label for a in AGENTS]
    # the default study is Fig. 1's five agents; 'all' adds the novelty-bonus baselines
    assert StudyConfig().agents == DEFAULT_AGENTS and set(DEFAULT_AGENTS) < set(labels)
    assert "RND" not in DEFAULT_AGENTS
    assert _agent_labels(["all"]) == tuple(labels)
    assert _agent_labels(["RND", "DDQN"]) == ("RND", "DDQN")


def test_bad_maze_input_exits_2(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    assert main(["maze", "--plot-only", str(tmp_path)]) == 2
    assert "holds no maze study" in capsys.readouterr().err
    assert main(["maze", "--agents", "Nope", "--out", str(tmp_path / "x"), "--steps", "1200"]) == 2
