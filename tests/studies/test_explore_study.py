"""The exploration suite (``farsighter explore``): its task table, the runner's task axis, the
per-run measures on synthetic files (by the return, and by the success for stochastic deep sea),
bsuite's deep sea criterion and the bad-episode callback, censored medians, the growth fits and
their bootstrap interval, the claims, bad flags, and tiny real studies end to end (the chain with
--plot-only, deep sea with bsuite's columns, stochastic deep sea measured by success)."""

from __future__ import annotations

import csv
import dataclasses
import json
import shlex
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from farsighter.cli import main
from farsighter.config import make_config
from farsighter.envs import make_env, make_vector_env
from farsighter.envs.chain import chain_id, drift_chain_id
from farsighter.envs.deep_sea import deep_sea_id
from farsighter.errors import FarsighterError
from farsighter.studies import explore, maze
from farsighter.studies.explore import (
    AGENTS,
    FAMILIES,
    QUICK,
    STUDY,
    BadEpisodeLog,
    StudyConfig,
    beats_dithering,
    bootstrap_exponent,
    bsuite_solution,
    budget_steps,
    censored_median,
    deep_sea_optimal_return,
    deep_sea_success_probability,
    ended_bad_flags,
    episodes_budget,
    families,
    fit_growth,
    growth,
    measure,
    run_config,
    tasks,
)
from farsighter.studies.runner import Agent, Job, load_runs, parse, settings_from, settings_of


def test_family_table() -> None:
    chain = FAMILIES["chain"]
    assert chain.sizes == (5, 10, 20, 30, 50)
    assert chain.env_ids == tuple(chain_id(n) for n in chain.sizes)
    assert chain.budgets == (10_000, 10_000, 20_000, 30_000, 50_000)
    assert (chain.threshold, chain.eval_episodes) == (0.5, 1)
    drift = FAMILIES["driftchain"]  # deep sea's budget: 2^L + 100 episodes of L steps, clamped
    assert drift.env_ids == tuple(drift_chain_id(n) for n in (6, 10, 14, 20))
    assert drift.budgets == (6 * 1_000, 10 * 1_124, 14 * 3_000, 20 * 3_000)
    assert (drift.threshold, drift.eval_episodes, drift.eval_every_at(20)) == (0.5, 1, 100)
    assert FAMILIES["doorkey"].env_ids == tuple(f"MiniGrid-DoorKey-{n}x{n}-v0" for n in (5, 6, 8))
    assert FAMILIES["doorkey"].budgets == (100_000, 250_000, 1_000_000)
    assert FAMILIES["empty"].env_ids == tuple(f"MiniGrid-Empty-{n}x{n}-v0" for n in (5, 8, 16))
    assert FAMILIES["empty"].budgets == (50_000, 100_000, 300_000)
    assert FAMILIES["keycorridor"].env_ids[2] == "MiniGrid-KeyCorridorS3R3-v0"
    assert FAMILIES["keycorridor"].budgets == (100_000, 300_000, 1_000_000)
    assert FAMILIES["multiroom"].env_ids == (
        "MiniGrid-MultiRoom-N2-S4-v0",
        "MiniGrid-MultiRoom-N4-S5-v0",
        "MiniGrid-MultiRoom-N6-v0",
    )
    assert FAMILIES["multiroom"].budgets == (100_000, 1_000_000, 2_000_000)
    car = FAMILIES["mountaincar"]
    assert (car.env_ids, car.budgets, car.threshold, car.eval_episodes) == (
        ("MountainCar-v0",),
        (200_000,),
        -199.0,
        5,
    )
    for name in ("doorkey", "empty", "keycorridor", "multiroom"):
        assert (FAMILIES[name].threshold, FAMILIES[name].eval_episodes) == (0.5, 10)
    acrobot = FAMILIES["acrobot"]
    assert (acrobot.env_ids, acrobot.budgets, acrobot.threshold, acrobot.goal) == (
        ("Acrobot-v1",),
        (100_000,),
        gym.spec("Acrobot-v1").reward_threshold,
        -500.0,
    )
    assert (acrobot.eval_every, acrobot.eval_episodes, acrobot.bsuite) == (5_000, 5, None)
    for family in FAMILIES.values():
        assert len(family.sizes) == len(family.env_ids) == len(family.budgets)
        env = make_env(make_config("ddqn", family.env_ids[0]), seed=0)  # the small size is real
        assert isinstance(env.action_space, gym.spaces.Discrete)
        assert len(env.observation_space.shape or ()) == 1  # flat float vectors
        env.close()


def test_tasks_with_the_steps_cap_and_sizes() -> None:
    assert tasks(QUICK) == ((chain_id(5), 10_000), (chain_id(10), 10_000), (chain_id(20), 20_000))
    capped = dataclasses.replace(QUICK, steps=15_000)
    assert [n for _, n in tasks(capped)] == [10_000, 10_000, 15_000]
    full = tasks(StudyConfig())
    assert len(full) == 5 + 4 + 3 + 3 + 3 + 3 + 1 + 1 + 2 + 9 + 4  # chain, driftchain, ...
    assert ("MountainCar-v0", 200_000) in full and ("Acrobot-v1", 100_000) in full
    assert full[-1] == (deep_sea_id(20, stochastic=True), 20 * 3_000)
    # --episodes sets deep sea runs (both families) alone; --steps still caps
    bsuite_length = StudyConfig(families=("chain", "deepsea"), sizes=(5, 14), episodes=10_000)
    assert tasks(bsuite_length) == ((chain_id(5), 10_000), (deep_sea_id(14), 140_000))
    capped = dataclasses.replace(bsuite_length, steps=100_000, families=("deepsea-stochastic",))
    assert tasks(capped) == ((deep_sea_id(14, stochastic=True), 100_000),)
    assert "--episodes 10000" in explore.command(dataclasses.asdict(bsuite_length), Path("o"))
    two = StudyConfig(families=("doorkey", "chain"), sizes=(5, 6))
    assert tasks(two) == (
        ("MiniGrid-DoorKey-5x5-v0", 100_000),
        ("MiniGrid-DoorKey-6x6-v0", 250_000),
        (chain_id(5), 10_000),
    )


