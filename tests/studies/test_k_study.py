"""The sweep over k (``farsighter k-study``, paper Fig. 4): the agents differ only in k, the grid,
bad flags, the table and the claims on synthetic saved runs (a rises-then-falls case and a
monotone one), and a tiny real study end to end with --plot-only."""

from __future__ import annotations

import csv
import dataclasses
import json
import shlex
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from farsighter.cli import main
from farsighter.config import PRESETS, AdaptiveKConfig, config_to_dict
from farsighter.envs.maze import ENV_ID
from farsighter.studies import explore, kstudy, maze
from farsighter.studies.claims import NOT_TESTED
from farsighter.studies.kstudy import (
    ADAPTIVE,
    AGENTS,
    QUICK,
    STUDY,
    StudyConfig,
    area,
    claims,
    run_config,
    summarise,
)
from farsighter.studies.runner import Job, check, load_runs, out_dir, parse, settings_from


def _flat(d: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in d.items():
        if isinstance(value, dict):
            out.update(_flat(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def _configs(env: str, steps: int, tmp_path: Path) -> dict[str, dict[str, Any]]:
    study = StudyConfig(envs=(env,), steps=steps)
    return {
        a.label: _flat(config_to_dict(run_config(a, study, 3, tmp_path, (env, steps))))
        for a in AGENTS
    }


def _diff(a: dict[str, Any], b: dict[str, Any]) -> set[str]:
    return {key for key in a if a[key] != b[key]}


@pytest.mark.parametrize("env", [ENV_ID, "CartPole-v1"])
def test_agents_differ_only_in_k(env: str, tmp_path: Path) -> None:
    configs = _configs(env, 40_000, tmp_path)
    base = configs["k=1"]
    assert base["preset"] == ("maze" if env == ENV_ID else "general")
    assert (base["algo"], base["seed"], base["total_steps"]) == ("farsighter", 3, 40_000)
    for k in kstudy.KS:
        cfg = configs[f"k={k}"]
        assert cfg["k"] == k and not cfg["adaptive_k.enabled"]
        assert _diff(cfg, base) <= {"k"}
    adaptive = configs[ADAPTIVE]
    assert {key.split(".")[0] for key in _diff(adaptive, base)} == {"k", "adaptive_k"}
    expected = kstudy.MAZE_ADAPTIVE if env == ENV_ID else kstudy.DEFAULT_ADAPTIVE
    assert all(adaptive[key] == value for key, value in expected.items())
    if env == ENV_ID:  # the maze study's adaptive k: from 20 within [2, 40]
        assert (adaptive["k"], adaptive["adaptive_k.k_max"], adaptive["adaptive_k.k_min"]) == (
            20,
            40,
            2,
        )
    else:  # the library's defaults, from k = 10 up to 500
        defaults = _flat({"adaptive_k": dataclasses.asdict(AdaptiveKConfig())})
        assert adaptive["k"] == 10 and adaptive["adaptive_k.k_max"] == 500
        for key in ("variance_target", "k_min", "empty_buffer", "empty_every_refresh"):
            assert adaptive[f"adaptive_k.{key}"] == defaults[f"adaptive_k.{key}"]


def test_the_maze_runs_as_the_maze_study(tmp_path: Path) -> None:
    """On the bridge maze, k=10 and adaptive k are the maze study's agents (same preset, budget
    and evaluation), except that no replay is saved with the final checkpoint."""
    ours = _configs(ENV_ID, kstudy.StudyConfig().steps, tmp_path)
    for mine, theirs in (("k=10", "Farsighter (k=10)"), (ADAPTIVE, "Farsighter (adaptive k)")):
        cfg = maze.run_config(maze.STUDY.agent(theirs), 3, maze.StudyConfig().steps, tmp_path)
        assert _diff(ours[mine], _flat(config_to_dict(cfg))) == {"save_replay"}


def test_grid_settings_and_evaluation_cadence(tmp_path: Path) -> None:
    assert StudyConfig().steps == maze.StudyConfig().steps == 40_000
    assert StudyConfig().envs == (ENV_ID,) and StudyConfig().seeds == (1, 2, 3, 4, 5)
    assert StudyConfig().agents == ("k=1", "k=10", "k=50", "k=150", "k=500", ADAPTIVE)
    args = parse(STUDY, ["--quick"])
    assert settings_from(STUDY, args) == QUICK
    assert out_dir(STUDY, QUICK, args) == Path("studies/k-study-quick")
    line = "--envs farsighter/BridgeMaze-v0 CartPole-v1 --seeds 1 2 --steps 8000"
    settings = settings_from(STUDY, parse(STUDY, shlex.split(line)))
    assert settings == StudyConfig(envs=(ENV_ID, "CartPole-v1"), seeds=(1, 2), steps=8_000)
    grid = STUDY.grid(settings)
    assert len(grid) == 6 * 2 * 2
    assert {j.task for j in grid} == {ENV_ID, "CartPole-v1"} and {j.steps for j in grid} == {8000}
    job = Job("k=500", 2, 8_000, ENV_ID)
    assert job.run_dir(tmp_path) == tmp_path / "runs/farsighter-bridgemaze-v0/k-500__s2"
    assert Job(ADAPTIVE, 1, 8_000, ENV_ID).run_dir(tmp_path).name == "adaptive-k__s1"
    check(STUDY, settings)  # every run's config validates (k=500 fits every buffer)
    # at least 4 evaluations: a short budget evaluates more often than the preset
    short = run_config(AGENTS[0], settings, 1, tmp_path, (ENV_ID, 1_500))
    assert short.eval_every == 375 and short.checkpoint_every == 0 and not short.save_replay
    assert run_config(AGENTS[0], settings, 1, tmp_path, (ENV_ID, 40_000)).eval_every == 2_000


BAD = [
    ("--steps 0", "--steps must be >= 1 (got 0)"),
    ("--envs Nope-v0", "cannot make environment 'Nope-v0'"),
    ("--envs Pendulum-v1", "needs a discrete action space"),
    ("--envs CartPole-v1 CartPole-v1", "--envs name an environment twice"),
    ("--agents k=3", "unknown k-study agent(s) ['k=3']"),
    ("--seeds -1", "--seeds must be >= 0"),
]


def _fails(line: str, message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "study"
    assert main(["k-study", *shlex.split(line), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("farsighter: error: ") and err.count("\n") == 1, err
    assert message in err and "Traceback" not in err, err
    assert not out.exists()


@pytest.mark.parametrize(("line", "message"), BAD)
def test_bad_flags_are_one_line_and_exit_2(
    line: str, message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _fails(line, message, tmp_path, capsys)


def test_k_larger_than_the_buffer_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    # a fixed k: 200 environments share the maze preset's 50k buffer, 250 rows each
    monkeypatch.setitem(PRESETS["maze"].values, "num_envs", 200)
    message = "k-study agent 'k=500' on farsighter/BridgeMaze-v0: k (500) must not exceed the "
    _fails("--agents k=10 k=500", message + "per-environment buffer (250)", tmp_path, capsys)
    # adaptive k's k_max (a fixed k is checked with each run's config, k_max is not)
    monkeypatch.setitem(kstudy.DEFAULT_ADAPTIVE, "adaptive_k.k_max", 2_000_000)
    message = "adaptive k on CartPole-v1: k_max (2000000) exceeds the per-environment buffer"
    _fails("--envs CartPole-v1", message, tmp_path, capsys)


# ------------------------------------------------------------------------------------------------
# The table and the claims, on synthetic saved runs.
# ------------------------------------------------------------------------------------------------

STEPS = 4_000


def _write_study(out: Path, finals: dict[str, list[float]], env: str = ENV_ID) -> None:
    """A study directory as the runner leaves it: study.json, and per run summary.json and an
    eval.csv with two evaluations (-200 at half the budget, then the final return); adaptive k's
    runs also have a metrics.csv whose last k is 23."""
    seeds = tuple(range(1, len(next(iter(finals.values()))) + 1))
    settings = StudyConfig(envs=(env,), seeds=seeds, steps=STEPS, agents=tuple(finals))
    out.mkdir()
    (out / "study.json").write_text(json.dumps(dataclasses.asdict(settings)))
    for label, values in finals.items():
        for seed, final in zip(seeds, values, strict=True):
            run = Job(label, seed, STEPS, env).run_dir(out)
            run.mkdir(parents=True)
            (run / "summary.json").write_text("{}")
            rows = f"{STEPS // 2},-200,0,1\n{STEPS},{final},0,1\n"
            head = "global_step,eval_return_mean,eval_return_std,eval_episodes\n"
            (run / "eval.csv").write_text(head + rows)
            if label == ADAPTIVE:
                head = "global_step,episode,episodic_return,k\n"
                (run / "metrics.csv").write_text(head + "200,1,-200,20\n400,2,-200,23\n")


def _ramp(center: float) -> list[float]:
    return [center - 2, center - 1, center, center + 1, center + 2]


RISES_THEN_FALLS = {
    "k=1": [-200.0] * 5,
    "k=10": _ramp(60),
    "k=50": _ramp(72),
    "k=150": _ramp(65),
    "k=500": [-200.0, -200.0, -200.0, -200.0, 40.0],
    ADAPTIVE: [75.0] * 5,
}
MONOTONE = {
    "k=1": [-200.0] * 5,
    "k=10": _ramp(0),
    "k=50": _ramp(20),
    "k=150": _ramp(40),
    "k=500": _ramp(72),
    ADAPTIVE: _ramp(72),
}


def _redraw(out: Path) -> tuple[list[dict[str, str]], str]:
    assert main(["k-study", "--plot-only", str(out)]) == 0
    for name in ("table.md", "figures/curves.png", "figures/k_curve.png"):
        assert (out / name).stat().st_size > 0, name
    return list(csv.DictReader((out / "table.csv").open())), (out / "report.md").read_text()


def test_rises_then_falls_table_and_claims(tmp_path: Path) -> None:
    out = tmp_path / "s"
    _write_study(out, RISES_THEN_FALLS)
    table, report = _redraw(out)
    by = {r["agent"]: r for r in table}
    assert list(by) == list(RISES_THEN_FALLS)
    k50 = by["k=50"]
    assert (k50["env"], k50["k"], k50["seeds"], k50["budget"]) == (ENV_ID, "50", "5", "4000")
    assert float(k50["final_return_mean"]) == pytest.approx(72.0)
    assert float(k50["final_return_std"]) == pytest.approx(np.sqrt(2.0))
    assert float(k50["auc_mean"]) == pytest.approx((72.0 - 200.0) / 2)  # two evaluations
    assert (k50["solved_seeds"], float(k50["solved_fraction"])) == ("5", 1.0)
    # the maze's rule: solved when the greedy return is above -200 (1 of k=500's seeds)
    assert (by["k=500"]["solved_seeds"], float(by["k=500"]["solved_fraction"])) == ("1", 0.2)
    assert (by["k=1"]["solved_seeds"], by["k=1"]["solved_rule"]) == ("0", "> -200")
    assert float(by[ADAPTIVE]["final_k_mean"]) == 23.0 and by[ADAPTIVE]["k"] == "adaptive"
    assert (
        "| `farsighter/BridgeMaze-v0` | k=50 | 5 | 72 ± 1.41 | -64 ± 0.707 | 5/5 (100%)"
        in (out / "table.md").read_text()
    )

    _, runs = load_runs(STUDY, out)
    shape, best, fastest = claims(summarise(runs))[ENV_ID]
    assert [p.verdict for p in shape.parts] == ["holds", "holds"] and shape.verdict == "holds"
    assert "Best interior k by mean final score: k=50; best fixed k overall: k=50" == shape.note
    assert best.verdict == "holds"
    assert best.note == "Best fixed k by mean final evaluation return: k=50"
    assert fastest.verdict == "holds"
    assert "neither k=1 nor k=500.** Best interior k" in report
    assert "mean final evaluation return: k=50 72, k=1 -200; difference 272" in report
    assert report.count(": **holds**.") == 3
    assert "farsighter k-study --envs farsighter/BridgeMaze-v0 --steps 4000" not in report
    assert f"--steps 4000 --out {out}" in report


def test_monotone_case_does_not_hold(tmp_path: Path) -> None:
    out = tmp_path / "s"
    _write_study(out, MONOTONE)
    _, report = _redraw(out)
    _, runs = load_runs(STUDY, out)
    shape, best, fastest = claims(summarise(runs))[ENV_ID]
    # k=150, the best interior k, beats k=1 but loses to k=500: the score only rises
    assert [p.verdict for p in shape.parts] == ["holds", "does not hold"]
    assert shape.verdict == "does not hold"
    assert shape.note.endswith("best fixed k overall: k=500 (an end of the sweep)")
    # adaptive k ties the best fixed k (k=500) seed for seed: the interval straddles 0
    assert (best.verdict, fastest.verdict) == ("undecided", "undecided")
    assert "**does not hold**" in report and "**undecided at this budget**" in report


def test_claims_not_tested_without_the_ends(tmp_path: Path) -> None:
    out = tmp_path / "s"
    _write_study(out, {k: RISES_THEN_FALLS[k] for k in QUICK.agents})
    _, report = _redraw(out)
    _, runs = load_runs(STUDY, out)
    shape, best, _ = claims(summarise(runs))[ENV_ID]
    assert shape.verdict == NOT_TESTED and shape.note == "Needs k=500 in the study (--agents)"
    assert best.verdict == "holds"  # adaptive k against k=10, the best fixed k here
    assert "--agents k=1 k=10 'adaptive k'" in report


def test_area_under_the_curve() -> None:
    assert area(np.array([1.0, 2.0, 4.0]), np.array([0.0, 2.0, 2.0])) == pytest.approx(5 / 3)
    assert area(np.array([5.0]), np.array([7.0])) == 7.0
    assert np.isnan(area(np.array([]), np.array([])))


def test_solved_rules() -> None:
    assert kstudy.solved_rule(ENV_ID) is kstudy.MAZE_SOLVED
    cartpole = kstudy.solved_rule("CartPole-v1")
    assert cartpole is not None and cartpole(475.0) and not cartpole(474.0)
    chain = kstudy.solved_rule("farsighter/Chain10-v0")
    assert chain is not None and chain.threshold == explore.FAMILIES["chain"].threshold
    assert kstudy.solved_rule("Acrobot-v1") is not None  # registered threshold -100
    deep = kstudy.solved_rule("farsighter/DeepSeaStochastic10-v0")  # a threshold per size
    sto = explore.FAMILIES["deepsea-stochastic"]
    assert deep is not None and deep.threshold == sto.threshold_at(10) == sto.threshold[1]
    assert kstudy.solved_rule("Nope-v0") is None
    # stochastic deep sea's threshold is on the success rate (eval_success.csv), not the return
    assert deep.success and deep.rule() == "success rate >= 0.194"
    assert chain.rule() == ">= 0.5" and not chain.success
    noisy = {
        "eval": {"global_step": np.array([10.0, 20.0]), "eval_return_mean": np.array([0.1, 0.9])},
        "eval_success": {"eval_success_rate": np.array([0.3, 0.1])},
    }
    assert kstudy.per_run(noisy, deep)["solved"] == 0.0  # a high return, a low success rate
    assert kstudy.per_run(noisy, chain)["solved"] == 1.0  # a return rule reads the return
    took = {**noisy, "eval_success": {"eval_success_rate": np.array([0.0, 0.2])}}
    assert kstudy.per_run(took, deep)["solved"] == 1.0
    assert np.isnan(kstudy.per_run({**noisy, "eval_success": None}, deep)["solved"])
    assert kstudy.per_run(noisy, deep)["final"] == 0.9  # the return is still reported
    (line,) = kstudy._setup(["farsighter/DeepSeaStochastic10-v0"])
    assert "solved when the final evaluation success rate is >= 0.194 (" in line


# ------------------------------------------------------------------------------------------------
# A tiny real study.
# ------------------------------------------------------------------------------------------------


def test_tiny_study_end_to_end(tmp_path: Path) -> None:
    out = tmp_path / "k"
    line = f"--agents k=1 '{ADAPTIVE}' --seeds 1 --steps 1500 --workers 1 --no-progress"
    assert main(["k-study", *shlex.split(line), "--out", str(out)]) == 0
    runs_dir = out / "runs" / "farsighter-bridgemaze-v0"
    assert sorted(p.name for p in runs_dir.iterdir()) == ["adaptive-k__s1", "k-1__s1"]
    for name in ("study.json", "table.csv", "table.md", "report.md"):
        assert (out / name).stat().st_size > 0, name
    for name in ("curves.png", "k_curve.png"):
        assert (out / "figures" / name).stat().st_size > 10_000, name
    rows = list(csv.DictReader((out / "table.csv").open()))
    assert [(r["agent"], r["seeds"]) for r in rows] == [("k=1", "1"), (ADAPTIVE, "1")]
    _, runs = load_runs(STUDY, out)
    assert len(runs["k=1"][0]["eval"]["global_step"]) == 4  # every 375 steps
    assert 2 <= float(rows[1]["final_k_mean"]) <= 40
    assert "undecided at this budget" in (out / "report.md").read_text()  # one seed each
