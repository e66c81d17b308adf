"""The exploration suite: how the episodes an agent needs to solve a task grow with its size.

Task families with a size knob (:data:`FAMILIES`: the combination-lock chain, MiniGrid DoorKey,
KeyCorridor and MultiRoom, bsuite's deep sea, deterministic and stochastic, MountainCar and
Acrobot), every agent with one config for all of them (the library's ``auto`` preset and the
agent's own overrides: no per-task tuning), several seeds each (:mod:`farsighter.studies.runner`
runs the agent x task x seed grid, resumes an interrupted study and loads the saved runs). Per run
it measures from the saved metrics.csv and eval.csv whether and when a greedy evaluation first
reached the family's threshold (stochastic deep sea: from success.csv and eval_success.csv, the
fraction of evaluation episodes that took the treasure, whose noise-free flag the environment
reports, rather than the noisy return); on deep sea it also records every episode's bad flag
(bad_episodes.csv, :class:`BadEpisodeLog`) and applies bsuite's own criterion
(:func:`bsuite_solution`). Per family and agent it fits the growth of the episodes to solve
against the size, polynomial and exponential, with a bootstrap interval on the polynomial
exponent. Everything is drawn from saved files, so ``--plot-only`` redraws it.

The package: :mod:`~farsighter.studies.explore.families` (the families, their sizes, budgets and
criteria), :mod:`~farsighter.studies.explore.agents` (the agents, read from ``agents.yaml``),
:mod:`~farsighter.studies.explore.measures` (per run, then per family x size x agent),
:mod:`~farsighter.studies.explore.growth` (the growth fits), :mod:`~farsighter.studies.explore.report`
(tables, figures, report); here the study's settings, flags, tasks and run configs.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

from farsighter.config import Config
from farsighter.errors import FarsighterError
from farsighter.rundir import EVAL_SUCCESS_FILE, SUCCESS_FILE
from farsighter.studies import runner
from farsighter.studies.explore import report
from farsighter.studies.explore.agents import AGENTS, COLORS, DEFAULT_AGENTS
from farsighter.studies.explore.families import (
    DEEP_SEA_MAX_EPISODES,
    DEEP_SEA_MIN_EPISODES,
    FAMILIES,
    TASKS,
    BsuiteCriterion,
    Family,
    budget_steps,
    deep_sea_optimal_return,
    deep_sea_success_probability,
    episodes_budget,
)

# `growth` is the function (explore.growth(rows)): it takes the name over from its module, which
# stays importable as `from farsighter.studies.explore.growth import ...`
from farsighter.studies.explore.growth import MIN_SIZES, bootstrap_exponent, fit_growth, growth
from farsighter.studies.explore.measures import (
    BAD_EPISODES_FILE,
    SOLVE_MEASURES,
    BadEpisodeLog,
    beats_dithering,
    bsuite_measure,
    bsuite_solution,
    censored_median,
    ended_bad_flags,
    measure,
    measures_of,
    per_run,
    primary_measure,
    seed_values,
    summarise,
)
from farsighter.studies.runner import Agent, Runs, StudyArgs, Task

__all__ = [
    "AGENTS",
    "BAD_EPISODES_FILE",
    "COLORS",
    "DEEP_SEA_MAX_EPISODES",
    "DEEP_SEA_MIN_EPISODES",
    "DEFAULT_AGENTS",
    "FAMILIES",
    "MIN_SIZES",
    "QUICK",
    "SOLVE_MEASURES",
    "STUDY",
    "TASKS",
    "Args",
    "BadEpisodeLog",
    "BsuiteCriterion",
    "Family",
    "StudyConfig",
    "beats_dithering",
    "bootstrap_exponent",
    "bsuite_measure",
    "bsuite_solution",
    "budget_steps",
    "censored_median",
    "command",
    "deep_sea_optimal_return",
    "deep_sea_success_probability",
    "ended_bad_flags",
    "episodes_budget",
    "fit_growth",
    "growth",
    "main",
    "measure",
    "measures_of",
    "per_run",
    "primary_measure",
    "run_config",
    "seed_values",
    "summarise",
    "tasks",
    "write_outputs",
]


@dataclass(frozen=True)
class StudyConfig:
    """What a study runs; saved as study.json."""

    families: tuple[str, ...] = tuple(FAMILIES)
    sizes: tuple[int, ...] = ()  # empty: every size of each family
    seeds: tuple[int, ...] = (1, 2, 3, 4, 5)
    steps: int = 0  # 0: each task's own budget; otherwise a cap on every budget
    episodes: int = 0  # deep sea runs: 0, episodes_budget(N); otherwise this many episodes
    workers: int = 0  # 0: one per core
    agents: tuple[str, ...] = DEFAULT_AGENTS


QUICK = StudyConfig(
    families=("chain",), sizes=(5, 10, 20), seeds=(1, 2, 3), agents=("DDQN", "BDQN", "Farsighter")
)


@dataclass(frozen=True)
class Args(StudyArgs):
    """The flags of ``farsighter explore``: the shared ones and the suite's."""

    steps: Annotated[int | None, runner.study_flag("N")] = None
    """Cap on every task's step budget (0: each task's own budget)."""
    episodes: Annotated[int | None, runner.study_flag("N")] = None
    """Deep sea runs (both families) train for N episodes (0: 2^N + 100, at least 1,000 and at
    most 3,000); bsuite itself runs 10,000, so --episodes 10000 scores bsuite's criterion over
    bsuite's whole run. --steps still caps."""
    families: Annotated[tuple[str, ...] | None, runner.study_flag("NAME [NAME ...]")] = None
    """Task families: chain, driftchain, doorkey, keycorridor, multiroom, mountaincar, acrobot,
    frozenlake, deepsea, deepsea-stochastic."""
    sizes: Annotated[tuple[int, ...] | None, runner.study_flag("N [N ...]")] = None
    """Only these sizes of the chosen families (none given: every size)."""