def test_deep_sea_families_budgets_and_thresholds(monkeypatch: pytest.MonkeyPatch) -> None:
    det, sto = FAMILIES["deepsea"], FAMILIES["deepsea-stochastic"]
    assert det.sizes == (6, 8, 10, 12, 14, 17, 20, 24, 30)
    assert sto.sizes == (6, 10, 14, 20)
    assert det.env_ids[0] == "farsighter/DeepSea6-v0"
    assert sto.env_ids[-1] == "farsighter/DeepSeaStochastic20-v0"
    # 2^N + 100 episodes of N steps, at least 1,000 and at most 3,000 episodes
    assert [episodes_budget(n) for n in (6, 8, 9, 10, 11, 12, 30)] == [
        1000,
        1000,
        1000,  # 2^9 + 100 = 612
        1124,
        2148,
        3000,
        3000,
    ]
    assert det.budgets == tuple(n * episodes_budget(n) for n in det.sizes)
    assert (det.budgets[0], det.budgets[1], det.budgets[-1]) == (6_000, 8_000, 90_000)
    assert budget_steps(12) == 36_000
    assert sto.budgets == tuple(budget_steps(n) for n in sto.sizes)
    assert sto.budgets == (6_000, 11_240, 42_000, 60_000)
    monkeypatch.setattr(families, "DEEP_SEA_MAX_EPISODES", 10_000)  # the one place to change it
    assert (episodes_budget(12), budget_steps(12), episodes_budget(14)) == (4196, 50_352, 10_000)
    monkeypatch.setattr(families, "DEEP_SEA_MAX_EPISODES", 500)  # the cap wins over the floor
    assert episodes_budget(6) == 500
    monkeypatch.setattr(families, "DEEP_SEA_MIN_EPISODES", 100)
    assert episodes_budget(6) == 164
    monkeypatch.undo()
    # greedy criteria: deterministic, one episode every max(100, 5 N) steps at 0.5
    assert [det.eval_every_at(n) for n in (6, 20, 24, 30)] == [100, 100, 120, 150]
    assert (det.threshold_at(30), det.goal, det.eval_episodes) == (0.5, 0.5, 1)
    assert det.measured_by == "return" and det.rule_at(6) == "mean return >= 0.5"
    # stochastic: 20 episodes, their success rate at half the optimal success probability
    assert (sto.eval_episodes, sto.measured_by, sto.goal) == (20, "success", 0.5)
    assert sto.threshold_at(6) == pytest.approx(0.5 * (5 / 6) ** 5)
    assert [sto.rule_at(n) for n in (6, 10, 20)] == [
        "success rate >= 0.201",
        "success rate >= 0.194",
        "success rate >= 0.189",
    ]
    for n in sto.sizes:
        env: Any = make_env(make_config("ddqn", deep_sea_id(n, stochastic=True)), seed=0).unwrapped
        # bsuite's optimal return is the success probability less the move cost
        p = deep_sea_success_probability(n, stochastic=True)
        assert p == pytest.approx(env.optimal_return + 0.01)
        assert sto.threshold_at(n) == pytest.approx(0.5 * p)
        assert deep_sea_optimal_return(n, stochastic=True) == pytest.approx(env.optimal_return)
    assert deep_sea_optimal_return(8) == pytest.approx(0.99)
    assert deep_sea_success_probability(8) == 1.0
    assert all(f.measured_by == "return" for k, f in FAMILIES.items() if k != "deepsea-stochastic")
    with pytest.raises(ValueError, match="measured_by must be"):
        dataclasses.replace(det, measured_by="mean")  # type: ignore[arg-type]
    assert (det.bsuite, sto.bsuite) == (
        explore.BsuiteCriterion(0.9, 1),
        explore.BsuiteCriterion(0.8, 100),
    )
    with pytest.raises(ValueError, match="one env id, budget"):
        dataclasses.replace(det, threshold=(0.5, 0.5))
    # a run's config takes the size's evaluation interval
    ddqn = AGENTS[0]
    cfg = run_config(ddqn, StudyConfig(), 1, Path("."), (det.env_ids[-1], 90_000))
    assert (cfg.eval_every, cfg.eval_episodes, cfg.log_every) == (150, 1, 1_000)
    cfg = run_config(ddqn, StudyConfig(), 1, Path("."), (sto.env_ids[-1], 60_000))
    assert (cfg.eval_every, cfg.eval_episodes, cfg.log_every) == (1_000, 20, 1_000)


def test_agents_are_one_config_each_on_the_auto_preset(tmp_path: Path) -> None:
    defaults = ("DDQN", "k-DDQN", "BDQN", "Farsighter", "OB2I", "RND")
    assert StudyConfig().agents == defaults
    by = {a.label: a for a in AGENTS}
    # the agents a study runs unnamed are the library's defaults, nothing else; a variant (a
    # published comparison's) runs only when named
    assert all(by[label].overrides == {} for label in defaults)
    # the default list trains no config twice
    configs = [
        run_config(by[label], QUICK, 3, tmp_path, (chain_id(10), 10_000))
        for label in StudyConfig().agents
    ]
    assert len({repr(dataclasses.replace(c, run_dir="")) for c in configs}) == len(configs)
    farsighter = configs[StudyConfig().agents.index("Farsighter")]
    assert (farsighter.blr.target, farsighter.k_target) == ("sample", "cut")  # the default's
    # random features that widen the draws and fit no value
    assert farsighter.blr.random_features == 32 and not farsighter.blr.random_features_fit
    assert farsighter.blr.data_weight == 100.0
    # a variant is the auto preset with its overrides, and the family's evaluation settings
    variant = Agent("Farsighter (redraw step)", "farsighter", {"blr.redraw": "step"})
    cfg = run_config(variant, QUICK, 3, tmp_path, (chain_id(10), 10_000))
    assert cfg == make_config(
        "farsighter",
        chain_id(10),
        preset="auto",
        **{"blr.redraw": "step"},
        seed=3,
        total_steps=10_000,
        eval_every=100,
        eval_episodes=1,
        checkpoint_every=0,
        save_replay=False,
        log_every=1_000,
        run_dir=str(tmp_path),
        progress=False,
        torch_threads=1,
        device="cpu",
        overwrite=True,
    )
    door = run_config(by["DDQN"], QUICK, 1, tmp_path, ("MiniGrid-DoorKey-8x8-v0", 1_000_000))
    assert (door.eval_every, door.eval_episodes, door.total_steps) == (10_000, 10, 1_000_000)


