"""The robotics study (paper section 5.2, Figure 3 and Table 3), a thin script over the library.

Runs the four continuous agents (NAF, multi-step NAF, Bayesian NAF, Farsighter-NAF) for several
seeds on one MuJoCo task (:mod:`farsighter.studies.runner` runs the grid, resumes an interrupted
study and loads the saved runs), then draws the learning curves (greedy evaluation return, or
success rate for goal-conditioned tasks; mean and std band over seeds) and a table of the final
evaluation, mean +- std over seeds, with the paper's Table 3 beside it (Walker2D at 30k steps).
Everything is drawn from saved files, so ``--plot-only`` redraws it.
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import tyro

from farsighter.config import Config
from farsighter.errors import FarsighterError
from farsighter.plots import band, figure, finish_axes, markdown_table
from farsighter.studies import runner
from farsighter.studies.runner import Agent, Runs, StudyArgs, slug

AGENTS: tuple[Agent, ...] = (
    Agent("NAF", "naf"),
    Agent("Multi-step NAF", "knaf"),
    Agent("Bayesian NAF", "bnaf"),
    Agent("Farsighter", "farsighter-naf"),
)

# Table 3 of the paper: score on Walker2D after 30k steps, mean +- std.
PAPER_TABLE3: dict[str, dict[str, tuple[float, float]]] = {
    "Walker2d": {
        "NAF": (-75.8, 631.0),
        "Multi-step NAF": (-68.2, 649.0),
        "Bayesian NAF": (160.1, 493.0),
        "Farsighter": (230.2, 566.8),
    }
}


@dataclass(frozen=True)
class StudyConfig:
    """What a study runs; saved as study.json."""

    env: str = "Walker2d-v5"
    seeds: tuple[int, ...] = (1, 2, 3)
    steps: int = 30_000
    eval_every: int = 2_000
    eval_episodes: int = 5
    workers: int = 0  # 0: one per core
    agents: tuple[str, ...] = tuple(a.label for a in AGENTS)


QUICK = StudyConfig(seeds=(1, 2), steps=6_000, eval_every=1_000, eval_episodes=3)


def run_config(agent: Agent, study: StudyConfig, seed: int, run_dir: Path) -> Config:
    """The library's ``continuous`` preset (identical shared settings for the four agents, as
    the paper keeps them), with the study's budget and evaluation cadence."""
    return runner.run_config(
        agent,
        study.env,
        "continuous",
        seed,
        study.steps,
        run_dir,
        eval_every=study.eval_every,
        eval_episodes=study.eval_episodes,
        learning_starts=min(1_000, study.steps // 4),
        checkpoint_every=0,
    )


@dataclass(frozen=True)
class Args(StudyArgs):
    """The flags of ``farsighter robotics``: the shared ones and the task's."""

    env: Annotated[str | None, tyro.conf.arg(metavar="ID", help_behavior_hint="")] = None
    """Task: Walker2d-v5 (default), FetchPickAndPlace-v4, HandManipulateBlock-v1, any other id."""
    eval_every: Annotated[int | None, tyro.conf.arg(metavar="N", help_behavior_hint="")] = None
    """Steps between greedy evaluations (default: the study's, at most half of --steps)."""
    eval_episodes: Annotated[int | None, tyro.conf.arg(metavar="N", help_behavior_hint="")] = None
    """Episodes of each evaluation (default: the study's)."""


def _resolve(study: StudyConfig, args: Args) -> StudyConfig:
    if args.eval_every is None:  # at least two evaluations
        return replace(study, eval_every=min(study.eval_every, max(1, study.steps // 2)))
    return study


def _check(study: StudyConfig) -> None:
    for name, value in (("eval-every", study.eval_every), ("eval-episodes", study.eval_episodes)):
        if value < 1:
            raise FarsighterError(f"--{name} must be >= 1 (got {value})")
    from farsighter.envs import make_env

    make_env(run_config(AGENTS[0], study, 1, Path(".")), seed=0).close()  # a bad id fails here


def _name(study: StudyConfig) -> str:
    return "robotics-" + slug(study.env)


# ------------------------------------------------------------------------------------------------
# Outputs: everything below reads only saved files.
# ------------------------------------------------------------------------------------------------


def _goal(runs: Runs) -> bool:
    """A goal-conditioned task: every run recorded its evaluation success rate."""
    return all(r["eval_success"] is not None for items in runs.values() for r in items)


def _curve(items: list[dict[str, Any]], goal: bool) -> tuple[np.ndarray, np.ndarray]:
    """Steps and (seeds x evaluations) values of the greedy evaluation (return or success)."""
    key, column = ("eval_success", "eval_success_rate") if goal else ("eval", "eval_return_mean")
    n = min(len(r[key]["global_step"]) for r in items)
    steps = items[0][key]["global_step"][:n]
    return steps, np.array([r[key][column][:n] for r in items], dtype=float)


def _final(items: list[dict[str, Any]], key: str, column: str) -> tuple[float, float]:
    """Mean and std over seeds of the last evaluation's ``column``."""
    values = np.array([r[key][column][-1] for r in items])
    return float(values.mean()), float(values.std())


def summarise(study: dict[str, Any], runs: Runs) -> list[dict[str, Any]]:
    goal = _goal(runs)
    paper = PAPER_TABLE3.get(study["env"].split(":")[-1].split("-v")[0], {})
    rows = []
    for label, items in runs.items():
        ret = _final(items, "eval", "eval_return_mean")
        success = _final(items, "eval_success", "eval_success_rate") if goal else (np.nan,) * 2
        paper_mean, paper_std = paper.get(label, (float("nan"),) * 2)
        rows.append(
            {
                "agent": label,
                "seeds": len(items),
                "final_return_mean": ret[0],
                "final_return_std": ret[1],
                "final_success_mean": float(success[0]),
                "final_success_std": float(success[1]),
                "paper_mean": paper_mean,
                "paper_std": paper_std,
            }
        )
    return rows


def write_outputs(out: Path, study: dict[str, Any], runs: Runs) -> None:
    """Figure, table (CSV and Markdown) and report.md."""
    goal = _goal(runs)
    rows = summarise(study, runs)
    _plot(study, runs, goal, out / "figures" / "curves.png")
    with (out / "table.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    (out / "table.md").write_text(_markdown_table(rows, goal))
    _write_report(study, rows, goal, out)


def _plot(study: dict[str, Any], runs: Runs, goal: bool, file: Path) -> None:
    with figure(file, figsize=(7, 4.2)) as (_, ax):
        for i, (label, items) in enumerate(runs.items()):
            steps, values = _curve(items, goal)
            band(ax, steps, values, f"C{i}", label)
        finish_axes(
            ax,
            "environment steps",
            "evaluation success rate" if goal else "evaluation return",
            f"{study['env']}: mean ± std over {len(study['seeds'])} seeds",
        )


def _pm(mean: float, std: float, digits: int = 1) -> str:
    return "n/a" if not np.isfinite(mean) else f"{mean:.{digits}f} ± {std:.{digits}f}"


def _markdown_table(rows: list[dict[str, Any]], goal: bool) -> str:
    head = ["agent", "seeds", "final return (ours)", "paper Table 3 (30k steps)"]
    if goal:
        head.insert(2, "final success rate (ours)")
    table = []
    for r in rows:
        cells = [
            r["agent"],
            str(r["seeds"]),
            _pm(r["final_return_mean"], r["final_return_std"]),
            _pm(r["paper_mean"], r["paper_std"]),
        ]
        if goal:
            cells.insert(2, _pm(r["final_success_mean"], r["final_success_std"], 2))
        table.append(cells)
    return markdown_table(head, table)


def _claims(by: dict[str, float], measure: str) -> list[str]:
    """The paper's claims as report lines; a tie is "not decided", not a failure."""
    claims: list[str] = []
    top = max(by.values())
    leaders = [a for a, v in by.items() if v == top]
    if len(leaders) > 1:
        claims.append(
            f"- Best agent by final {measure} (paper: Farsighter): {', '.join(leaders)} tie at "
            f"{top:.3g}: not decided in this run."
        )
    else:
        claims.append(
            f"- Best agent by final {measure}: **{leaders[0]}** (paper: Farsighter). "
            + (
                "This holds in this run."
                if leaders[0] == "Farsighter"
                else "This does NOT hold here."
            )
        )
    if "Farsighter" in by and "Bayesian NAF" in by:
        f, b = by["Farsighter"], by["Bayesian NAF"]
        verdict = (
            "a tie: not decided in this run."
            if f == b
            else "holds in this run."
            if f > b
            else "does NOT hold in this run."
        )
        claims.append(
            "- Multi-step uncertainty (Farsighter) beats one-step (Bayesian NAF): "
            f"{f:.3g} vs {b:.3g}: {verdict}"
        )
    return claims


def _write_report(study: dict[str, Any], rows: list[dict[str, Any]], goal: bool, out: Path) -> None:
    key = "final_success_mean" if goal else "final_return_mean"
    by = {r["agent"]: r[key] for r in rows}
    measure = "success rate" if goal else "return"
    lines = [
        f"# Robotics study: {study['env']} (paper section 5.2, Figure 3, Table 3)",
        "",
        f"Agents: {', '.join(study['agents'])}; seeds {list(study['seeds'])}; "
        f"{study['steps']:,} environment steps each; greedy evaluation every "
        f"{study['eval_every']:,} steps over {study['eval_episodes']} episodes (noiseless mu, "
        "posterior-mean weights). Shared settings: the `continuous` preset "
        "(`farsighter presets`).",
        "",
    ]
    if goal:
        lines += [
            "Budget: the paper's Figure 3 trains the robotic tasks far longer (\"around 100 "
            'million steps" for FetchPickAndPlace to reach an almost 100% success rate). Well '
            "below that, success rates at the chance level (episodes whose goal starts where "
            "the object already is) are what to expect; compare budgets before results.",
            "",
        ]
    lines += [
        "## Table",
        "",
        "Final evaluation (mean ± std over seeds of each seed's mean evaluation "
        + ("success rate and return" if goal else "return")
        + "). The paper's Table 3 reports Walker2D after 30k steps; its ± is wide because it "
        "spans runs and episodes.",
        "",
        _markdown_table(rows, goal),
        "## Claims",
        "",
    ]
    lines += _claims(by, measure)
    lines += [
        "",
        "## Figure",
        "",
        "![learning curves](figures/curves.png)",
        "",
        f"Redraw from the saved runs with `farsighter robotics --plot-only {out}`.",
        "",
    ]
    (out / "report.md").write_text("\n".join(lines))


STUDY = runner.Study(
    kind="robotics",
    description="The continuous-control study of section 5.2 (Figure 3, Table 3).",
    agents=AGENTS,
    full=StudyConfig(),
    quick=QUICK,
    run_config=run_config,
    write_outputs=write_outputs,
    run_files=("eval.csv", "eval_success.csv"),
    args=Args,
    resolve=_resolve,
    check=_check,
    name=_name,
)


def main(argv: Sequence[str]) -> int:
    """``farsighter robotics ARGV``."""
    return runner.main(STUDY, argv)
