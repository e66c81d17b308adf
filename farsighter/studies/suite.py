"""The exploration suite with normalised scores and one aggregate (``farsighter suite``).

The suite file (``suite.yaml`` beside this module, :func:`load_suite`) is the one place that lists
the task families, the set each sits in (selection or validation, SPEC section 6: defaults are
chosen on the selection set and confirmed on the validation set, which never chooses), their
tasks with their step budgets and normalised-score references (0: the uniform random policy's
expected return; 1: the optimal or best known return; each with its source), and the agents.
:mod:`farsighter.studies.runner` runs the agent x task x seed grid with the library's defaults
(the ``auto`` preset and an agent's own overrides: no per-task tuning), resumes an interrupted
study and loads the saved runs.

A run's score (:func:`run_return`, :meth:`SuiteTask.normalise`) is the mean training episodic
return over the last 10% of its episodes (at least one), normalised by its task's references.
The outputs, drawn from saved files only (``--plot-only`` redraws them): ``scores.csv`` (one row a
run), ``aggregate.csv`` and ``figures/aggregate.png`` (per agent and set: the IQM and the mean of
the normalised scores with 95% stratified bootstrap CIs over tasks x seeds, rliable through
:mod:`farsighter.aggregate`), ``families.csv`` and ``families.md`` (per family and agent: the mean
score with a 95% bootstrap CI over seeds) and ``report.md``.
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import numpy as np

from farsighter.config import Config
from farsighter.errors import FarsighterError
from farsighter.plots import figure, markdown_table
from farsighter.studies import runner
from farsighter.studies.claims import fmt
from farsighter.studies.runner import Agent, Runs, StudyArgs, Task
from farsighter.studies.suite_file import SETS, SuiteFamily, SuiteTask, load_suite

SET_CHOICES = (*SETS, "all")
"""--set: a set, or both."""
LAST_FRACTION = 0.1
"""A run's return: the mean over this last fraction of its training episodes (at least one)."""
BOOTSTRAP_RESAMPLES = 2_000
BOOTSTRAP_SEED = 0


SUITE = load_suite()
TASKS = SUITE.tasks()


@dataclass(frozen=True)
class SuiteConfig:
    """What a study runs; saved as study.json."""

    set: str = "all"
    families: tuple[str, ...] = ()  # empty: every family of the set
    seeds: tuple[int, ...] = SUITE.seeds
    steps: int = 0  # 0: each task's own budget; otherwise a cap on every budget
    fraction: float = 1.0  # of each task's budget (--quick: a quarter)
    workers: int = 0  # 0: one per core
    agents: tuple[str, ...] = SUITE.default_agents


FULL = SuiteConfig()
QUICK = SuiteConfig(seeds=SUITE.quick_seeds, fraction=SUITE.quick_fraction)


@dataclass(frozen=True)
class Args(StudyArgs):
    """The flags of ``farsighter suite``: the shared ones and the suite's."""

    steps: Annotated[int | None, runner.study_flag("N")] = None
    """Cap on every task's step budget (0: each task's own; at least each task's time limit)."""
    set: Annotated[str | None, runner.study_flag("{selection,validation,all}")] = None
    """The families of this set (default: all)."""
    families: Annotated[tuple[str, ...] | None, runner.study_flag("NAME [NAME ...]")] = None
    """Only these families (of the chosen set), as suite.yaml names them."""


def families_of(study: SuiteConfig) -> tuple[SuiteFamily, ...]:
    """The chosen families: --families, or every family of --set (suite.yaml's order)."""
    names = study.families or tuple(
        name for name, f in SUITE.families.items() if study.set in ("all", f.set)
    )
    return tuple(SUITE.families[name] for name in names)


def budget(task: SuiteTask, study: SuiteConfig) -> int:
    """The task's budget times the study's fraction (at least one episode's time limit), capped
    by --steps."""
    steps = max(int(task.steps * study.fraction), task.time_limit)
    return min(steps, study.steps) if study.steps else steps


def tasks(study: SuiteConfig) -> tuple[Task, ...]:
    """(environment id, step budget) of every task of the study, family by family."""
    return tuple((t.env, budget(t, study)) for f in families_of(study) for t in f.tasks)


def run_config(agent: Agent, study: SuiteConfig, seed: int, run_dir: Path, task: Task) -> Config:
    """The library's default for the task (``auto``) and the agent's overrides; no periodic
    evaluation, checkpoint or replay (the score is read from the training episodes)."""
    env, steps = task
    return runner.run_config(
        agent,
        env,
        "auto",
        seed,
        steps,
        run_dir,
        eval_every=0,
        checkpoint_every=0,
        save_replay=False,
        log_every=1_000,
    )