def test_the_agents_file_is_checked(tmp_path: Path) -> None:
    from farsighter.studies.explore import agents

    text = agents.AGENTS_FILE.read_text()
    assert agents.load() == (AGENTS, explore.DEFAULT_AGENTS)
    for edit, message in (
        (("  RND: {algo: rnd}\n", "  RND: {algo: rnd}\n  RND: {algo: ddqn}\n"), "RND given twice"),
        (("{algo: kddqn}", "{algo: kdqn}"), "unknown algorithm 'kdqn'"),
        (("{algo: bdqn}", "{algo: bdqn, override: {k: 3}}"), "agent 'BDQN' takes 'algo'"),
        (("OB2I, RND]", "OB2I, RND, PPO]"), r"default_agents \['PPO'\] are not in agents"),
    ):
        assert edit[0] in text
        bad = tmp_path / "agents.yaml"
        bad.write_text(text.replace(edit[0], edit[1], 1))
        with pytest.raises(ValueError, match=message):
            agents.load(bad)
    good = tmp_path / "good.yaml"
    good.write_text(text.replace("{algo: bdqn}", "{algo: bdqn, overrides: {k: 3}}"))
    assert {a.label: a.overrides for a in agents.load(good)[0]}["BDQN"] == {"k": 3}


def test_frozen_lake_family_asks_for_half_of_the_best_success_rate() -> None:
    lake = FAMILIES["frozenlake"]
    assert (lake.sizes, lake.env_ids, lake.budgets) == (
        (4, 8),
        ("FrozenLake-v1", "FrozenLake8x8-v1"),
        (50_000, 200_000),
    )
    assert (lake.threshold, lake.goal, lake.eval_episodes, lake.measured_by) == (
        0.5,
        0.0,
        20,
        "return",
    )
    for env_id, best in (("FrozenLake-v1", 0.744), ("FrozenLake8x8-v1", 0.913)):
        # the best success probability within the time limit, by value iteration on the
        # environment's own transition table: the figure the family's text states
        spec = gym.spec(env_id)
        table: Any = gym.make(env_id).unwrapped.P  # type: ignore[attr-defined]
        value = np.zeros(len(table))
        for _ in range(int(spec.max_episode_steps or 0)):
            value = np.array(
                [
                    max(
                        sum(p * (r + (0.0 if done else value[s2])) for p, s2, r, done in outcomes)
                        for outcomes in table[s].values()
                    )
                    for s in range(len(table))
                ]
            )
        assert round(float(value[0]), 3) == best
        assert f"{best}" in lake.solved and best > lake.threshold
    # the observation reaches the agent as a one-hot vector of the lake's cells
    env = make_env(make_config("ddqn", "FrozenLake-v1"), seed=0)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (16,) and obs.sum() == 1.0 and obs[0] == 1.0
    env.close()


def test_the_grid_has_a_task_axis_and_maze_keeps_its_layout(tmp_path: Path) -> None:
    jobs = STUDY.grid(QUICK)
    assert len(jobs) == 3 * 3 * 3
    assert jobs[0] == Job("DDQN", 1, 10_000, chain_id(5))
    assert jobs[0].run_dir(tmp_path) == tmp_path / "runs" / "farsighter-chain5-v0" / "ddqn__s1"
    farsighter = Job("Farsighter", 2, 20_000, chain_id(20)).run_dir(tmp_path)
    assert farsighter == tmp_path / "runs" / "farsighter-chain20-v0" / "farsighter__s2"
    assert {j.steps for j in jobs if j.task == chain_id(20)} == {20_000}
    # a study without tasks: agent x seed, runs/<slug>__s<seed>, its own steps
    maze_jobs = maze.STUDY.grid(maze.QUICK)
    assert len(maze_jobs) == 3 * 5 and {j.task for j in maze_jobs} == {None}
    assert maze_jobs[0].run_dir(tmp_path) == tmp_path / "runs" / "ddqn__s1"
    assert {j.steps for j in maze_jobs} == {maze.QUICK.steps}


def test_settings_round_trip_and_the_command_line(tmp_path: Path) -> None:
    saved = json.loads(json.dumps(dataclasses.asdict(QUICK)))
    assert settings_of(STUDY, saved) == QUICK
    assert explore.command(saved, tmp_path) == f"farsighter explore --quick --out {tmp_path}"
    args = parse(STUDY, ["--families", "chain", "--sizes", "5", "--agents", "k-DDQN"])
    settings = settings_from(STUDY, args)
    line = explore.command(json.loads(json.dumps(dataclasses.asdict(settings))), tmp_path)
    assert shlex.split(line)[2:] == [
        "--families",
        "chain",
        "--sizes",
        "5",
        "--agents",
        "k-DDQN",
        "--out",
        str(tmp_path),
    ]
    assert settings_from(STUDY, parse(STUDY, ["--quick"])) == QUICK
    every = settings_from(STUDY, parse(STUDY, ["--agents", "all"]))  # the alias included
    assert every == dataclasses.replace(StudyConfig(), agents=tuple(a.label for a in AGENTS))


# ------------------------------------------------------------------------------------------------
# Measures on synthetic metrics.csv / eval.csv files.
# ------------------------------------------------------------------------------------------------


def _write_csv(file: Path, rows: list[dict[str, float]]) -> None:
    with file.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def _run_files(tmp_path: Path, returns: list[float], evals: list[float]) -> dict[str, Any]:
    """A run whose episode i ends at step 10 i, evaluated every 25 steps; read back as the
    runner reads a run."""
    from farsighter.plots import read_csv

    _write_csv(
        tmp_path / "metrics.csv",
        [
            {"global_step": 10 * (i + 1), "episode": i + 1, "episodic_return": r}
            for i, r in enumerate(returns)
        ],
    )
    _write_csv(
        tmp_path / "eval.csv",
        [{"global_step": 25 * (i + 1), "eval_return_mean": v} for i, v in enumerate(evals)],
    )
    return {"metrics": read_csv(tmp_path / "metrics.csv"), "eval": read_csv(tmp_path / "eval.csv")}


