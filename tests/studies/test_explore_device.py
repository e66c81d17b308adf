"""benchmarks/explore_device.py: the exploration suite's runs with another device."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from benchmarks import explore_device
from farsighter.studies import explore


def test_the_device_reaches_every_run_config_and_nothing_else_moves(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(explore_device.DEVICE_VAR, "cuda")  # a config is built without a GPU
    study = explore.StudyConfig(families=("chain",), sizes=(5,), seeds=(1,), agents=("Farsighter",))
    agent = next(a for a in explore.AGENTS if a.label == "Farsighter")
    task = explore.tasks(study)[0]
    moved = explore_device._run_config(agent, study, 1, tmp_path, task)
    plain = explore.run_config(agent, study, 1, tmp_path, task)
    assert plain.runtime.device == "cpu" and moved.runtime.device == "cuda"
    assert dataclasses.replace(moved, runtime=plain.runtime) == plain


def test_a_cpu_study_writes_each_runs_verdicts(tmp_path: Path) -> None:
    out, result = tmp_path / "study", tmp_path / "runs.json"
    flags = "--families chain --sizes 5 --seeds 1 --agents Farsighter --steps 600 --workers 1"
    argv = ["--device", "cpu", "--json", str(result), "--", *flags.split(), "--out", str(out)]
    assert explore_device.main([*argv, "--no-progress"]) == 0
    saved = json.loads(result.read_text())
    assert saved["device"] == "cpu" and len(saved["runs"]) == 1
    run = saved["runs"][0]
    assert (run["family"], run["size"], run["seed"], run["budget"]) == ("chain", 5, 1, 600)
    assert isinstance(run["solved"], bool) and isinstance(run["held"], bool)
    config = json.loads(next(out.glob("runs/*/*/config.json")).read_text())
    assert config["runtime"]["device"] == "cpu"
