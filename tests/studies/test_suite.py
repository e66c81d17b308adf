"""The exploration suite with normalised scores (``farsighter suite``): its file (sets, families,
references and their sources), the tabular tasks' references against the real environments
(Monte Carlo under the uniform policy, and the DP-optimal policy simulated), the score of a run
from its metrics.csv, the aggregates, a tiny real study end to end with --plot-only, and bad
input."""

from __future__ import annotations

import csv
import importlib.util
import shlex
from pathlib import Path
from types import ModuleType
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import farsighter.envs.tabular  # noqa: F401  (registers the tabular ids)
from farsighter.aggregate import iqm
from farsighter.cli import main
from farsighter.envs.tabular import TABULAR_TASKS, TabularMDP, reference_returns
from farsighter.plots import read_csv
from farsighter.studies import suite
from farsighter.studies.explore.families import deep_sea_optimal_return
from farsighter.studies.suite import (
    FULL,
    QUICK,
    SUITE,
    TASKS,
    aggregate_rows,
    budget,
    family_rows,
    run_return,
    score_rows,
    tasks,
)
from farsighter.studies.suite_file import SETS, SUITE_FILE, load_suite

ROOT = Path(__file__).resolve().parents[2]

SELECTION = {
    "distractor": {"farsighter/DistractorCorridor-v0": 10_000},
    "ladder": {"farsighter/CashOutLadder-v0": 18_000},
    "chain": {"farsighter/Chain10-v0": 10_000, "farsighter/Chain20-v0": 20_000},
    "deepsea": {"farsighter/DeepSea10-v0": 11_240, "farsighter/DeepSea14-v0": 42_000},
    "frozenlake": {"FrozenLake-v1": 30_000},
    "empty": {"MiniGrid-Empty-5x5-v0": 30_000},
    "acrobot": {"Acrobot-v1": 50_000},
    "cartpole": {"CartPole-v1": 50_000},
}
VALIDATION = {
    "riverswim": {"farsighter/RiverSwim-v0": 10_000},
    "distractor-grid": {"farsighter/DistractorGrid-v0": 20_000},
    "sixarms": {"farsighter/SixArms-v0": 25_000},
    "deepsea-stochastic": {"farsighter/DeepSeaStochastic10-v0": 11_240},
    "driftchain": {"farsighter/DriftChain10-v0": 11_240},
    "taxi": {"Taxi-v4": 60_000},
    "doorkey": {"MiniGrid-DoorKey-5x5-v0": 60_000},
    "lunarlander": {"LunarLander-v3": 60_000},
}


def _script() -> ModuleType:
    spec = importlib.util.spec_from_file_location(
        "suite_references", ROOT / "scripts" / "suite_references.py"
    )
    assert spec and spec.loader
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# ------------------------------------------------------------------------------------------------
# The suite file.
# ------------------------------------------------------------------------------------------------


def test_every_family_sits_in_exactly_one_set_with_its_tasks_and_budgets() -> None:
    for name, expected in (("selection", SELECTION), ("validation", VALIDATION)):
        got = {
            f.name: {t.env: t.steps for t in f.tasks}
            for f in SUITE.families.values()
            if f.set == name
        }
        assert got == expected, name
    assert all(f.set in SETS for f in SUITE.families.values())
    assert not set(SELECTION) & set(VALIDATION)
    kinds = {f.name: f.kind for f in SUITE.families.values()}
    assert kinds["distractor"] == kinds["riverswim"] == "small reward beside a large one"
    assert kinds["chain"] == kinds["driftchain"] == kinds["deepsea-stochastic"] == "lock"
    assert kinds["taxi"] == kinds["empty"] == "grid world"
    assert kinds["lunarlander"] == kinds["cartpole"] == "dense control"
    assert kinds["ladder"] == kinds["sixarms"] == "stochastic rewards in the thousands"


def test_every_task_has_random_below_best_with_sources_and_its_time_limit() -> None:
    from farsighter.config import make_config
    from farsighter.envs import make_env

    for env_id, task in TASKS.items():
        assert task.random.value < task.best.value, env_id
        assert task.random.source.strip() and task.best.source.strip(), env_id
        env = make_env(make_config("ddqn", env_id), seed=0)
        limit = env.spec.max_episode_steps if env.spec else None
        assert task.time_limit == (limit or env.unwrapped.max_steps), env_id  # type: ignore[attr-defined]
        env.close()
        if env_id not in TABULAR_TASKS:  # measured by the script, with its source
            assert "uniform policy" in task.random.source and "seed 0" in task.random.source