def test_measures_of_a_solved_run(tmp_path: Path) -> None:
    returns = [0.0, 0.0, 0.0, 0.99, 0.0, 0.99, 0.99, 0.99, 0.99, 0.99]
    run = _run_files(tmp_path, returns, [0.0, 0.0, 0.99, 0.0])  # evals at 25, 50, 75, 100
    m = measure(run, threshold=0.5, goal=0.5)
    # first evaluation at the threshold: step 75, when 7 episodes (steps 10..70) had finished
    assert m == {
        "solved": True,
        "episodes_to_solve": 7.0,
        "steps_to_solve": 75.0,
        "held": False,  # the last evaluation fell back
        "episodes_to_first_reward": 4.0,
        "episodes": 10,
    }
    run = _run_files(tmp_path, returns, [0.99])
    assert measure(run, 0.5, 0.5)["held"] and measure(run, 0.5, 0.5)["episodes_to_solve"] == 2


def test_measures_of_an_unsolved_run(tmp_path: Path) -> None:
    run = _run_files(tmp_path, [-200.0] * 6, [-200.0, -199.5])  # MountainCar: never at -199
    m = measure(run, threshold=-199.0, goal=-200.0)
    assert not m["solved"] and not m["held"] and m["episodes"] == 6
    assert np.isnan(m["episodes_to_solve"]) and np.isnan(m["episodes_to_first_reward"])
    assert measure(run, threshold=-199.5, goal=-200.0)["steps_to_solve"] == 50.0
    empty = measure({"metrics": {}, "eval": None}, 0.5, 0.5)
    assert not empty["solved"] and empty["episodes"] == 0


def _success_files(
    tmp_path: Path, returns: list[float], successes: list[int], rates: list[float]
) -> dict[str, Any]:
    """:func:`_run_files` with success.csv (per training episode) and eval_success.csv (per
    evaluation, every 25 steps), the evaluations' mean returns all 0.99."""
    from farsighter.plots import read_csv

    run = _run_files(tmp_path, returns, [0.99] * len(rates))
    _write_csv(
        tmp_path / "success.csv",
        [
            {"global_step": 10 * (i + 1), "episode": i + 1, "success": v}
            for i, v in enumerate(successes)
        ],
    )
    _write_csv(
        tmp_path / "eval_success.csv",
        [
            {"global_step": 25 * (i + 1), "eval_success_rate": v, "eval_episodes": 20}
            for i, v in enumerate(rates)
        ],
    )
    return {
        **run,
        "success": read_csv(tmp_path / "success.csv"),
        "eval_success": read_csv(tmp_path / "eval_success.csv"),
    }


def test_measures_by_success_ignore_the_noisy_returns(tmp_path: Path) -> None:
    # stochastic deep sea: noisy returns above the goal and mean returns above the threshold
    # from the start, but the treasure first taken in episode 6 and at the third evaluation
    returns = [1.3, -0.4, 0.9, 0.2, -1.0, 0.6, 0.0, 1.1]
    run = _success_files(tmp_path, returns, [0, 0, 0, 0, 0, 1, 0, 1], [0.0, 0.1, 0.25, 0.15])
    m = measure(run, threshold=0.2, goal=0.5, measured_by="success")
    assert m == {
        "solved": True,
        "episodes_to_solve": 7.0,  # the evaluation at step 75
        "steps_to_solve": 75.0,
        "held": False,
        "episodes_to_first_reward": 6.0,
        "episodes": 8,
    }
    # the return measure on the same run: solved at once, a reward in the first episode
    by_return = measure(run, threshold=0.2, goal=0.5)
    assert (by_return["steps_to_solve"], by_return["episodes_to_first_reward"]) == (25.0, 1.0)
    # the study measures each family by its own: the stochastic one by success
    task = {"seed": 1, "steps": 80}
    rows = explore.per_run(
        {"DDQN": [{**run, **task, "task": t} for t in (deep_sea_id(6, True), deep_sea_id(6))]}
    )
    assert [(r["family"], r["steps_to_solve"], r["episodes_to_first_reward"]) for r in rows] == [
        ("deepsea-stochastic", 75.0, 6.0),
        ("deepsea", 25.0, 1.0),
    ]
    # no success at all: unsolved whatever the returns
    run = _success_files(tmp_path, returns, [0] * 8, [0.0] * 4)
    never = measure(run, threshold=0.2, goal=0.5, measured_by="success")
    assert not never["solved"] and not never["held"] and never["episodes"] == 8
    assert np.isnan(never["episodes_to_first_reward"]) and np.isnan(never["steps_to_solve"])
    # a run recorded without is_success cannot be measured so: said, not scored unsolved
    old = {**run, "success": None, "eval_success": None, "task": "t", "seed": 3}
    with pytest.raises(FarsighterError, match=r"\(t, seed 3\) has evaluations but no eval_success"):
        measure(old, 0.2, 0.5, "success")
    assert not measure({"metrics": {}, "eval": None}, 0.2, 0.5, "success")["solved"]


def test_censored_medians_are_lower_bounds_where_a_failure_reaches_the_middle() -> None:
    assert censored_median([10, 20, 30], [False, False, True]) == (20.0, False)
    assert censored_median([10, 40, 30], [False, True, True]) == (30.0, True)
    assert censored_median([10, 20, 30, 40], [False, False, False, True]) == (25.0, False)
    assert censored_median([10, 20, 30, 40], [False, False, True, False]) == (25.0, True)
    assert censored_median([5.0], [True]) == (5.0, True)


def test_growth_fits_recover_known_exponents() -> None:
    sizes = [5, 10, 20, 30, 50]
    poly = fit_growth(sizes, [3 * n**2 for n in sizes])
    assert poly["p"] == pytest.approx(2.0) and poly["r2_poly"] == pytest.approx(1.0)
    assert poly["r2_exp"] < 0.99 and poly["better"] == "polynomial"
    exp = fit_growth(sizes, [7 * np.exp(0.15 * n) for n in sizes])
    assert exp["r"] == pytest.approx(0.15) and exp["r2_exp"] == pytest.approx(1.0)
    assert exp["better"] == "exponential"
    few = fit_growth([5, 10], [10, 40])
    assert few["better"] == "not enough sizes" and np.isnan(few["p"])


