"""benchmarks/refit_iterations.py: the refit of a run's replay, capped at given iterations."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.refit_iterations import measure
from farsighter import make_config, train


def test_the_refit_of_a_switched_run_by_iteration_cap(tmp_path: Path) -> None:
    run = tmp_path / "chain"
    cfg = make_config(
        "farsighter", "farsighter/Chain5-v0", run_dir=str(run), total_steps=1_500, seed=1
    )
    train(cfg)
    figures = measure(run, [1, 3])
    assert figures["rows"] > 100
    assert [c["cap"] for c in figures["by_cap"]] == [1, 3]
    assert all(0 < c["iterations"] <= c["cap"] for c in figures["by_cap"])
    # the chain's end pays 1: one iteration sees it, none passes it by much
    assert 0.9 <= figures["by_cap"][0]["target_max"] <= 1.5


def test_a_run_of_another_agent_is_refused(tmp_path: Path) -> None:
    run = tmp_path / "ddqn"
    train(make_config("ddqn", "farsighter/Chain5-v0", run_dir=str(run), total_steps=300))
    with pytest.raises(ValueError, match="accepted: farsighter, bdqn"):
        measure(run, [1])
