"""What the library writes as JSON is strict JSON: a non-finite float is ``null``, never a bare
``NaN`` or ``Infinity`` (issue #64)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from farsighter import jsonio
from farsighter.cli import main


def strict(text: str) -> Any:
    def refuse(name: str) -> Any:
        raise ValueError(f"not strict JSON: {name}")

    return json.loads(text, parse_constant=refuse)


def test_non_finite_floats_are_written_null() -> None:
    value = {"a": float("nan"), "b": [1.5, float("inf"), (np.float64("-inf"), 2)], "c": "NaN"}
    assert strict(jsonio.dumps(value)) == {"a": None, "b": [1.5, None, [None, 2]], "c": "NaN"}
    with pytest.raises(ValueError, match="not strict JSON"):
        strict(json.dumps(value))


def test_a_run_writes_and_prints_strict_json(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A run that never reaches learning_starts has no training-phase throughput (NaN): its
    summary.json, config.json and printed summary still parse strictly, with null for it."""
    args = ["train", "--algo", "ddqn", "--env", "CartPole-v1", "--total-steps", "200"]
    args += ["--learning-starts", "1000", "--eval-episodes", "1", "--hidden-sizes", "16", "16"]
    assert main([*args, "--no-progress", "--run-dir", str(tmp_path / "run")]) == 0
    printed = strict(capsys.readouterr().out)
    saved = strict((tmp_path / "run" / "summary.json").read_text())
    assert saved["train_phase_sps"] is None and saved["global_step"] == 200
    assert printed == saved
    strict((tmp_path / "run" / "config.json").read_text())


def test_a_non_finite_config_value_is_refused_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """config.json could not hold it (and a resume read it back): refused before the run."""
    args = ["train", "--algo", "ddqn", "--env", "CartPole-v1", "--lr", "inf", "--no-progress"]
    assert main([*args, "--run-dir", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["farsighter: error: lr must be a finite number (got inf)"]
    assert not (tmp_path / "run").exists()