def _check(study: SuiteConfig) -> None:
    if study.set not in SET_CHOICES:
        raise FarsighterError(
            f"unknown suite set '{study.set}'; accepted: {', '.join(SET_CHOICES)}"
        )
    accepted = ", ".join(SUITE.families)
    unknown = [f for f in study.families if f not in SUITE.families]
    if unknown:
        raise FarsighterError(f"unknown suite family(ies) {unknown}; accepted: {accepted}")
    if len(set(study.families)) != len(study.families):
        raise FarsighterError("--families name a family twice")
    other = [f for f in study.families if study.set not in ("all", SUITE.families[f].set)]
    if other:
        raise FarsighterError(
            f"--families {' '.join(other)} not in the {study.set} set (--set all takes both)"
        )
    if study.steps < 0:
        raise FarsighterError(f"--steps must be >= 0 (0: each task's budget; got {study.steps})")
    if not 0 < study.fraction <= 1:
        raise FarsighterError(f"the budget fraction must be in (0, 1] (got {study.fraction})")
    for f in families_of(study):
        for t in f.tasks:
            if study.steps and study.steps < t.time_limit:
                raise FarsighterError(
                    f"--steps {study.steps} is shorter than one episode of {t.env} (its time "
                    f"limit is {t.time_limit} steps)"
                )
    from farsighter.config import make_config
    from farsighter.envs import make_env

    for env, _ in tasks(study):  # a missing extra (minigrid, bsuite, box2d) fails here
        make_env(make_config("ddqn", env), seed=0).close()


# ------------------------------------------------------------------------------------------------
# Scores: per run, then per agent x set (rliable) and per family x agent.
# ------------------------------------------------------------------------------------------------


def run_return(metrics: dict[str, np.ndarray] | None) -> float:
    """The mean training episodic return over the last 10% of the run's episodes (at least
    one); NaN for a run without a finished episode."""
    if not metrics or len(metrics.get("episodic_return", ())) == 0:
        return float("nan")
    returns = np.asarray(metrics["episodic_return"], dtype=float)
    last = max(1, int(len(returns) * LAST_FRACTION))
    return float(returns[-last:].mean())


SCORE_KEYS = ("agent", "set", "family", "kind", "task", "seed", "return", "random", "best", "score")


def score_rows(runs: Runs) -> list[dict[str, Any]]:
    """One row per finished run (agent, then task and seed order)."""
    rows = []
    for label, rs in runs.items():
        for run in rs:
            task = TASKS[run["task"]]
            family = SUITE.families[task.family]
            value = run_return(run.get("metrics"))
            rows.append(
                {
                    "agent": label,
                    "set": family.set,
                    "family": family.name,
                    "kind": family.kind,
                    "task": task.env,
                    "seed": run["seed"],
                    "return": value,
                    "random": task.random.value,
                    "best": task.best.value,
                    "score": task.normalise(value),
                }
            )
    return rows


def _matrix(rows: list[dict[str, Any]]) -> tuple[np.ndarray, list[str], list[int]]:
    """The scores as (seeds, tasks), over the seeds with a finite score on every task."""
    names = list(dict.fromkeys(r["task"] for r in rows))
    by = {(r["task"], r["seed"]): r["score"] for r in rows if np.isfinite(r["score"])}
    seeds = sorted({r["seed"] for r in rows})
    seeds = [s for s in seeds if all((t, s) in by for t in names)]
    x = np.array([[by[t, s] for t in names] for s in seeds], dtype=float)
    return x.reshape(len(seeds), len(names)), names, seeds


AGGREGATE_KEYS = (
    *("agent", "set", "seeds", "tasks"),
    *("iqm", "iqm_lo", "iqm_hi", "mean", "mean_lo", "mean_hi"),
)