def test_bootstrap_interval_on_the_exponent() -> None:
    sizes = [2, 4, 8]
    # every seed of a size alike: any resample has the same medians, so the interval is p itself
    lo, hi = bootstrap_exponent(sizes, [[12, 12, 12], [48, 48, 48], [192, 192]])
    assert lo == pytest.approx(2.0) and hi == pytest.approx(2.0)
    # the two seeds of size 2 took 1 and 100 episodes: a resample's median there is 1 (a
    # quarter of them), 50.5 (half) or 100 (a quarter), so the 2.5 and 97.5 percentiles are the
    # slopes through 100 and through 1 at size 2 (sizes 4 and 8 fixed at 100 and 400)
    lo, hi = bootstrap_exponent(sizes, [[1, 100], [100, 100], [400, 400]])

    def slope(y0: float) -> float:
        return float(np.polyfit(np.log(sizes), np.log([y0, 100, 400]), 1)[0])

    assert lo == pytest.approx(slope(100)) and hi == pytest.approx(slope(1))
    again = bootstrap_exponent(sizes, [[1, 100], [100, 100], [400, 400]])
    assert again == (lo, hi)  # a fixed seed
    assert all(np.isnan(bootstrap_exponent([2, 4], [[1, 2], [3, 4]])))


def _row(
    family: str, size: int, agent: str, greedy: float | None, bs: float | None
) -> dict[str, Any]:
    """A :func:`explore.per_run` row of a 1,000-episode run (None: unsolved)."""
    return {
        "family": family,
        "size": size,
        "env": f"{family}{size}",
        "agent": agent,
        "seed": 1,
        "budget": 10_000,
        "solved": greedy is not None,
        "episodes_to_solve": float("nan") if greedy is None else greedy,
        "steps_to_solve": float("nan") if greedy is None else 10 * greedy,
        "held": greedy is not None,
        "episodes_to_first_reward": float("nan"),
        "episodes": 1_000,
        "bsuite_solved": None if family != "deepsea" else bs is not None,
        "bsuite_episode": float("nan") if bs is None else bs,
    }


def test_growth_fits_each_measure_with_its_interval() -> None:
    sizes = (6, 8, 10, 12)
    rows = [
        _row("deepsea", n, "Farsighter", 900.0, 2.0 * n**2 + k)  # bsuite: about 2 n^2
        for n in sizes
        for k in (0, 1, 2)
    ]
    rows += [_row("chain", n, "Farsighter", 3.0 * n**3, None) for n in (5, 10, 20) for _ in "ab"]
    rows += [_row("deepsea", 14, "Farsighter", None, None)] * 3  # unsolved: not fitted
    fits = {(f["family"], f["measure"]): f for f in growth(rows)}
    assert set(fits) == {("deepsea", "greedy"), ("deepsea", "bsuite"), ("chain", "greedy")}
    bs = fits["deepsea", "bsuite"]
    assert bs["n_sizes"] == 4 and bs["censored_medians"] == 0
    assert bs["p"] == pytest.approx(2.0, abs=0.05) and bs["better"] == "polynomial"
    assert bs["p_lo"] <= bs["p"] <= bs["p_hi"] and bs["p_hi"] - bs["p_lo"] < 0.1
    assert fits["deepsea", "greedy"]["p"] == pytest.approx(0.0)  # 900 at every size
    assert fits["chain", "greedy"]["p"] == pytest.approx(3.0)
    assert fits["chain", "greedy"]["p_lo"] == pytest.approx(3.0)  # the seeds agree
    # exponential growth; at size 14 two seeds unsolved enter at their run's 1,000 episodes and
    # make the median a lower bound (the fit flattens: it grows at least this fast)
    rows = [_row("deepsea", n, "DDQN", None, 10.0 * 2**n) for n in sizes for _ in range(3)]
    exp = next(f for f in growth(rows) if f["measure"] == "bsuite")
    assert (exp["n_sizes"], exp["censored_medians"], exp["better"]) == (4, 0, "exponential")
    assert exp["r"] == pytest.approx(np.log(2))
    rows += [_row("deepsea", 14, "DDQN", None, None)] * 2 + [_row("deepsea", 14, "DDQN", None, 5.0)]
    bs = next(f for f in growth(rows) if f["measure"] == "bsuite")
    assert (bs["n_sizes"], bs["censored_medians"]) == (5, 1) and bs["r"] < exp["r"]


# ------------------------------------------------------------------------------------------------
# bsuite's deep sea criterion and the callback that records the bad flags.
# ------------------------------------------------------------------------------------------------


def test_bsuite_solution_is_the_first_episode_below_the_bad_fraction() -> None:
    # 9 bad episodes then good ones: 9/10 is not below 0.9, 9/11 is: episode 11
    assert bsuite_solution([1] * 9 + [0] * 5, threshold=0.9) == 11
    assert bsuite_solution([1] * 9 + [0], threshold=0.9) is None
    assert bsuite_solution([0, 1, 1], threshold=0.9) == 1  # a first good episode: 0/1
    assert bsuite_solution([], threshold=0.9) is None
    # stochastic: 0.8 and only from episode 100 on; the 5 good episodes first count in the sum
    bad = [0] * 5 + [1] * 95 + [0] * 30
    assert bsuite_solution(bad, threshold=0.8, min_episode=100) == 119  # 95/119 < 0.8 <= 95/118
    assert bsuite_solution(bad, threshold=0.8) == 1
    assert bsuite_solution(bad, threshold=0.8, min_episode=100, max_episode=118) is None
    # beating dithering at N: an episode below 2^N + 100
    assert beats_dithering(163, 6) and not beats_dithering(164, 6)
    assert not beats_dithering(None, 6)


