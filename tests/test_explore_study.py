"""The exploration suite (``farsighter explore``): its task table, the runner's task axis, the
per-run measures on synthetic files, censored medians, the growth fits, the claims, bad flags,
and a tiny real study end to end with --plot-only."""

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
from farsighter.envs import make_env
from farsighter.envs.chain import chain_id
from farsighter.studies import explore, maze
from farsighter.studies.explore import (
    AGENTS,
    FAMILIES,
    QUICK,
    STUDY,
    StudyConfig,
    censored_median,
    fit_growth,
    measure,
    run_config,
    tasks,
)
from farsighter.studies.runner import Job, load_runs, parse, settings_from, settings_of


def test_family_table() -> None:
    chain = FAMILIES["chain"]
    assert chain.sizes == (5, 10, 20, 30, 50)
    assert chain.env_ids == tuple(chain_id(n) for n in chain.sizes)
    assert chain.budgets == (10_000, 10_000, 20_000, 30_000, 50_000)
    assert (chain.threshold, chain.eval_episodes) == (0.5, 1)
    assert FAMILIES["doorkey"].env_ids == tuple(f"MiniGrid-DoorKey-{n}x{n}-v0" for n in (5, 6, 8))
    assert FAMILIES["doorkey"].budgets == (100_000, 250_000, 1_000_000)
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
    for name in ("doorkey", "keycorridor", "multiroom"):
        assert (FAMILIES[name].threshold, FAMILIES[name].eval_episodes) == (0.5, 10)
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
    assert len(full) == 5 + 3 + 3 + 3 + 1 and full[-1] == ("MountainCar-v0", 200_000)
    two = StudyConfig(families=("doorkey", "chain"), sizes=(5, 6))
    assert tasks(two) == (
        ("MiniGrid-DoorKey-5x5-v0", 100_000),
        ("MiniGrid-DoorKey-6x6-v0", 250_000),
        (chain_id(5), 10_000),
    )


def test_agents_are_one_config_each_on_the_auto_preset(tmp_path: Path) -> None:
    assert [a.label for a in AGENTS] == [
        "DDQN",
        "k-DDQN",
        "BDQN",
        "Farsighter",
        "Farsighter (redraw step)",
        "Farsighter (redraw k)",
        "Farsighter (redraw episode)",
        "OB2I",
        "RND",
    ]
    by = {a.label: a for a in AGENTS}
    # the default list trains no config twice
    assert "Farsighter (redraw step)" not in StudyConfig().agents
    configs = [
        run_config(by[label], QUICK, 3, tmp_path, (chain_id(10), 10_000))
        for label in StudyConfig().agents
    ]
    assert len({repr(dataclasses.replace(c, run_dir="")) for c in configs}) == len(configs)
    assert by["Farsighter"].overrides == {} and by["DDQN"].overrides == {}
    assert by["Farsighter (redraw k)"].overrides == {"blr.redraw": "k"}
    cfg = run_config(by["Farsighter (redraw step)"], QUICK, 3, tmp_path, (chain_id(10), 10_000))
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
    args = parse(
        STUDY, ["--families", "chain", "--sizes", "5", "--agents", "Farsighter (redraw k)"]
    )
    settings = settings_from(STUDY, args)
    line = explore.command(json.loads(json.dumps(dataclasses.asdict(settings))), tmp_path)
    assert shlex.split(line)[2:] == [
        "--families",
        "chain",
        "--sizes",
        "5",
        "--agents",
        "Farsighter (redraw k)",
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


# ------------------------------------------------------------------------------------------------
# The command: bad flags, and a tiny study end to end.
# ------------------------------------------------------------------------------------------------

BAD = [
    ("--families nope", "unknown explore family(ies) ['nope']; accepted: chain, doorkey"),
    ("--families chain chain", "--families name a family twice"),
    ("--families", "--families must name at least one of"),
    ("--families chain --sizes 7", "--sizes 7 is no size of the chosen families (chain: 5 10 20"),
    ("--families chain mountaincar --sizes 5", "--sizes leave family mountaincar without a task"),
    ("--steps -1", "--steps must be >= 0"),
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

    # a finished run is kept when the study runs again
    stamp = (run_dir / "summary.json").stat().st_mtime_ns
    assert main(["explore", *line.split(), "--out", str(out), "--no-progress"]) == 0
    assert (run_dir / "summary.json").stat().st_mtime_ns == stamp

    figure.unlink()
    (out / "table.csv").unlink()
    assert main(["explore", "--plot-only", str(out)]) == 0
    assert figure.exists() and (out / "table.csv").exists()