def aggregate_rows(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per set (selection, validation, all) and agent: the IQM and the mean of the normalised
    scores with 95% stratified bootstrap CIs (seeds resampled within each task), over the seeds
    that finished every task of the set."""
    from farsighter.aggregate import aggregate

    out = []
    for name in SET_CHOICES:
        for agent in dict.fromkeys(r["agent"] for r in rows):
            cells = [r for r in rows if r["agent"] == agent and name in ("all", r["set"])]
            x, names, seeds = _matrix(cells)
            if not cells or not seeds:
                continue
            (row,) = aggregate({agent: x}, reps=BOOTSTRAP_RESAMPLES, seed=BOOTSTRAP_SEED)
            row.update(set=name, seeds=len(seeds), tasks=len(names))
            out.append({k: row[k] for k in AGGREGATE_KEYS})
    return out


def bootstrap_mean(values: Sequence[float]) -> tuple[float, float, float]:
    """The mean and its 95% percentile bootstrap interval (seeds resampled)."""
    x = np.asarray(values, dtype=float)
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    means = x[rng.integers(0, len(x), size=(BOOTSTRAP_RESAMPLES, len(x)))].mean(axis=1)
    lo, hi = np.percentile(means, [2.5, 97.5])
    return float(x.mean()), float(lo), float(hi)


FAMILY_KEYS = ("family", "set", "kind", "agent", "tasks", "seeds", "score", "lo", "hi")


def family_rows(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per family and agent: the mean normalised score (a seed's: the mean over the family's
    tasks) and its 95% bootstrap CI over the seeds that finished every task of the family."""
    out = []
    for family in dict.fromkeys(r["family"] for r in rows):
        for agent in dict.fromkeys(r["agent"] for r in rows):
            cells = [r for r in rows if r["family"] == family and r["agent"] == agent]
            x, names, seeds = _matrix(cells)
            if not seeds:
                continue
            score, lo, hi = bootstrap_mean(x.mean(axis=1))
            out.append(
                {
                    "family": family,
                    "set": cells[0]["set"],
                    "kind": cells[0]["kind"],
                    "agent": agent,
                    "tasks": len(names),
                    "seeds": len(seeds),
                    "score": score,
                    "lo": lo,
                    "hi": hi,
                }
            )
    return out


# ------------------------------------------------------------------------------------------------
# Outputs: tables, figure and report, from the saved files only.
# ------------------------------------------------------------------------------------------------


def _write_csv(file: Path, keys: Sequence[str], rows: list[dict[str, Any]]) -> None:
    with file.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(keys))
        writer.writeheader()
        writer.writerows(rows)


def write_outputs(out: Path, study: dict[str, Any], runs: Runs) -> None:
    """scores.csv, aggregate.csv, figures/aggregate.png, families.csv, families.md, report.md."""
    rows = score_rows(runs)
    aggregates = aggregate_rows(rows)
    families = family_rows(rows)
    _write_csv(out / "scores.csv", SCORE_KEYS, rows)
    _write_csv(out / "aggregate.csv", AGGREGATE_KEYS, aggregates)
    _write_csv(out / "families.csv", FAMILY_KEYS, families)
    (out / "families.md").write_text(_families_table(families))
    _plot(aggregates, out / "figures" / "aggregate.png")
    _write_report(out, study, rows, aggregates, families)


def _ci(value: float, lo: float, hi: float) -> str:
    return f"{value:.2f} [{lo:.2f}, {hi:.2f}]"


def _aggregate_table(aggregates: list[dict[str, Any]]) -> str:
    head = ["set", "agent", "seeds", "tasks", "IQM [95% CI]", "mean [95% CI]"]
    return markdown_table(
        head,
        [
            [
                r["set"],
                r["agent"],
                str(r["seeds"]),
                str(r["tasks"]),
                _ci(r["iqm"], r["iqm_lo"], r["iqm_hi"]),
                _ci(r["mean"], r["mean_lo"], r["mean_hi"]),
            ]
            for r in aggregates
        ],
    )


def _families_table(families: list[dict[str, Any]]) -> str:
    head = ["set", "family", "kind", "tasks", "agent", "seeds", "mean score [95% CI]"]
    return markdown_table(
        head,
        [
            [
                r["set"],
                r["family"],
                r["kind"],
                str(r["tasks"]),
                r["agent"],
                str(r["seeds"]),
                _ci(r["score"], r["lo"], r["hi"]),
            ]
            for r in families
        ],
    )


def _plot(aggregates: list[dict[str, Any]], file: Path) -> None:
    """IQM and mean with their CIs: one row per set and agent, the sets stacked."""
    agents = list(dict.fromkeys(r["agent"] for r in aggregates))
    colors = {a: f"C{i}" for i, a in enumerate(agents)}
    height = max(2.5, 0.35 * len(aggregates) + 1.5)
    with figure(file, 1, 2, figsize=(10, height), sharey=True) as (_, axes):
        for ax, metric, title in zip(axes, ("iqm", "mean"), ("IQM", "Mean"), strict=True):
            for y, r in enumerate(aggregates):
                lo, hi = r[f"{metric}_lo"], r[f"{metric}_hi"]
                ax.errorbar(
                    r[metric],
                    y,
                    xerr=[[r[metric] - lo], [hi - r[metric]]],
                    fmt="o",
                    color=colors[r["agent"]],
                    capsize=3,
                )
            ax.axvline(0.0, color="grey", lw=0.8, ls=":")
            ax.axvline(1.0, color="grey", lw=0.8, ls=":")
            ax.set_title(f"{title} of normalised scores (95% CI)")
            ax.set_xlabel("normalised score (0: uniform random, 1: best)")
            ax.grid(alpha=0.3, axis="x")
        axes[0].set_yticks(range(len(aggregates)))
        axes[0].set_yticklabels([f"{r['set']}: {r['agent']}" for r in aggregates])
        axes[0].invert_yaxis()


