"""The sweep over k (paper section 5.3, Figure 4) and adaptive k (section 4.5).

Farsighter with k = 1, 10, 50, 150 and 500 and with adaptive k, on one or more environments
(default: the bridge maze with the maze study's ``maze`` preset and budget), several seeds each
(:mod:`farsighter.studies.runner` runs the agent x environment x seed grid, resumes an interrupted
study and loads the saved runs). Every agent runs with the same preset and differs only in k (and,
for adaptive k, in the adaptive-k settings). From each run's saved eval.csv it reads the final
greedy evaluation return, the area under the evaluation curve and whether the final greedy policy
solves the task; it draws the learning curves, the final score against k (Figure 4's shape), and
decides the paper's two claims (the score rises then falls with k; adaptive k is best) by the
bootstrap comparisons of :mod:`farsighter.studies.claims`. Everything is drawn from saved files,
so ``--plot-only`` redraws it. The sweep's k, the measures and the claims live in
:mod:`farsighter.studies.kstudy_measures` (re-exported here); this module writes the tables,
figures and report.
"""

from __future__ import annotations

import csv
import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import numpy as np

from farsighter.config import Config
from farsighter.envs.maze import ENV_ID
from farsighter.errors import FarsighterError
from farsighter.plots import band, figure, finish_axes, markdown_table
from farsighter.rundir import EVAL_SUCCESS_FILE
from farsighter.studies import maze, runner
from farsighter.studies.claims import CONFIDENCE, N_BOOT, VERDICT_TEXT, fmt
from farsighter.studies.kstudy_measures import (  # noqa: F401  (re-exported)
    ADAPTIVE,
    AUC,
    BEST,
    FASTEST,
    FINAL,
    FIRST,
    K_OF,
    KS,
    LAST,
    MAZE_SOLVED,
    SHAPE,
    Decided,
    Solved,
    adaptive_claims,
    area,
    claims,
    combine,
    per_run,
    shape_claim,
    solved_rule,
    summarise,
)
from farsighter.studies.runner import Agent, Runs, StudyArgs, Task

# Every agent is Farsighter with the same preset; a fixed-k agent sets k only.
AGENTS: tuple[Agent, ...] = (
    *(Agent(f"k={k}", "farsighter", {"k": k}) for k in KS),
    # Its settings depend on the environment (:func:`agent_for`).
    Agent(ADAPTIVE, "farsighter", {"adaptive_k.enabled": True}),
)

# Adaptive k on the bridge maze: the maze study's settings (k from 20 within [2, 40], Q-variance
# target 0.5, the buffer kept when k changes).
MAZE_ADAPTIVE: dict[str, Any] = dict(maze.STUDY.agent("Farsighter (adaptive k)").overrides)
# Elsewhere: the library's adaptive-k defaults (farsighter.config.AdaptiveKConfig), with Figure
# 4's range: from k = 10 (its smallest k) up to k_max = 500 (its largest).
DEFAULT_ADAPTIVE: dict[str, Any] = {"k": 10, "adaptive_k.enabled": True, "adaptive_k.k_max": 500}


def is_maze(env: str) -> bool:
    """The bridge maze of the maze study (it runs with the ``maze`` preset)."""
    return env == ENV_ID


def preset_for(env: str) -> str:
    """``maze`` on the bridge maze (as the maze study), ``auto`` elsewhere."""
    return "maze" if is_maze(env) else "auto"


def agent_for(agent: Agent, env: str) -> Agent:
    """The agent as it runs on ``env``: adaptive k takes the environment's settings."""
    if agent.label != ADAPTIVE:
        return agent
    return dataclasses.replace(agent, overrides=MAZE_ADAPTIVE if is_maze(env) else DEFAULT_ADAPTIVE)


@dataclass(frozen=True)
class StudyConfig:
    """What a study runs; saved as study.json."""

    envs: tuple[str, ...] = (ENV_ID,)
    seeds: tuple[int, ...] = (1, 2, 3, 4, 5)
    steps: int = maze.StudyConfig().steps  # every environment's budget: the maze study's
    workers: int = 0  # 0: one per core
    agents: tuple[str, ...] = tuple(a.label for a in AGENTS)


# About a minute on one core: the small end of the sweep and adaptive k, 2 seeds, a short budget.
QUICK = StudyConfig(seeds=(1, 2), steps=15_000, agents=("k=1", "k=10", ADAPTIVE))