def test_agents_and_the_quick_and_full_forms() -> None:
    assert [(a.label, a.algo, a.overrides) for a in SUITE.agents[:4]] == [
        ("Farsighter", "farsighter", {}),
        ("BDQN", "bdqn", {}),
        ("DDQN", "ddqn", {}),
        ("RND", "rnd", {}),
    ]
    assert FULL.agents == QUICK.agents == ("Farsighter", "BDQN", "DDQN", "RND")
    assert FULL.seeds == (1, 2, 3, 4, 5) and QUICK.seeds == (1, 2)
    assert dict(tasks(FULL)) == {e: t.steps for e, t in TASKS.items()}
    for env_id, steps in tasks(QUICK):
        assert steps == max(TASKS[env_id].steps // 4, TASKS[env_id].time_limit)
    capped = suite.SuiteConfig(steps=300)
    assert budget(TASKS["farsighter/DistractorCorridor-v0"], capped) == 300
    only = suite.SuiteConfig(set="validation")
    assert {suite.TASKS[e].family for e, _ in tasks(only)} == set(VALIDATION)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (("random: 0.111355", "random: 2.0"), "must be below best"),
        (("  ladder:\n", "  distractor:\n"), "distractor given twice"),
        (("set: validation", "set: neither"), "set must be one of"),
        (
            ('best_source: "backward induction on the task\'s tables"', "best_source: ''"),
            "needs a source",
        ),
    ],
)
def test_a_malformed_suite_file_is_refused(
    tmp_path: Path, edit: tuple[str, str], message: str
) -> None:
    text = SUITE_FILE.read_text()
    assert edit[0] in text
    bad = tmp_path / "suite.yaml"
    bad.write_text(text.replace(edit[0], edit[1], 1))
    with pytest.raises(ValueError, match=message):
        load_suite(bad)


# ------------------------------------------------------------------------------------------------
# References: the tabular ones against the real environments, the others against their sources.
# ------------------------------------------------------------------------------------------------


def _optimal_policy(mdp: TabularMDP) -> np.ndarray:
    """pi[h, s]: the best action with h steps left (backward induction, as reference_returns)."""
    S, A, _ = mdp.P.shape
    cont = (~mdp.terminal).astype(float)
    v, pi = np.zeros(S), np.zeros((mdp.time_limit + 1, S), dtype=int)
    step_reward = (mdp.P * mdp.R).sum(axis=2)
    for h in range(1, mdp.time_limit + 1):
        q = step_reward + mdp.P @ (cont * v)
        pi[h], v = q.argmax(axis=1), q.max(axis=1)
    return pi


def _returns(env_id: str, episodes: int, policy: np.ndarray | None) -> np.ndarray:
    """Episodic returns on the registered environment: uniform actions, or pi[steps left, s]."""
    env = gym.make(env_id)
    rng = np.random.default_rng(0)
    n = int(env.action_space.n)  # type: ignore[attr-defined]
    limit = env.spec.max_episode_steps if env.spec else 0
    out = np.zeros(episodes)
    s, _ = env.reset(seed=0)
    for i in range(episodes):
        if i:
            s, _ = env.reset()
        t, done = 0, False
        while not done:
            a = int(rng.integers(n)) if policy is None else int(policy[limit - t, int(s)])
            s, r, terminated, truncated, _ = env.step(a)
            out[i] += float(r)
            t, done = t + 1, terminated or truncated
    return out


@pytest.mark.parametrize("env_id", list(TABULAR_TASKS))
def test_tabular_references_match_the_real_environment(env_id: str) -> None:
    mdp = TABULAR_TASKS[env_id]()
    random, best = reference_returns(mdp)
    task = TASKS[env_id]
    assert task.random.source == task.best.source == "backward induction on the task's tables"
    assert task.random.value == pytest.approx(random, rel=1e-5)
    assert task.best.value == pytest.approx(best, rel=1e-5)
    assert mdp.time_limit == task.time_limit
    uniform = _returns(env_id, 2_000, None)
    se = uniform.std(ddof=1) / np.sqrt(len(uniform))
    assert abs(uniform.mean() - random) < 4 * se + 1e-9, (uniform.mean(), random, se)
    optimal = _returns(env_id, 500, _optimal_policy(mdp))
    se = optimal.std(ddof=1) / np.sqrt(len(optimal))
    assert abs(optimal.mean() - best) < 4 * se + 1e-9, (optimal.mean(), best, se)
    if env_id == "farsighter/DistractorCorridor-v0":  # deterministic: every episode earns 1
        np.testing.assert_array_equal(optimal, 1.0)
        assert best == 1.0