def tasks(study: StudyConfig) -> tuple[Task, ...]:
    """(environment id, step budget) of every task of the study, family by family."""
    out = []
    for name in study.families:
        family = FAMILIES[name]
        for size in family.sizes:
            if not study.sizes or size in study.sizes:
                env, budget = family.task(size)
                if family.bsuite and study.episodes:  # deep sea: every episode lasts N steps
                    budget = size * study.episodes
                out.append((env, min(budget, study.steps) if study.steps else budget))
    return tuple(out)


def run_config(agent: Agent, study: StudyConfig, seed: int, run_dir: Path, task: Task) -> Config:
    """The library's default for the task (``auto``) and the agent's overrides; the family's
    evaluation settings and no replay in the final checkpoint (measurement, not tuning)."""
    env, steps = task
    name, size = TASKS[env]
    family, every = FAMILIES[name], FAMILIES[name].eval_every_at(size)
    return runner.run_config(
        agent,
        env,
        "auto",
        seed,
        steps,
        run_dir,
        eval_every=every,
        eval_episodes=family.eval_episodes,
        checkpoint_every=0,
        save_replay=False,  # a MiniGrid run's replay is gigabytes; the study never resumes one
        log_every=max(every, 1_000),
    )


def _sizes(names: Sequence[str]) -> str:
    return "; ".join(f"{n}: {' '.join(map(str, FAMILIES[n].sizes))}" for n in names)


def _check(study: StudyConfig) -> None:
    accepted = ", ".join(FAMILIES)
    unknown = [f for f in study.families if f not in FAMILIES]
    if unknown:
        raise FarsighterError(f"unknown explore family(ies) {unknown}; accepted: {accepted}")
    if not study.families:
        raise FarsighterError(f"--families must name at least one of: {accepted}")
    if len(set(study.families)) != len(study.families):
        raise FarsighterError("--families name a family twice")
    if study.steps < 0:
        raise FarsighterError(f"--steps must be >= 0 (0: each task's budget; got {study.steps})")
    if study.episodes < 0:
        raise FarsighterError(
            f"--episodes must be >= 0 (0: each deep sea size's own; got {study.episodes})"
        )
    chosen = {s for f in study.families for s in FAMILIES[f].sizes}
    stray = [s for s in study.sizes if s not in chosen]
    if stray:
        raise FarsighterError(
            f"--sizes {' '.join(map(str, stray))} is no size of the chosen families "
            f"({_sizes(study.families)})"
        )
    for name in study.families:
        if study.sizes and not set(study.sizes) & set(FAMILIES[name].sizes):
            raise FarsighterError(f"--sizes leave family {name} without a task ({_sizes([name])})")
    for env, steps in tasks(study):
        name, size = TASKS[env]
        if FAMILIES[name].bsuite and steps < size:
            raise FarsighterError(
                f"--steps {steps} leaves {env} without an episode (each lasts {size} steps)"
            )
    from farsighter.config import make_config
    from farsighter.envs import make_env

    for env, _ in tasks(study):  # a missing extra (minigrid, bsuite) fails here, before any run
        make_env(make_config("ddqn", env), seed=0).close()


def _bad_episode_log(study: StudyConfig) -> BadEpisodeLog:
    return BadEpisodeLog()


def command(study: dict[str, Any], out: Path) -> str:
    """The command line that runs the study saved in ``study`` (a study.json) into ``out``."""
    settings = runner.settings_of(STUDY, study)
    quick = dataclasses.replace(settings, workers=0) == QUICK
    base = QUICK if quick else StudyConfig()
    names = ("families", "sizes", "seeds", "steps", "episodes", "agents")
    return runner.command_line("explore", settings, base, names, quick, out)


def write_outputs(out: Path, study: dict[str, Any], runs: Runs) -> None:
    """The study's outputs (:func:`farsighter.studies.explore.report.write_outputs`), its
    report naming the :func:`command` that made it."""
    report.write_outputs(out, study, runs, command(study, out))


STUDY = runner.Study(
    kind="explore",
    description="The exploration suite: task families with a size knob (chain, MiniGrid "
    "DoorKey, KeyCorridor, MultiRoom, bsuite's deep sea and its stochastic version, "
    "MountainCar, Acrobot), every agent with one config; how the episodes to solve grow with "
    "the size (deep sea also by bsuite's bad-episode criterion). --quick (the chain at L = 5, "
    "10, 20) takes a few minutes on 2 cores.",
    agents=AGENTS,
    full=StudyConfig(),
    quick=QUICK,
    run_config=run_config,
    write_outputs=write_outputs,
    # the last three: runs whose environment reports is_success (success.csv, eval_success.csv)
    # or bad_episode (deep sea)
    run_files=("metrics.csv", "eval.csv", SUCCESS_FILE, EVAL_SUCCESS_FILE, BAD_EPISODES_FILE),
    args=Args,
    callback=_bad_episode_log,
    check=_check,
    tasks=tasks,
)


def main(argv: Sequence[str]) -> int:
    """``farsighter explore ARGV``."""
    return runner.main(STUDY, argv)