def command(study: dict[str, Any], out: Path) -> str:
    """The command line that runs the study saved in ``study`` (a study.json) into ``out``."""
    settings = runner.settings_of(STUDY, study)
    quick = settings.fraction == QUICK.fraction and settings.fraction != FULL.fraction
    base = QUICK if quick else FULL
    names = ("set", "families", "seeds", "steps", "agents")
    return runner.command_line("suite", settings, base, names, quick, out)


def _references(study: SuiteConfig) -> str:
    head = ["set", "family", "kind", "task", "budget (steps)", "random (0)", "best (1)"]
    rows = [
        [
            f.set,
            f.name,
            f.kind,
            f"`{t.env}`",
            f"{budget(t, study):,}",
            f"{fmt(t.random.value)} ({t.random.source})",
            f"{fmt(t.best.value)} ({t.best.source})",
        ]
        for f in families_of(study)
        for t in f.tasks
    ]
    return markdown_table(head, rows)


_PROTOCOL = (
    "Protocol (SPEC section 6): defaults are chosen on the selection set and confirmed on the "
    "validation set, which never chooses. A candidate default is compared with the others on the "
    "selection set by one aggregate, the IQM of normalised scores with its stratified bootstrap "
    "CI; it is accepted only if it does not lose on the validation set. Every family sits wholly "
    "in one set. Every agent runs with the library's defaults for the task (the `auto` preset and "
    "the agent's own overrides from suite.yaml): no per-task tuning."
)
_SCORE = (
    "A run's return is the mean training episodic return over the last 10% of its episodes (at "
    "least one); its score is `(return - random) / (best - random)`: 0 is the uniform random "
    "policy's expected return and 1 the optimal or best known one (the references table gives "
    "each number's source). The aggregate runs over tasks x seeds, with 95% stratified bootstrap "
    f"CIs (seeds resampled within each task; {BOOTSTRAP_RESAMPLES:,} resamples, rliable's IQM: "
    "the mean of the middle 50% of the scores); a family's score is the mean over its tasks per "
    "seed, with a 95% percentile bootstrap CI over the seeds."
)


def _write_report(
    out: Path,
    study: dict[str, Any],
    rows: list[dict[str, Any]],
    aggregates: list[dict[str, Any]],
    families: list[dict[str, Any]],
) -> None:
    from farsighter.provenance import code_version

    settings = runner.settings_of(STUDY, study)
    chosen = families_of(settings)
    missing = [r for r in rows if not np.isfinite(r["score"])]
    version = code_version()
    drawn = version.get("commit", version.get("version", "?"))[:10]
    lines = [
        "# Exploration suite: normalised scores",
        "",
        f"Made by `{command(study, out)}`. Agents: {', '.join(settings.agents)}; seeds "
        f"{list(settings.seeds)}; {len(tasks(settings))} task(s) in {len(chosen)} family(ies) "
        f"(set: {settings.set}); {len(rows)} finished runs. Drawn by farsighter {drawn}"
        f"{' with uncommitted changes' if version.get('dirty') else ''}; the runs' code is on the "
        "last line.",
        "",
        _PROTOCOL,
        "",
        _SCORE,
        "",
        "## Aggregate",
        "",
        _aggregate_table(aggregates),
        "![aggregate](figures/aggregate.png)",
        "",
        "## Families",
        "",
        _families_table(families),
        "## Tasks and references",
        "",
        _references(settings),
    ]
    if missing:
        lines += [
            f"{len(missing)} run(s) finished no episode and have no score; they are left out.",
            "",
        ]
    lines += [f"Redraw from the saved runs with `farsighter suite --plot-only {out}`.", ""]
    (out / "report.md").write_text("\n".join(lines))


STUDY = runner.Study(
    kind="suite",
    description="The exploration suite with normalised scores (suite.yaml): families split into "
    "a selection set (defaults are chosen here) and a validation set (which confirms, never "
    "chooses); one aggregate, the IQM of normalised scores with stratified bootstrap CIs "
    "(rliable), per set and agent. Families: "
    + "; ".join(
        f"{name} set: {', '.join(f for f, fam in SUITE.families.items() if fam.set == name)}"
        for name in SETS
    )
    + ".",
    agents=SUITE.agents,
    full=FULL,
    quick=QUICK,
    run_config=run_config,
    write_outputs=write_outputs,
    run_files=("metrics.csv",),
    args=Args,
    check=_check,
    tasks=tasks,
)


def main(argv: Sequence[str]) -> int:
    """``farsighter suite ARGV``."""
    return runner.main(STUDY, argv)