def test_the_other_best_returns_follow_their_sources() -> None:
    script = _script()
    assert TASKS["FrozenLake-v1"].best.value == pytest.approx(0.744, abs=5e-4)
    assert TASKS["FrozenLake-v1"].best.value == pytest.approx(
        script.toy_text_best("FrozenLake-v1"), rel=1e-5
    )
    assert TASKS["Taxi-v4"].best.value == pytest.approx(script.toy_text_best("Taxi-v4"), rel=1e-5)
    assert TASKS["MiniGrid-Empty-5x5-v0"].best.value == pytest.approx(1 - 0.9 * 5 / 100)
    assert script.minigrid_best("MiniGrid-Empty-5x5-v0") == (pytest.approx(0.955), 5.0)
    assert TASKS["farsighter/DeepSeaStochastic10-v0"].best.value == pytest.approx(
        deep_sea_optimal_return(10, True), rel=1e-5
    )
    for env_id in (
        "farsighter/Chain10-v0",
        "farsighter/DeepSea14-v0",
        "farsighter/DriftChain10-v0",
    ):
        assert TASKS[env_id].best.value == 0.99
    assert TASKS["CartPole-v1"].best.value == 500
    for env_id in ("Acrobot-v1", "LunarLander-v3"):
        assert TASKS[env_id].best.value == gym.spec(env_id).reward_threshold
        assert "reward_threshold" in TASKS[env_id].best.source


def test_the_script_rewrites_one_tasks_references_in_place() -> None:
    script = _script()
    text = SUITE_FILE.read_text()
    ref = {"random": 0.5, "random_source": "a", "best": 2.0, "best_source": 'b "c"'}
    new = script.rewrite(text, "farsighter/Chain20-v0", ref)
    changed = [(a, b) for a, b in zip(text.splitlines(), new.splitlines(), strict=True) if a != b]
    assert [b.strip() for _, b in changed] == [
        "random: 0.5",
        'random_source: "a"',
        "best: 2",
        "best_source: \"b 'c'\"",
    ]


# ------------------------------------------------------------------------------------------------
# Scores and aggregates.
# ------------------------------------------------------------------------------------------------