@dataclass(frozen=True)
class Args(StudyArgs):
    """The flags of ``farsighter k-study``: the shared ones and the study's."""

    envs: Annotated[tuple[str, ...] | None, runner.study_flag("ENV [ENV ...]")] = None
    """Gymnasium ids with discrete actions (the bridge maze runs with the maze study's preset)."""
    steps: Annotated[int | None, runner.study_flag("N")] = None
    """Environment steps of each run, on every environment."""


def tasks(study: StudyConfig) -> tuple[Task, ...]:
    """(environment id, budget) per environment."""
    return tuple((env, study.steps) for env in study.envs)


def run_config(agent: Agent, study: StudyConfig, seed: int, run_dir: Path, task: Task) -> Config:
    """The environment's preset (:func:`preset_for`) and the agent's k (:func:`agent_for`). The
    same for every agent: at least 4 evaluations in a run (a shorter interval than the preset's
    only when the budget is short), and no checkpoint before the end, none with the replay (the
    study never resumes a run)."""
    env, steps = task
    agent = agent_for(agent, env)
    preset = preset_for(env)
    base = runner.run_config(agent, env, preset, seed, steps, run_dir)
    return runner.run_config(
        agent,
        env,
        preset,
        seed,
        steps,
        run_dir,
        eval_every=min(base.eval_every or steps, max(1, steps // 4)),
        checkpoint_every=0,
        save_replay=False,
    )


def _check(study: StudyConfig) -> None:
    if not study.envs:
        raise FarsighterError(f"--envs must name at least one environment (such as {ENV_ID})")
    if len(set(study.envs)) != len(study.envs):
        raise FarsighterError("--envs name an environment twice")
    if study.steps < 1:
        raise FarsighterError(f"--steps must be >= 1 (got {study.steps})")
    from farsighter.envs import make_env
    from farsighter.envs.factory import check_spaces

    for task in tasks(study):  # an unknown id, continuous actions or a missing extra fail here
        cfg = run_config(STUDY.agent("k=10"), study, 1, Path("."), task)
        env = make_env(cfg, seed=0)
        try:
            check_spaces(cfg.algo, env.observation_space, env.action_space)
        finally:
            env.close()
        if ADAPTIVE in study.agents:  # the fixed k are checked with every run's config
            adaptive = run_config(STUDY.agent(ADAPTIVE), study, 1, Path("."), task)
            per_env = adaptive.buffer_size // adaptive.num_envs
            if adaptive.adaptive_k.k_max > per_env:
                raise FarsighterError(
                    f"adaptive k on {task[0]}: k_max ({adaptive.adaptive_k.k_max}) exceeds the "
                    f"per-environment buffer ({per_env})"
                )


# ------------------------------------------------------------------------------------------------
# Outputs: tables, figures and report, from the saved files only.
# ------------------------------------------------------------------------------------------------

COLORS = {a.label: f"C{i}" for i, a in enumerate(AGENTS)}


def write_outputs(out: Path, study: dict[str, Any], runs: Runs) -> None:
    """table.csv and table.md (per environment x agent), figures/curves.png,
    figures/k_curve.png and report.md."""
    rows = summarise(runs)
    fields = [k for k in rows[0] if k != "per_seed"]
    with (out / "table.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=fields, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    (out / "table.md").write_text(_table(rows))
    _plot_curves(runs, out / "figures" / "curves.png")
    _plot_k_curve(rows, out / "figures" / "k_curve.png")
    _report(study, rows, out)


def _pm(mean: float, std: float) -> str:
    return f"{fmt(mean)} ± {fmt(std)}"


def _table(rows: list[dict[str, Any]]) -> str:
    head = [
        "env",
        "agent",
        "seeds",
        "final eval return",
        "area under the curve",
        "solved (seeds)",
        "final k",
    ]
    cells = [
        [
            f"`{r['env']}`",
            r["agent"],
            str(r["seeds"]),
            _pm(r["final_return_mean"], r["final_return_std"]),
            _pm(r["auc_mean"], r["auc_std"]),
            f"{r['solved_seeds']}/{r['seeds']} ({r['solved_fraction']:.0%})"
            if np.isfinite(r["solved_fraction"])
            else "n/a",
            fmt(r["final_k_mean"]),
        ]
        for r in rows
    ]
    return markdown_table(head, cells)


def _envs(runs: Runs) -> list[str]:
    return list(dict.fromkeys(r["task"] for items in runs.values() for r in items))


def _panels(n: int) -> tuple[int, int]:
    cols = min(3, n)
    return (n + cols - 1) // cols, cols


def _plot_curves(runs: Runs, file: Path) -> None:
    envs = _envs(runs)
    rows, cols = _panels(len(envs))
    with figure(file, rows, cols, figsize=(5 * cols, 3.6 * rows), squeeze=False) as (_, axes):
        for ax, env in zip(axes.flat, envs, strict=False):
            for label, items in runs.items():
                mine = [r for r in items if r["task"] == env and r["eval"]]
                if not mine:
                    continue
                n = min(len(r["eval"]["global_step"]) for r in mine)
                steps = mine[0]["eval"]["global_step"][:n]
                values = np.array([r["eval"]["eval_return_mean"][:n] for r in mine], dtype=float)
                band(ax, steps, values, COLORS.get(label), label)
            finish_axes(ax, "environment steps", "evaluation return", env)
        for ax in list(axes.flat)[len(envs) :]:
            ax.set_visible(False)


def _plot_k_curve(rows: list[dict[str, Any]], file: Path) -> None:
    from matplotlib.ticker import NullLocator

    envs = list(dict.fromkeys(r["env"] for r in rows))
    n_rows, cols = _panels(len(envs))
    with figure(file, n_rows, cols, figsize=(5 * cols, 3.6 * n_rows), squeeze=False) as (_, axes):
        for ax, env in zip(axes.flat, envs, strict=False):
            mine = [r for r in rows if r["env"] == env]
            fixed = [r for r in mine if r["agent"] in K_OF]
            if fixed:
                ks = [K_OF[r["agent"]] for r in fixed]
                ax.errorbar(
                    ks,
                    [r["final_return_mean"] for r in fixed],
                    yerr=[r["final_return_std"] for r in fixed],
                    fmt="o-",
                    color="C0",
                    capsize=5,
                    label="fixed k (mean ± std over seeds)",
                )
                ax.set_xscale("log")
                ax.set_xticks(ks, [str(k) for k in ks])
                ax.xaxis.set_minor_locator(NullLocator())
            for r in mine:
                if r["agent"] == ADAPTIVE:
                    mean, std = r["final_return_mean"], r["final_return_std"]
                    ax.axhline(mean, color="C3", ls="--", label="adaptive k (mean ± std)")
                    ax.axhspan(mean - std, mean + std, color="C3", alpha=0.15)
            finish_axes(ax, "k (log scale)", "final evaluation return", env)
        for ax in list(axes.flat)[len(envs) :]:
            ax.set_visible(False)


def command(study: dict[str, Any], out: Path) -> str:
    """The command line that runs the study saved in ``study`` (a study.json) into ``out``."""
    settings = runner.settings_of(STUDY, study)
    quick = dataclasses.replace(settings, workers=0) == QUICK
    base = QUICK if quick else StudyConfig()
    names = ("envs", "seeds", "steps", "agents")
    return runner.command_line("k-study", settings, base, names, quick, out)


def _setup(envs: Sequence[str]) -> list[str]:
    """What each environment runs with: its preset, adaptive k's settings, the solved rule."""
    lines = []
    for env in envs:
        adaptive = agent_for(STUDY.agent(ADAPTIVE), env).overrides
        settings = ", ".join(
            f"{key.removeprefix('adaptive_k.')} = {value}"
            for key, value in adaptive.items()
            if key != "adaptive_k.enabled"
        )
        origin = "the maze study's" if is_maze(env) else "the library's defaults, with"
        rule = solved_rule(env)
        solved = (
            f"solved when the final evaluation {'success rate' if rule.success else 'return'} "
            f"is {rule.comparison()} ({rule.text})"
            if rule
            else "no solved threshold known (solved: n/a)"
        )
        lines.append(
            f"- `{env}`: preset `{preset_for(env)}`; adaptive k: {origin} {settings}; {solved}."
        )
    return lines


_TABLE_NOTE = (
    "*Final eval return*: the mean return of the run's last greedy evaluation (after the last "
    "training step), mean ± std over seeds. *Area under the curve*: the area under the run's "
    "evaluation curve divided by the steps it spans (its mean height, in return units; higher "
    "means it got good sooner), mean ± std over seeds. *Solved*: seeds whose final evaluation "
    "meets the environment's rule above. *Final k*: k in the run's last training episode (mean "
    "over seeds; it moves only for adaptive k)."
)
_STATISTIC_NOTE = (
    "Each comparison takes one agent against one other on per-seed values: the difference of the "
    f"two groups' means, with a {CONFIDENCE:.0%} percentile bootstrap confidence interval "
    f"({N_BOOT:,} resamples; the seeds of each group resampled independently, with replacement), "
    "as the maze study decides its claims. A comparison **holds** when the whole interval lies "
    "above 0, **does not hold** when it lies wholly below 0 or is exactly [0, 0] (the groups do "
    "not differ at all), and is **undecided at this budget** when the interval contains 0, and "
    "always when a group has fewer than 2 seeds. Claim (1) holds when both of its comparisons "
    "hold, does not hold when either does not, and is otherwise undecided. The best k of a "
    "claim is picked by the same seeds' means: in (1) this favours the claim (a chosen best "
    "interior k is likelier to look better than an end), so a *holds* there is weaker evidence "
    "than a comparison fixed in advance; in (2) it works against adaptive k."
)


def _claim_lines(decided: Sequence[Decided]) -> list[str]:
    lines = []
    for number, d in zip(("(1)", "(2a)", "(2b)"), decided, strict=True):
        lines.append(f"- {number} **{d.claim}.** {d.note}: **{VERDICT_TEXT[d.verdict]}**.")
        lines += [f"  - {c.claim}: {c.evidence}: {VERDICT_TEXT[c.verdict]}." for c in d.parts]
    return lines


def _report(study: dict[str, Any], rows: list[dict[str, Any]], out: Path) -> None:
    envs = list(dict.fromkeys(r["env"] for r in rows))
    lines = [
        "# The sweep over k (paper section 5.3, Figure 4; adaptive k, section 4.5)",
        "",
        f"Made by `{command(study, out)}`. Agents: {', '.join(study['agents'])}; seeds "
        f"{list(study['seeds'])}; {study['steps']:,} environment steps per run.",
        "",
        "Every agent is Farsighter with the same preset, differing only in k: a fixed k, or "
        "adaptive k (section 4.5: after each posterior refresh k grows by one when the "
        "Q-variance is below a target and shrinks by one when above). The paper (Fig. 4, "
        "Montezuma's Revenge) finds the score rising with k and then falling, best at k = 150, "
        "and adaptive k best of all, rising fastest early and finishing highest.",
        "",
        *_setup(envs),
        "",
        "## Table",
        "",
        _TABLE_NOTE,
        "",
        _table(rows),
        "## The paper's claims, checked",
        "",
        _STATISTIC_NOTE,
        "",
    ]
    for env, decided in claims(rows).items():
        lines += [f"### `{env}`", "", *_claim_lines(decided), ""]
    lines += [
        "## Figures",
        "",
        "Evaluation return over training (mean ± std over seeds):",
        "",
        "![learning curves](figures/curves.png)",
        "",
        "Final evaluation return against k (Fig. 4's shape; adaptive k dashed, its band one std):",
        "",
        "![final score against k](figures/k_curve.png)",
        "",
        f"Redraw from the saved runs with `farsighter k-study --plot-only {out}`.",
        "",
    ]
    (out / "report.md").write_text("\n".join(lines))


STUDY = runner.Study(
    kind="k-study",
    description="The sweep over k (paper section 5.3, Figure 4) with adaptive k (section 4.5): "
    "Farsighter at k = 1, 10, 50, 150, 500 and adaptive k, the same preset otherwise, on the "
    "bridge maze or any Gymnasium environment with discrete actions. --quick takes about a "
    "minute on one core.",
    agents=AGENTS,
    full=StudyConfig(),
    quick=QUICK,
    run_config=run_config,
    write_outputs=write_outputs,
    run_files=("eval.csv", "metrics.csv", EVAL_SUCCESS_FILE),  # the last: is_success tasks only
    args=Args,
    check=_check,
    tasks=tasks,
)


def main(argv: Sequence[str]) -> int:
    """``farsighter k-study ARGV``."""
    return runner.main(STUDY, argv)
