"""benchmarks.deepsea_growth: a second study's sizes replace the base study's in the growth fit."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from benchmarks import deepsea_growth
from farsighter.envs.deep_sea import deep_sea_id
from farsighter.studies import explore, runner


def _run(size: int, episodes: int, solved_at: int | None, seed: int) -> dict[str, Any]:
    """A deep sea run of ``episodes`` episodes whose greedy evaluations take the treasure from
    episode ``solved_at`` on (never: None), and whose episodes are good from then on."""
    ends = size * np.arange(1.0, episodes + 1)
    good = np.zeros(episodes) if solved_at is None else np.arange(1, episodes + 1) >= solved_at
    ev_steps = ends[9::10]
    solved_step = np.inf if solved_at is None else size * solved_at
    return {
        "seed": seed,
        "steps": size * episodes,
        "task": deep_sea_id(size),
        "metrics": {"global_step": ends, "episodic_return": 0.99 * good},
        "eval": {
            "global_step": ev_steps,
            "eval_return_mean": np.where(ev_steps >= solved_step, 0.99, 0.0),
        },
        "bad_episodes": {"global_step": ends, "bad": 1.0 - good},
    }


def test_the_extra_studys_sizes_replace_the_bases(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    base, extra = tmp_path / "base", tmp_path / "extra"
    # base: N = 6, 8 solved; N = 10 unsolved in two of three seeds within 1,000 episodes
    runs = {
        base: {
            "Farsighter": [_run(6, 1_000, 100, s) for s in (1, 2, 3)]
            + [_run(8, 1_000, 200, s) for s in (1, 2, 3)]
            + [_run(10, 1_000, e, s) for s, e in ((1, None), (2, None), (3, 400))],
            "DDQN": [_run(10, 1_000, None, 1)],
        },
        # extra: N = 10 again, 3,000 episodes, every seed solved
        extra: {
            "Farsighter": [_run(10, 3_000, e, s) for s, e in ((1, 1_500), (2, 1_200), (3, 400))]
        },
    }
    monkeypatch.setattr(runner, "load_runs", lambda study, path: ({}, runs[path]))
    rows, replaced = deepsea_growth.combined_rows(base, extra, "Farsighter")
    assert replaced == [10]
    assert {r["agent"] for r in rows} == {"Farsighter"}
    at_10 = sorted((r["seed"], r["budget"]) for r in rows if r["size"] == 10)
    assert at_10 == [(1, 30_000), (2, 30_000), (3, 30_000)]  # only the extra study's
    assert sum(r["size"] != 10 for r in rows) == 6
    greedy = next(f for f in explore.growth(rows) if f["measure"] == "greedy")
    assert greedy["censored_medians"] == 0  # the base's N = 10 median was a lower bound
    medians = {t["size"]: t["median_episodes_to_solve"] for t in explore.summarise(rows)}
    assert medians[10] > medians[8] > medians[6]


def test_an_extra_study_without_the_agent_is_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    runs = {tmp_path / "a": {"Farsighter": [_run(6, 1_000, 100, 1)]}, tmp_path / "b": {}}
    monkeypatch.setattr(runner, "load_runs", lambda study, path: ({}, runs[path]))
    with pytest.raises(SystemExit, match="no finished runs of 'Farsighter'"):
        deepsea_growth.combined_rows(tmp_path / "a", tmp_path / "b", "Farsighter")