def _metrics(tmp_path: Path, returns: list[float]) -> dict[str, np.ndarray]:
    file = tmp_path / "metrics.csv"
    with file.open("w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["global_step", "episode", "episodic_return", "episodic_length"])
        for i, r in enumerate(returns):
            writer.writerow([10 * (i + 1), i + 1, r, 10])
    return read_csv(file)


def test_the_score_of_a_run(tmp_path: Path) -> None:
    returns = [0.0] * 20 + [0.1, 1.0, 1.0, 0.1, 1.0]  # 25 episodes: the last 2 (10%)
    assert run_return(_metrics(tmp_path, returns)) == pytest.approx(0.55)
    assert run_return(_metrics(tmp_path, [0.0, 0.0, 1.0])) == 1.0  # at least one episode
    assert np.isnan(run_return(None)) and np.isnan(run_return({}))
    env_id = "farsighter/DistractorCorridor-v0"
    runs = {
        "DDQN": [{"seed": 3, "steps": 300, "task": env_id, "metrics": _metrics(tmp_path, returns)}]
    }
    (row,) = score_rows(runs)
    task = TASKS[env_id]
    assert row["score"] == pytest.approx((0.55 - task.random.value) / (1.0 - task.random.value))
    assert (row["agent"], row["set"], row["family"], row["seed"]) == (
        "DDQN",
        "selection",
        "distractor",
        3,
    )
    assert row["kind"] == "small reward beside a large one" and row["best"] == 1.0


def _row(agent: str, env_id: str, seed: int, score: float) -> dict[str, Any]:
    task = TASKS[env_id]
    family = SUITE.families[task.family]
    return {
        "agent": agent,
        "set": family.set,
        "family": family.name,
        "task": env_id,
        "seed": seed,
        "score": score,
        "kind": family.kind,
    }


def test_aggregates_per_set_and_families_over_seeds() -> None:
    rng = np.random.default_rng(1)
    envs = ["farsighter/Chain10-v0", "farsighter/Chain20-v0", "farsighter/RiverSwim-v0"]
    rows = [
        _row(a, e, s, float(rng.uniform())) for a in ("A", "B") for e in envs for s in (1, 2, 3)
    ]
    rows = [r for r in rows if not (r["agent"] == "B" and r["task"] == envs[0] and r["seed"] == 3)]
    agg = {(r["set"], r["agent"]): r for r in aggregate_rows(rows)}
    assert set(agg) == {(s, a) for s in ("selection", "validation", "all") for a in ("A", "B")}
    full = [r["score"] for r in rows if r["agent"] == "A"]
    assert agg["all", "A"]["iqm"] == pytest.approx(iqm(np.array(full)))
    assert agg["all", "A"]["mean"] == pytest.approx(np.mean(full))
    assert (agg["all", "A"]["seeds"], agg["all", "A"]["tasks"]) == (3, 3)
    assert (agg["all", "B"]["seeds"], agg["validation", "B"]["seeds"]) == (
        2,
        3,
    )  # seed 3 unfinished
    for r in agg.values():
        assert r["iqm_lo"] <= r["iqm"] <= r["iqm_hi"] and r["mean_lo"] <= r["mean"] <= r["mean_hi"]
    fam = {(r["family"], r["agent"]): r for r in family_rows(rows)}
    chain = [
        np.mean(
            [
                r["score"]
                for r in rows
                if r["agent"] == "A" and r["seed"] == s and r["family"] == "chain"
            ]
        )
        for s in (1, 2, 3)
    ]
    assert fam["chain", "A"]["score"] == pytest.approx(np.mean(chain))
    assert fam["chain", "A"]["tasks"] == 2 and fam["chain", "B"]["seeds"] == 2
    assert fam["chain", "A"]["lo"] <= fam["chain", "A"]["score"] <= fam["chain", "A"]["hi"]


# ------------------------------------------------------------------------------------------------
# The command.
# ------------------------------------------------------------------------------------------------


def test_tiny_suite_end_to_end_and_plot_only(tmp_path: Path) -> None:
    out = tmp_path / "s"
    line = "--families distractor --agents DDQN Farsighter --seeds 1 --steps 300 --workers 1"
    assert main(["suite", *line.split(), "--out", str(out), "--no-progress"]) == 0
    for name in ("report.md", "scores.csv", "aggregate.csv", "families.csv", "families.md"):
        assert (out / name).exists(), name
    figure = out / "figures" / "aggregate.png"
    assert figure.stat().st_size > 10_000
    rows = list(csv.DictReader((out / "scores.csv").open()))
    assert list(rows[0]) == list(suite.SCORE_KEYS)
    assert [(r["agent"], r["task"], r["seed"]) for r in rows] == [
        ("DDQN", "farsighter/DistractorCorridor-v0", "1"),
        ("Farsighter", "farsighter/DistractorCorridor-v0", "1"),
    ]
    task = TASKS["farsighter/DistractorCorridor-v0"]
    for r, label in zip(rows, ("ddqn", "farsighter"), strict=True):
        metrics = read_csv(
            out / "runs" / "farsighter-distractorcorridor-v0" / f"{label}__s1" / "metrics.csv"
        )
        assert float(r["return"]) == pytest.approx(run_return(metrics))
        assert float(r["score"]) == pytest.approx(task.normalise(run_return(metrics)))
    agg = list(csv.DictReader((out / "aggregate.csv").open()))
    assert {(r["set"], r["agent"]) for r in agg} == {
        (s, a) for s in ("selection", "all") for a in ("DDQN", "Farsighter")
    }
    report = (out / "report.md").read_text()
    command = (
        "farsighter suite --families distractor --seeds 1 --steps 300 --agents DDQN Farsighter"
    )
    assert f"Made by `{command} --out {out}`" in report
    assert "validation set, which never chooses" in report
    assert "![aggregate](figures/aggregate.png)" in report
    assert "backward induction on the task's tables" in report and "Made with " in report

    figure.unlink()
    (out / "scores.csv").unlink()
    assert main(["suite", "--plot-only", str(out)]) == 0
    assert figure.exists() and (out / "scores.csv").exists()


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ("--families nope", "unknown suite family(ies) ['nope']"),
        ("--agents Nope", "unknown suite agent(s) ['Nope']"),
        ("--set both", "unknown suite set 'both'"),
        ("--set validation --families distractor", "not in the validation set"),
        ("--families cartpole --steps 100", "shorter than one episode of CartPole-v1"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(
    line: str, message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "s"
    assert main(["suite", *shlex.split(line), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("farsighter: error: ") and err.count("\n") == 1, err
    assert message in err and not out.exists()


def test_the_command_is_listed(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([]) == 0
    assert "farsighter suite [--quick]" in capsys.readouterr().out