def test_ended_bad_flags_in_both_autoreset_layouts() -> None:
    same_step = {  # SyncVectorEnv SAME_STEP (the loop's): the ended episode's info in final_info
        "bad_episode": np.array([False, False, False]),  # the reset's info
        "final_info": {
            "bad_episode": np.array([False, True, True]),
            "_episode": np.array([True, False, True]),
        },
    }
    assert ended_bad_flags(same_step) == [False, True]
    next_step = {"bad_episode": np.array([True, True]), "_episode": np.array([False, True])}
    assert ended_bad_flags(next_step) == [True]
    assert ended_bad_flags({"bad_episode": np.array([True, False])}) == []  # none ended
    chain_end = {"final_info": {"episode": {}, "_episode": np.array([True])}}
    assert ended_bad_flags(chain_end) is None and ended_bad_flags({}) is None


def test_the_callback_records_every_episode_of_the_real_vector_env(tmp_path: Path) -> None:
    size, num_envs = 3, 2
    cfg = make_config("ddqn", deep_sea_id(size), num_envs=num_envs)
    envs = make_vector_env(cfg, seed=0)
    mapping = envs.envs[0].unwrapped._env._action_mapping  # type: ignore[attr-defined]
    log = BadEpisodeLog()
    obs, _ = envs.reset(seed=0)
    step = 0
    for _ in range(3 * size):  # three episodes in each environment
        cells = [divmod(int(np.argmax(o)), size) for o in obs]
        right = [int(mapping[r, c]) for r, c in cells]
        # environment 0 always moves right; environment 1 moves wrong at the first step
        actions = np.array([right[0], right[1] if cells[1] != (0, 0) else 1 - right[1]])
        obs, _, _, _, info = envs.step(actions)
        step += num_envs
        log.on_step(step, info, agent=None)
    envs.close()
    log.on_finish(tmp_path, agent=None)
    with (tmp_path / "bad_episodes.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert [(int(r["global_step"]), int(r["episode"]), int(r["bad"])) for r in rows] == [
        (6, 1, 0),
        (6, 2, 1),
        (12, 3, 0),
        (12, 4, 1),
        (18, 5, 0),
        (18, 6, 1),
    ]
    # an environment without the flag writes nothing
    chain = BadEpisodeLog()
    vec = make_vector_env(make_config("ddqn", chain_id(5)), seed=0)
    vec.reset(seed=0)
    for t in range(20):
        chain.on_step(t + 1, vec.step(np.array([0]))[4], agent=None)
    vec.close()
    chain.on_finish(tmp_path / "x", agent=None)  # would fail to write there: no directory
    assert not chain.rows and not (tmp_path / "x").exists()


# ------------------------------------------------------------------------------------------------
# Outputs and claims on synthetic runs (the runner's run dicts).
# ------------------------------------------------------------------------------------------------


