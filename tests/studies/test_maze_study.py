"""The maze study end to end at a tiny size: every output exists, resume skips finished runs,
--plot-only redraws from the saved files; its run configs, claims and table."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
from pathlib import Path
from typing import Any

import numpy as np

from farsighter.cli import main
from farsighter.config import PRESETS, config_to_dict, make_config
from farsighter.studies.claims import VERDICT_TEXT
from farsighter.studies.maze import (
    AGENTS,
    COLORS,
    DEFAULT_AGENTS,
    ENV_ID,
    PER_SEED_METRICS,
    QUICK,
    STUDY,
    StudyConfig,
    _claims,
    _markdown_table,
    run_config,
    summarise,
)
from farsighter.studies.runner import parse, settings_from

RESULTS = Path(__file__).resolve().parents[2] / "docs" / "results" / "maze"

# The shared settings of every maze agent as maze.py held them before they became the `maze`
# preset (the pre-refactor truth, on top of the `control` preset).
OLD_COMMON: dict[str, Any] = {
    "gamma": 1.0,
    "optimizer": "adam",
    "lr": 0.001,
    "optim_eps": 1e-8,
    "hidden_sizes": (64, 64),
    "batch_size": 64,
    "train_every": 4,
    "buffer_size": 50_000,
    "learning_starts": 1_000,
    "target_update_every": 500,
    "eps_decay_steps": 10_000,
    "eps_end": 0.05,
    "loss": "huber",
    "eval_every": 2_000,
    "eval_episodes": 1,
    "eval_max_steps": 200,
    "checkpoint_every": 0,
    "log_every": 1_000,
    "blr.posterior_every": 1_000,
    "blr.posterior_samples": 5_000,
    "blr.prior_std": 10.0,
    "blr.noise_std": 10.0,
}


def test_run_configs_are_those_of_before_the_maze_preset(tmp_path: Path) -> None:
    assert PRESETS["maze"].values == OLD_COMMON
    for agent in AGENTS:
        old = make_config(
            agent.algo,
            ENV_ID,
            preset="control",
            seed=3,
            total_steps=40_000,
            run_dir=str(tmp_path),
            progress=False,
            torch_threads=1,
            device="cpu",
            overwrite=True,
            **{**OLD_COMMON, **agent.overrides},
        )
        new = run_config(agent, 3, 40_000, tmp_path)
        assert new.preset == "maze"  # the only difference: the name of where they come from
        assert config_to_dict(new) == config_to_dict(dataclasses.replace(old, preset="maze")), (
            agent.label
        )


def test_the_committed_results_redraw_to_the_same_report(tmp_path: Path) -> None:
    out = tmp_path / "maze"
    out.mkdir()
    shutil.copy(RESULTS / "study.json", out)
    shutil.copytree(RESULTS / "runs", out / "runs")
    assert main(["maze", "--plot-only", str(out)]) == 0
    for name in ("report.md", "table.md", "table.csv"):
        text = (out / name).read_text().replace(str(out), "docs/results/maze")
        assert text == (RESULTS / name).read_text(), name


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
    claim_lines = [line for line in report.splitlines() if line.startswith("- **")]
    assert claim_lines
    verdicts = tuple(f": {v}." for v in VERDICT_TEXT.values())
    for line in claim_lines:
        assert line.endswith(verdicts), line
    # one seed per agent: nothing can be decided, and the report says so instead of a verdict
    assert not any(line.endswith((": holds.", ": does not hold.")) for line in claim_lines)
    assert "percentile bootstrap" in report and "10,000 resamples" in report
    # the code that made it: the commit of this checkout, in study.json and the report
    made_by = json.loads((out / "study.json").read_text())["made_by"]
    assert len(made_by) == 1 and len(made_by[0]["commit"]) == 40
    last = report.rstrip().splitlines()[-1]
    assert last.startswith(f"Made with commit {made_by[0]['commit'][:10]}"), last

    # a finished run is not redone: its files keep their modification time
    run = out / "runs" / "ddqn__s1" / "summary.json"
    stamp = run.stat().st_mtime_ns
    unfinished = out / "runs" / "farsighter-k-10__s1"
    (unfinished / "probe.csv").unlink()  # as if killed before it finished
    assert main(args) == 0
    assert run.stat().st_mtime_ns == stamp
    assert (unfinished / "probe.csv").exists()
    assert json.loads((out / "study.json").read_text())["made_by"] == made_by  # same code

    os.remove(out / "figures" / "heatmaps.png")
    assert main(["maze", "--plot-only", str(out)]) == 0
    assert (out / "figures" / "heatmaps.png").exists()


def test_agents_are_the_library_agents() -> None:
    assert {a.algo for a in AGENTS} == {"ddqn", "bdqn", "ob2i", "farsighter", "rnd", "krnd"}
    labels = [a.label for a in AGENTS]
    assert len(set(labels)) == len(labels) and set(labels) <= set(COLORS)
    # the default study is Fig. 1's five agents; 'all' adds the novelty-bonus baselines and the
    # two ablations that isolate k
    assert StudyConfig().agents == DEFAULT_AGENTS
    assert DEFAULT_AGENTS == (
        "DDQN",
        "BDQN",
        "OB2I",
        "Farsighter (k=10)",
        "Farsighter (adaptive k)",
    )
    assert set(DEFAULT_AGENTS) < set(labels)
    for extra in ("RND", "k-RND (k=10)", "BDQN (redraw every step)", "Farsighter (k=1)"):
        assert extra in labels and extra not in DEFAULT_AGENTS
    by = {a.label: a for a in AGENTS}
    assert by["Farsighter (k=1)"].algo == "farsighter" and by["Farsighter (k=1)"].overrides == {
        "k": 1
    }
    assert by["Farsighter (k=10)"].overrides == {"k": 10}  # the two differ in k alone
    assert by["BDQN (redraw every step)"].algo == "bdqn"
    assert by["BDQN (redraw every step)"].overrides == {"blr.redraw": "step"}
    assert settings_from(STUDY, parse(STUDY, ["--agents", "all"])).agents == tuple(labels)
    some = settings_from(STUDY, parse(STUDY, ["--agents", "RND", "DDQN", "--quick"]))
    assert some == dataclasses.replace(QUICK, agents=("RND", "DDQN"))


# ------------------------------------------------------------------------------------------------
# The claims on synthetic rows, built as summarise builds them, where the verdict is known.
# ------------------------------------------------------------------------------------------------


def _row(agent: str, seeds: int = 5, **per_seed: Any) -> dict[str, Any]:
    """A summarise row with only what _claims reads; unspecified metrics are constant."""
    values = {key: np.full(seeds, 0.5) for key in PER_SEED_METRICS}
    values.update({k: np.asarray(v, dtype=float) for k, v in per_seed.items()})
    return {"agent": agent, "seeds": seeds, "per_seed": values}


def _verdicts(rows: list[dict[str, Any]], *words: str) -> list[str]:
    """Verdicts of the claims whose text contains every one of ``words``."""
    return [c.verdict for c in _claims(rows) if all(w in c.claim for w in words)]


def test_farsighter_solving_every_seed_beats_ddqn() -> None:
    rows = [
        _row("DDQN", greedy_solved=[0] * 5, final_eval_return=[-200.0] * 5),
        _row("Farsighter (k=10)", greedy_solved=[1] * 5, final_eval_return=[75.0] * 5),
    ]
    claims = [c for c in _claims(rows) if "DDQN" in c.claim]
    assert [c.verdict for c in claims] == ["holds", "holds"]
    solves = claims[0]
    assert "greedy solves: Farsighter (k=10) 5/5, DDQN 0/5" in solves.evidence
    assert "difference 1 [95% CI 1, 1]" in solves.evidence
    assert "difference 275 [95% CI 275, 275]" in claims[1].evidence
    # the other way round the same data refute the claim
    flipped = [
        _row("DDQN", greedy_solved=[1] * 5),
        _row("Farsighter (k=10)", greedy_solved=[0] * 5),
    ]
    assert _verdicts(flipped, "more seeds than") == ["does not hold"]


def test_identical_groups_do_not_hold() -> None:
    same = {key: [3.0, 1.0, 2.0, 5.0, 4.0] for key in PER_SEED_METRICS}
    rows = [_row("BDQN", **same), _row("Farsighter (k=10)", **same), _row("DDQN", **same)]
    # identical but not constant groups resample to differences either side of 0: undecided;
    # identical constant groups (the defaults of _row) cannot differ at all: does not hold
    constant = [_row("BDQN"), _row("Farsighter (k=10)"), _row("DDQN")]
    assert set(_verdicts(rows, "Farsighter")) == {"undecided"}
    assert set(_verdicts(constant, "Farsighter")) == {"does not hold"}
    assert len(_verdicts(constant, "Farsighter")) == 6  # 4 against BDQN, 2 against DDQN


def test_two_seeds_of_overlapping_noise_are_undecided() -> None:
    rows = [
        _row("BDQN", seeds=2, abs_error=[40.0, 10.0], success_last_quarter=[0.2, 0.6]),
        _row("Farsighter (k=10)", seeds=2, abs_error=[30.0, 5.0], success_last_quarter=[0.3, 0.7]),
    ]
    assert _verdicts(rows, "Farsighter (k=10)", "less biased") == ["undecided"]
    assert _verdicts(rows, "more reliably") == ["undecided"]


def test_lower_abs_error_is_better_and_each_farsighter_row_is_checked() -> None:
    rows = [
        _row("BDQN", abs_error=[140.0, 150.0, 145.0, 148.0, 142.0]),
        _row("Farsighter (k=10)", abs_error=[1.0, 2.5, 1.8, 2.2, 2.0]),
        _row("Farsighter (adaptive k)", abs_error=[300.0, 310.0, 305.0, 290.0, 295.0]),
    ]
    assert _verdicts(rows, "Farsighter (k=10)", "less biased") == ["holds"]
    assert _verdicts(rows, "Farsighter (adaptive k)", "less biased") == ["does not hold"]
    claim = next(c for c in _claims(rows) if "Farsighter (k=10)" in c.claim)
    assert claim.evidence.startswith("mean |Q(start) - 75|: Farsighter (k=10) 1.9, BDQN 145;")
    assert claim.ci is not None and claim.ci.hi < 0
    # one claim per Farsighter row, no best-of: every BDQN claim appears for both rows
    assert len(_verdicts(rows, "Farsighter (k=10)")) == len(
        _verdicts(rows, "Farsighter (adaptive k)")
    )


def test_claims_against_novelty_baselines_and_k_alone() -> None:
    rows = [
        _row("RND", greedy_solved=[1, 0, 0, 0, 0]),
        _row("k-RND (k=10)", greedy_solved=[0] * 5),
        _row("Farsighter (k=10)", greedy_solved=[1] * 5, success_last_quarter=[0.9] * 5),
        _row(
            "Farsighter (k=1)",
            greedy_solved=[1] * 5,
            success_last_quarter=[0.2, 0.9, 0.5, 0.1, 0.3],
        ),
    ]
    assert _verdicts(rows, "Farsighter (k=10)", "novelty bonus (RND;") == ["holds"]
    assert _verdicts(rows, "Farsighter (k=10)", "novelty bonus (k-RND") == ["holds"]
    assert _verdicts(rows, "k alone", "greedy solves") == ["does not hold"]  # both 5/5
    assert _verdicts(rows, "k alone", "last quarter") == ["holds"]
    assert _verdicts(rows[:3], "k alone") == []  # only with both rows present


def test_ob2i_variance_is_compared_like_with_like() -> None:
    wide = [-100.0, 100.0, 0.0, 50.0, -50.0]
    rows = [
        # OB2I's own uncertainty is tiny and BDQN's huge, but they are different estimators:
        # Fig. 1c is checked on the spread of Q(start) across seeds, the same for every agent
        _row(
            "OB2I",
            q_start=wide,
            abs_error=[175.0, 25.0, 75.0, 25.0, 125.0],
            own_uncertainty_at_start=[1e-3] * 5,
        ),
        _row(
            "BDQN",
            q_start=[74.0, 76.0, 75.0, 75.5, 74.5],
            abs_error=[1.0, 1.0, 0.0, 0.5, 0.5],
            own_uncertainty_at_start=[1e6] * 5,
        ),
        _row("Farsighter (k=10)", q_start=[3 * q for q in wide]),
        _row("DDQN", q_start=wide),
    ]
    variance = [c for c in _claims(rows) if "largest variance" in c.claim]
    # one line per other agent: larger than BDQN's, smaller than Farsighter's, and the same
    # seeds' values as DDQN's, which resample either side of 0
    assert [c.verdict for c in variance] == ["holds", "does not hold", "undecided"]
    assert "larger than BDQN's" in variance[0].claim
    assert "larger than Farsighter (k=10)'s" in variance[1].claim
    assert "larger than DDQN's" in variance[2].claim
    assert variance[0].evidence.startswith(
        "variance of Q(start) across seeds: OB2I 5000, BDQN 0.5;"
    )
    assert _verdicts(rows, "OB2I's Q-estimate is less biased") == ["does not hold"]
    without = [c for c in _claims(rows[1:]) if "OB2I" in c.claim]
    assert [c.verdict for c in without] == ["not tested"]


def _fake_run(algo: str, seed: int, q: float, var: float, solved: bool) -> dict[str, Any]:
    steps = np.arange(1, 41, dtype=float) * 100
    returns = np.where(np.arange(40) > 20, 70.0, -200.0) if solved else np.full(40, -200.0)
    visits = np.ones((15, 13), dtype=np.int64)
    return {
        "seed": seed,
        "metrics": {"global_step": steps, "episodic_return": returns},
        "eval": {"eval_return_mean": np.array([-200.0, 75.0 if solved else -200.0])},
        "probe": {
            "global_step": np.array([0.0, 2000.0, 4000.0]),
            "q_start": np.array([0.0, q / 2, q]),
            "q_start_var": np.array([np.nan, var * 2, var]),
            "q_variance": np.array([np.nan, 4.0, 1.0]) if np.isfinite(var) else np.full(3, np.nan),
        },
        "visits": visits,
        "config": {"algo": algo},
    }


def test_summarise_keeps_per_seed_values_and_names_the_estimator() -> None:
    runs = {
        "DDQN": [_fake_run("ddqn", s, -300.0 - s, np.nan, False) for s in (1, 2, 3)],
        "BDQN": [_fake_run("bdqn", s, 60.0 + s, 0.5, False) for s in (1, 2, 3)],
        "OB2I": [_fake_run("ob2i", s, 70.0 + 4 * s, 20.0, s > 1) for s in (1, 2, 3)],
        "Farsighter (k=10)": [_fake_run("farsighter", s, 75.0, 0.1, True) for s in (1, 2, 3)],
    }
    rows = summarise(runs, max_steps=200)
    assert [r["agent"] for r in rows] == list(runs)  # one row per agent
    by = {r["agent"]: r for r in rows}
    assert {a: r["estimator"] for a, r in by.items()} == {
        "DDQN": "n/a",
        "BDQN": "BLR phi^T Cov phi",
        "OB2I": "variance over heads",
        "Farsighter (k=10)": "BLR phi^T Cov phi",
    }
    for r in rows:
        assert set(r["per_seed"]) == set(PER_SEED_METRICS)
        assert all(len(v) == 3 for v in r["per_seed"].values())
    assert list(by["BDQN"]["per_seed"]["abs_error"]) == [14.0, 13.0, 12.0]
    assert list(by["OB2I"]["per_seed"]["greedy_solved"]) == [0.0, 1.0, 1.0]
    assert by["OB2I"]["greedy_success_seeds"] == 2
    assert by["OB2I"]["q_start_var_across_seeds"] == np.var([74.0, 78.0, 82.0])
    assert np.isnan(by["DDQN"]["own_uncertainty_at_start"])
    assert list(by["BDQN"]["per_seed"]["variance_last_over_peak"]) == [0.25] * 3
    table = _markdown_table(rows)
    header = table.splitlines()[0]
    assert "Q(start) var across seeds" in header
    assert "own uncertainty at start | estimator" in header
    assert "| OB2I |" in table and "variance over heads" in table
    # the claims run on these rows: Farsighter solves 3/3, DDQN 0/3
    assert _verdicts(rows, "more seeds than epsilon-greedy DDQN") == ["holds"]


def test_bad_maze_input_exits_2(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    assert main(["maze", "--plot-only", str(tmp_path)]) == 2
    assert "holds no maze study" in capsys.readouterr().err
    assert main(["maze", "--agents", "Nope", "--out", str(tmp_path / "x"), "--steps", "1200"]) == 2