def _synthetic(episodes_to_solve: int | None, budget: int, task: str, seed: int) -> dict[str, Any]:
    """A chain run whose episode i ends at step 10 i; its evaluations (every 100 steps) reach
    the end of the chain from the step its ``episodes_to_solve``-th episode ends (never: None)."""
    n = budget // 10
    ep_steps = 10.0 * np.arange(1, n + 1)
    ev_steps = 100.0 * np.arange(1, budget // 100 + 1)
    solved_at = np.inf if episodes_to_solve is None else 10.0 * episodes_to_solve
    return {
        "seed": seed,
        "steps": budget,
        "task": task,
        "metrics": {"global_step": ep_steps, "episodic_return": np.zeros(n)},
        "eval": {
            "global_step": ev_steps,
            "eval_return_mean": np.where(ev_steps >= solved_at, 0.99, 0),
        },
    }


def _study(episodes: dict[str, dict[int, list[int | None]]], out: Path) -> dict[str, Any]:
    """Write a study's outputs from per agent, per chain length, per seed episodes to solve."""
    runs = {
        agent: [
            _synthetic(e, 100_000, chain_id(size), seed)
            for size, per_seed in by_size.items()
            for seed, e in enumerate(per_seed, 1)
        ]
        for agent, by_size in episodes.items()
    }
    saved = dataclasses.asdict(
        StudyConfig(families=("chain",), sizes=(5, 10, 20), agents=tuple(episodes), seeds=(1, 2, 3))
    )
    (out / "figures").mkdir(parents=True)
    explore.write_outputs(out, json.loads(json.dumps(saved)), runs)
    return saved


def test_polynomial_farsighter_against_exponential_ddqn_is_shown(tmp_path: Path) -> None:
    _study(
        {
            "DDQN": {5: [50, 60, 40], 10: [300, 400, 350], 20: [9_000, 8_000, None]},
            "Farsighter": {5: [250, 200, 300], 10: [1_000, 900, 1_100], 20: [4_000, 4_000, 4_000]},
        },
        tmp_path,
    )
    table = list(csv.DictReader((tmp_path / "table.csv").open()))
    ddqn20 = next(r for r in table if (r["agent"], r["size"]) == ("DDQN", "20"))
    assert ddqn20["seeds_solved"] == "2" and float(ddqn20["median_episodes_to_solve"]) == 9_000
    assert ddqn20["episodes_censored"] == "False"  # the failed seed lies above the median
    growth = {r["agent"]: r for r in csv.DictReader((tmp_path / "growth.csv").open())}
    assert growth["Farsighter"]["better"] == "polynomial"
    assert float(growth["Farsighter"]["p"]) == pytest.approx(2.0)
    assert growth["DDQN"]["better"] == "exponential"
    report = (tmp_path / "report.md").read_text()
    assert (
        "- **chain**: shown: Farsighter's episodes to solve grow polynomially while DDQN's "
        "grow exponentially" in report
    )
    assert (
        "Most (family, size) pairs solved by more than half of the seeds: **DDQN** and "
        "**Farsighter** with 3 of 3" in report
    )
    assert (tmp_path / "figures" / "chain.png").stat().st_size > 10_000


def test_a_ddqn_that_fails_where_farsighter_solves_and_the_not_shown_cases(tmp_path: Path) -> None:
    _study(
        {
            "DDQN": {5: [50, 60, 40], 10: [None, None, 900], 20: [None, None, None]},
            "Farsighter": {5: [250, 200, 300], 10: [1_000, 900, 1_100], 20: [4_000, 4_000, None]},
        },
        tmp_path / "fails",
    )
    report = (tmp_path / "fails" / "report.md").read_text()
    assert "shown: Farsighter's episodes to solve grow polynomially while DDQN fails" in report
    assert "DDQN solves no seed at size(s) 20 (Farsighter 2/3)" in report
    assert "| chain | 10 | 100,000 | DDQN | 1/3 | 1/3 | >10000 |" in report  # censored median
    _study(
        {
            "DDQN": {5: [250, 200, 300], 10: [1_000, 900, 1_100], 20: [4_000, 4_000, 4_000]},
            "Farsighter": {5: [50, 60, 40], 10: [300, 400, 350], 20: [9_000, 8_000, 9_000]},
        },
        tmp_path / "flipped",
    )
    report = (tmp_path / "flipped" / "report.md").read_text()
    assert "- **chain**: not shown: Farsighter's growth does not fit a polynomial better" in report
    _study(
        {
            "DDQN": {5: [50, 60, 40], 10: [300, 400, 350], 20: [None] * 3},
            "Farsighter": {5: [50, 60, 40], 10: [None] * 3, 20: [None] * 3},
        },
        tmp_path / "few",
    )
    report = (tmp_path / "few" / "report.md").read_text()
    assert "not shown: Farsighter solves a seed at fewer than 3 sizes" in report


def _deep_sea_run(size: int, bad_until: int | None, seed: int) -> dict[str, Any]:
    """A deep sea run of its family's budget whose episodes are bad up to ``bad_until`` (never
    good: None) and whose greedy evaluations never reach the threshold."""
    n = episodes_budget(size)
    bad = np.ones(n) if bad_until is None else (np.arange(1, n + 1) <= bad_until).astype(float)
    return {
        "seed": seed,
        "steps": budget_steps(size),
        "task": deep_sea_id(size),
        "metrics": {
            "global_step": size * np.arange(1.0, n + 1),
            "episodic_return": 0.99 * (1 - bad),
        },
        "eval": {"global_step": np.array([100.0]), "eval_return_mean": np.array([0.0])},
        "bad_episodes": {"global_step": size * np.arange(1.0, n + 1), "bad": bad},
    }


def test_deep_sea_claims_fit_bsuites_episode_and_say_it_plainly(tmp_path: Path) -> None:
    sizes = (6, 8, 10)
    runs = {
        "DDQN": [_deep_sea_run(n, 2**n // 2, s) for n in sizes for s in (1, 2, 3)],
        "Farsighter": [_deep_sea_run(n, 2 * n**2, s) for n in sizes for s in (1, 2, 3)],
    }
    runs["DDQN"][-1] = _deep_sea_run(10, None, 3)  # one seed never leaves the bad episodes
    saved = dataclasses.asdict(
        StudyConfig(families=("deepsea",), sizes=sizes, agents=tuple(runs), seeds=(1, 2, 3))
    )
    (tmp_path / "figures").mkdir()
    explore.write_outputs(tmp_path, json.loads(json.dumps(saved)), runs)
    table = {(r["agent"], r["size"]): r for r in csv.DictReader((tmp_path / "table.csv").open())}
    ddqn10 = table["DDQN", "10"]
    assert (ddqn10["seeds_solved"], ddqn10["seeds_bsuite"], ddqn10["seeds_bsuite_solved"]) == (
        "0",
        "3",
        "2",
    )
    # 512 bad episodes then good ones: 512/569 < 0.9 <= 512/568, so bsuite's episode is 569
    assert float(ddqn10["median_bsuite_episode"]) == 569 and ddqn10["bsuite_censored"] == "False"
    report = (tmp_path / "report.md").read_text()
    assert (
        "| deepsea | 10 | 11,240 | DDQN | 0/3 | 0/3 | >1124 | >11240 | 513 | 2/3 | 569 |" in report
    )
    assert (
        "- **deepsea**: shown: Farsighter's episodes to solve grow polynomially while DDQN's "
        in report
    )
    assert (
        "Fitted: bsuite's episode to solve (bad-episode fraction). Farsighter: p = 1.98" in report
    )
    assert (
        "  - Farsighter: growth is polynomial (a polynomial fits better; p = 1.98, 95% bootstrap "
        "interval [1.98, 1.98])." in report
    )
    assert (
        "  - DDQN: growth is not polynomial (an exponential fits better: r = 0.69 (R² 1)" in report
    )
    growth_rows = list(csv.DictReader((tmp_path / "growth.csv").open()))
    assert [(g["agent"], g["measure"]) for g in growth_rows] == [
        ("DDQN", "greedy"),
        ("DDQN", "bsuite"),
        ("Farsighter", "greedy"),
        ("Farsighter", "bsuite"),
    ]
    far = growth_rows[-1]
    assert float(far["p_lo"]) == pytest.approx(float(far["p"])) == float(far["p_hi"])  # seeds agree
    assert "| deepsea | Farsighter | bsuite | 3 | 0 | p = 1.98 (R² 1) | [1.98, 1.98] |" in report
    assert "bsuite scores it (`bsuite/experiments/deep_sea/analysis.py`)" in report
    assert (tmp_path / "figures" / "deepsea.png").stat().st_size > 10_000


# ------------------------------------------------------------------------------------------------
# The command: bad flags, and a tiny study end to end.
# ------------------------------------------------------------------------------------------------

BAD = [
    (
        "--families nope",
        "unknown explore family(ies) ['nope']; accepted: chain, driftchain, doorkey",
    ),
    ("--families chain chain", "--families name a family twice"),
    ("--families", "--families must name at least one of"),
    ("--families chain --sizes 7", "--sizes 7 is no size of the chosen families (chain: 5 10 20"),
    ("--families chain mountaincar --sizes 5", "--sizes leave family mountaincar without a task"),
    ("--steps -1", "--steps must be >= 0"),
    (
        "--families deepsea --sizes 6 --steps 5",
        "--steps 5 leaves farsighter/DeepSea6-v0 without an episode (each lasts 6 steps)",
    ),
    ("--seeds 1 1", "--seeds name a seed twice"),
    ("--agents Nope", "unknown explore agent(s) ['Nope']"),
]


@pytest.mark.parametrize(("line", "message"), BAD)
def test_bad_flags_are_one_line_and_exit_2(
    line: str, message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "study"
    assert main(["explore", *shlex.split(line), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("farsighter: error: ") and err.count("\n") == 1, err
    assert message in err and "Traceback" not in err
    assert not out.exists()


def test_the_command_is_listed(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([]) == 0
    assert "farsighter explore [--quick]" in capsys.readouterr().out


def test_tiny_study_end_to_end_and_plot_only(tmp_path: Path) -> None:
    out = tmp_path / "x"
    line = "--families chain --sizes 5 --seeds 1 --agents DDQN --steps 2000 --workers 1"
    assert main(["explore", *line.split(), "--out", str(out), "--no-progress"]) == 0
    run_dir = out / "runs" / "farsighter-chain5-v0" / "ddqn__s1"
    assert (run_dir / "summary.json").exists() and (run_dir / "eval.csv").exists()
    for name in ("report.md", "table.csv", "table.md", "runs.csv", "growth.csv", "study.json"):
        assert (out / name).exists(), name
    figure = out / "figures" / "chain.png"
    assert figure.stat().st_size > 10_000
    report = (out / "report.md").read_text()
    assert (
        f"farsighter explore --families chain --sizes 5 --seeds 1 --steps 2000 --agents DDQN --out {out}"
        in report
    )
    assert "| chain | 5 | `farsighter/Chain5-v0` | 2,000 |" in report
    saved, runs = load_runs(STUDY, out)
    assert [(r["task"], r["seed"], r["steps"]) for r in runs["DDQN"]] == [(chain_id(5), 1, 2000)]
    rows = list(csv.DictReader((out / "runs.csv").open()))
    assert int(rows[0]["episodes"]) == len(runs["DDQN"][0]["metrics"]["global_step"])
    # the chain reports no bad flags: no bad_episodes.csv, and bsuite's columns say n/a
    assert not (run_dir / "bad_episodes.csv").exists() and runs["DDQN"][0]["bad_episodes"] is None
    assert rows[0]["bsuite_solved"] == "" and "| n/a | n/a |" in report

    # a finished run is kept when the study runs again
    stamp = (run_dir / "summary.json").stat().st_mtime_ns
    assert main(["explore", *line.split(), "--out", str(out), "--no-progress"]) == 0
    assert (run_dir / "summary.json").stat().st_mtime_ns == stamp

    figure.unlink()
    (out / "table.csv").unlink()
    assert main(["explore", "--plot-only", str(out)]) == 0
    assert figure.exists() and (out / "table.csv").exists()


def test_tiny_deep_sea_study_records_bad_flags_and_bsuites_columns(tmp_path: Path) -> None:
    out = tmp_path / "x"
    line = "--families deepsea --sizes 6 --seeds 1 --agents DDQN --steps 600 --workers 1"
    assert main(["explore", *line.split(), "--out", str(out), "--no-progress"]) == 0
    run_dir = out / "runs" / "farsighter-deepsea6-v0" / "ddqn__s1"
    with (run_dir / "bad_episodes.csv").open() as fh:
        bad = list(csv.DictReader(fh))
    assert [int(r["episode"]) for r in bad] == list(range(1, 101))  # 600 steps, 6 a episode
    assert [int(r["global_step"]) for r in bad] == [6 * e for e in range(1, 101)]
    _, runs = load_runs(STUDY, out)
    returns = runs["DDQN"][0]["metrics"]["episodic_return"]
    flags = np.array([int(r["bad"]) for r in bad])
    # deterministic deep sea: an episode is good exactly when it reached the reward (0.99),
    # which is when it took the treasure (success.csv, from the environment's is_success)
    np.testing.assert_array_equal(flags, (returns < 0.5).astype(int))
    np.testing.assert_array_equal(runs["DDQN"][0]["success"]["success"], 1 - flags)
    episode = bsuite_solution(flags, 0.9)
    solved = beats_dithering(episode, 6)
    (row,) = csv.DictReader((out / "runs.csv").open())
    assert row["bsuite_solved"] == str(solved)
    table = (out / "table.md").read_text()
    assert "| bsuite solved | median bsuite episode |" in table
    median = f"{episode}" if solved else ">100"
    assert "| deepsea | 6 | 600 | DDQN | " in table and f"| {int(solved)}/1 | {median} |" in table
    assert "| deepsea | DDQN | bsuite |" in table  # the growth table's bsuite row


def test_tiny_stochastic_deep_sea_study_is_measured_by_success(tmp_path: Path) -> None:
    out = tmp_path / "x"
    line = "--families deepsea-stochastic --sizes 6 --seeds 1 --agents DDQN --steps 600 --workers 1"
    assert main(["explore", *line.split(), "--out", str(out), "--no-progress"]) == 0
    _, runs = load_runs(STUDY, out)
    run = runs["DDQN"][0]
    # every training episode's success (100 of 6 steps) and every evaluation's rate (20
    # episodes every 300 steps) were recorded and loaded
    assert list(run["success"]["episode"]) == list(range(1, 101))
    assert list(run["eval_success"]["global_step"]) == [300, 600]
    assert list(run["eval_success"]["eval_episodes"]) == [20, 20]
    # taking the treasure needs the diagonal all the way: a success is never a bad episode
    bad = run["bad_episodes"]["bad"]
    assert not np.any((run["success"]["success"] == 1) & (bad == 1))
    (row,) = csv.DictReader((out / "runs.csv").open())
    threshold = FAMILIES["deepsea-stochastic"].threshold_at(6)
    rates = run["eval_success"]["eval_success_rate"]
    assert row["solved"] == str(bool(np.any(rates >= threshold)))
    assert row["held"] == str(bool(rates[-1] >= threshold))
    took = np.flatnonzero(run["success"]["success"] == 1)
    first = float(took[0] + 1) if len(took) else float("nan")
    np.testing.assert_equal(float(row["episodes_to_first_reward"]), first)
    report = (out / "report.md").read_text()
    assert "| deepsea-stochastic | 6 | `farsighter/DeepSeaStochastic6-v0` | 600 |" in report
    assert "| success rate >= 0.201 |" in report
    assert "the fraction of its 20 episodes that took the treasure" in report
