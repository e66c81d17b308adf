"""The exploration suite: how the episodes an agent needs to solve a task grow with its size.

Task families with a size knob (:data:`FAMILIES`: the combination-lock chain, MiniGrid DoorKey,
KeyCorridor and MultiRoom, and MountainCar), every agent with one config for all of them (the
library's ``auto`` preset and the agent's own overrides: no per-task tuning), several seeds each
(:mod:`farsighter.studies.runner` runs the agent x task x seed grid, resumes an interrupted study
and loads the saved runs). Per run it measures from the saved metrics.csv and eval.csv whether and
when a greedy evaluation first reached the family's threshold; per family and agent it fits the
growth of the episodes to solve against the size, polynomial and exponential. Everything is
drawn from saved files, so ``--plot-only`` redraws it.
"""

from __future__ import annotations

import csv
import dataclasses
import shlex
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import numpy as np

from farsighter.config import Config
from farsighter.envs.chain import SOLVED_RETURN, chain_id
from farsighter.errors import FarsighterError
from farsighter.studies import runner
from farsighter.studies.claims import fmt
from farsighter.studies.runner import Agent, Runs, StudyArgs, Task, figure


@dataclass(frozen=True)
class Family:
    """Tasks of one kind at growing sizes, and how a run on them is measured."""

    size: str
    """What the size is (the figures' x axis)."""
    sizes: tuple[int, ...]
    env_ids: tuple[str, ...]
    """The environment id of each size."""
    budgets: tuple[int, ...]
    """Environment steps of a run at each size."""
    threshold: float
    """Solved: a greedy evaluation's mean return is at least this."""
    solved: str
    """What reaching the threshold means (the report)."""
    goal: float
    """A training episode whose return is above this reached the reward (first-reward column)."""
    eval_every: int
    eval_episodes: int

    def task(self, size: int) -> Task:
        i = self.sizes.index(size)
        return self.env_ids[i], self.budgets[i]


CHAIN_SIZES = (5, 10, 20, 30, 50)
_MINIGRID_SOLVED = (
    "MiniGrid pays 1 - 0.9 t/T for reaching the goal at step t of its step limit T and 0 "
    "otherwise, so a mean of 0.5 needs the goal reached in more than half of the evaluation "
    "episodes"
)


def _minigrid(
    size: str, sizes: tuple[int, ...], ids: tuple[str, ...], budgets: tuple[int, ...]
) -> Family:
    """A MiniGrid family: solved at a mean return of 0.5, 10 evaluation episodes every 10k
    steps; a training episode with any reward reached the goal."""
    return Family(size, sizes, ids, budgets, 0.5, _MINIGRID_SOLVED, 0.0, 10_000, 10)


FAMILIES: dict[str, Family] = {
    "chain": Family(
        size="chain length L",
        sizes=CHAIN_SIZES,
        env_ids=tuple(chain_id(n) for n in CHAIN_SIZES),
        budgets=tuple(max(10_000, 1_000 * n) for n in CHAIN_SIZES),
        threshold=SOLVED_RETURN,
        solved="the greedy episode reached the end of the chain (return 0.99; every other "
        "return is at most 0)",
        goal=SOLVED_RETURN,
        eval_every=100,  # one deterministic episode of at most L + 1 steps: cheap
        eval_episodes=1,
    ),
    "doorkey": _minigrid(
        "grid side",
        (5, 6, 8),
        tuple(f"MiniGrid-DoorKey-{n}x{n}-v0" for n in (5, 6, 8)),
        (100_000, 250_000, 1_000_000),
    ),
    "keycorridor": _minigrid(
        "rows R",
        (1, 2, 3),
        tuple(f"MiniGrid-KeyCorridorS3R{n}-v0" for n in (1, 2, 3)),
        (100_000, 300_000, 1_000_000),
    ),
    "multiroom": _minigrid(
        "rooms N",
        (2, 4, 6),
        ("MiniGrid-MultiRoom-N2-S4-v0", "MiniGrid-MultiRoom-N4-S5-v0", "MiniGrid-MultiRoom-N6-v0"),
        (100_000, 1_000_000, 2_000_000),
    ),
    "mountaincar": Family(
        size="size (one)",
        sizes=(1,),
        env_ids=("MountainCar-v0",),
        budgets=(200_000,),
        threshold=-199.0,
        solved="the reward is -1 a step until the flag and an episode ends at 200 steps, so one "
        "that never reaches the flag returns -200: a mean of -199 or more means the car reached "
        "the flag in the evaluation episodes, on average at least one step before the 200-step "
        "limit",
        goal=-200.0,
        eval_every=5_000,
        eval_episodes=5,
    ),
}

TASKS: dict[str, tuple[str, int]] = {
    env: (name, size)
    for name, family in FAMILIES.items()
    for size, env in zip(family.sizes, family.env_ids, strict=True)
}
"""Environment id -> (family, size)."""

# One config per agent for every task and size: the `auto` preset and these overrides only.
AGENTS: tuple[Agent, ...] = (
    Agent("DDQN", "ddqn"),
    Agent("k-DDQN", "kddqn"),
    Agent("BDQN", "bdqn"),
    # the library's default: a draw per step (Algorithm 2) since the DoorKey runs; per episode when
    # docs/results/explore/report.md (the chain) was made, so there "Farsighter" is per episode
    Agent("Farsighter", "farsighter"),
    Agent("Farsighter (redraw step)", "farsighter", {"blr.redraw": "step"}),
    Agent("Farsighter (redraw k)", "farsighter", {"blr.redraw": "k"}),
    Agent("Farsighter (redraw episode)", "farsighter", {"blr.redraw": "episode"}),
    Agent("OB2I", "ob2i"),
    Agent("RND", "rnd"),
)
COLORS = {a.label: f"C{i}" for i, a in enumerate(AGENTS)}
DEFAULT_AGENTS = tuple(a.label for a in AGENTS if a.label != "Farsighter (redraw step)")
"""The default list: every agent once. "Farsighter (redraw step)" builds the same config as
"Farsighter" now that a draw per step is the default, so it is left out unless named (the saved
studies in docs/results name it)."""


@dataclass(frozen=True)
class StudyConfig:
    """What a study runs; saved as study.json."""

    families: tuple[str, ...] = tuple(FAMILIES)
    sizes: tuple[int, ...] = ()  # empty: every size of each family
    seeds: tuple[int, ...] = (1, 2, 3, 4, 5)
    steps: int = 0  # 0: each task's own budget; otherwise a cap on every budget
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
    families: Annotated[tuple[str, ...] | None, runner.study_flag("NAME [NAME ...]")] = None
    """Task families: chain, doorkey, keycorridor, multiroom, mountaincar."""
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
                out.append((env, min(budget, study.steps) if study.steps else budget))
    return tuple(out)


def run_config(agent: Agent, study: StudyConfig, seed: int, run_dir: Path, task: Task) -> Config:
    """The library's default for the task (``auto``) and the agent's overrides; the family's
    evaluation settings and no replay in the final checkpoint (measurement, not tuning)."""
    env, steps = task
    family = FAMILIES[TASKS[env][0]]
    return runner.run_config(
        agent,
        env,
        "auto",
        seed,
        steps,
        run_dir,
        eval_every=family.eval_every,
        eval_episodes=family.eval_episodes,
        checkpoint_every=0,
        save_replay=False,  # a MiniGrid run's replay is gigabytes; the study never resumes one
        log_every=max(family.eval_every, 1_000),
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
    from farsighter.config import make_config
    from farsighter.envs import make_env

    for env, _ in tasks(study):  # a missing extra (minigrid) fails here, before any run
        make_env(make_config("ddqn", env), seed=0).close()


# ------------------------------------------------------------------------------------------------
# Measures: per run, then per family x size x agent, then the growth per family x agent.
# ------------------------------------------------------------------------------------------------


def measure(run: dict[str, Any], threshold: float, goal: float) -> dict[str, Any]:
    """One run's measures from its metrics.csv and eval.csv (NaN where a run never got there).

    solved: some evaluation's mean return reached ``threshold``; episodes_to_solve and
    steps_to_solve: the training episodes finished and the step at the first such evaluation;
    held: the final evaluation is at the threshold; episodes_to_first_reward: the first training
    episode whose return is above ``goal``; episodes: training episodes in all.
    """
    m, e = run["metrics"] or {}, run["eval"] or {}
    ep_steps = m.get("global_step", np.array([]))
    returns = m.get("episodic_return", np.array([]))
    ev_steps = e.get("global_step", np.array([]))
    ev = e.get("eval_return_mean", np.array([]))
    hit = np.flatnonzero(ev >= threshold)
    first = float(ev_steps[hit[0]]) if len(hit) else float("nan")
    reward = np.flatnonzero(returns > goal)
    return {
        "solved": bool(len(hit)),
        "episodes_to_solve": float(np.sum(ep_steps <= first)) if len(hit) else float("nan"),
        "steps_to_solve": first,
        "held": bool(len(ev) and ev[-1] >= threshold),
        "episodes_to_first_reward": float(reward[0] + 1) if len(reward) else float("nan"),
        "episodes": len(returns),
    }


def censored_median(values: Sequence[float], censored: Sequence[bool]) -> tuple[float, bool]:
    """The median of ``values`` where a censored value is a lower bound (the run ended first),
    and whether the median is itself only a lower bound (raising the censored values would
    raise it)."""
    v, c = np.asarray(values, dtype=float), np.asarray(censored, dtype=bool)
    median = float(np.median(v))
    return median, float(np.median(np.where(c, np.inf, v))) != median


def per_run(runs: Runs) -> list[dict[str, Any]]:
    """One row per finished run: where it ran and its :func:`measure`."""
    rows = []
    for label, items in runs.items():
        for run in items:
            name, size = TASKS[run["task"]]
            family = FAMILIES[name]
            rows.append(
                {
                    "family": name,
                    "size": size,
                    "env": run["task"],
                    "agent": label,
                    "seed": run["seed"],
                    "budget": run["steps"],
                    **measure(run, family.threshold, family.goal),
                }
            )
    return rows


def summarise(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per family x size x agent (families and agents in their order in ``rows``, sizes
    ascending): seeds solved and held, and the median episodes and steps to solve with unsolved
    seeds censored at the run's end."""
    families = list(dict.fromkeys(r["family"] for r in rows))
    agents = list(dict.fromkeys(r["agent"] for r in rows))
    cells: dict[tuple[str, int, str], list[dict[str, Any]]] = {}
    for r in sorted(
        rows, key=lambda r: (families.index(r["family"]), r["size"], agents.index(r["agent"]))
    ):
        cells.setdefault((r["family"], r["size"], r["agent"]), []).append(r)
    table = []
    for (family, size, agent), rs in cells.items():
        unsolved = [not r["solved"] for r in rs]
        episodes = [r["episodes"] if not r["solved"] else r["episodes_to_solve"] for r in rs]
        steps = [r["budget"] if not r["solved"] else r["steps_to_solve"] for r in rs]
        no_reward = [not np.isfinite(r["episodes_to_first_reward"]) for r in rs]
        first = [
            r["episodes"] if c else r["episodes_to_first_reward"]
            for r, c in zip(rs, no_reward, strict=True)
        ]
        med_ep, ep_cens = censored_median(episodes, unsolved)
        med_st, st_cens = censored_median(steps, unsolved)
        med_fr, fr_cens = censored_median(first, no_reward)
        table.append(
            {
                "family": family,
                "size": size,
                "env": rs[0]["env"],
                "budget": rs[0]["budget"],
                "agent": agent,
                "seeds": len(rs),
                "seeds_solved": sum(r["solved"] for r in rs),
                "seeds_held": sum(r["held"] for r in rs),
                "median_episodes_to_solve": med_ep,
                "episodes_censored": ep_cens,
                "median_steps_to_solve": med_st,
                "steps_censored": st_cens,
                "median_episodes_to_first_reward": med_fr,
                "first_reward_censored": fr_cens,
            }
        )
    return table


def _line(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Least-squares slope of y on x, and R^2 (NaN where y does not vary)."""
    slope, intercept = np.polyfit(x, y, 1)
    ss_res = float(np.sum((y - (slope * x + intercept)) ** 2))
    ss_tot = float(np.sum((y - y.mean()) ** 2))
    return float(slope), 1.0 - ss_res / ss_tot if ss_tot > 1e-12 else float("nan")


MIN_SIZES = 3


def fit_growth(sizes: Sequence[float], episodes: Sequence[float]) -> dict[str, Any]:
    """Episodes against size: polynomial, log(episodes) = p log(size) + c, and exponential,
    log(episodes) = r size + c, by least squares, each with its R^2, and which fits better
    (higher R^2). Fewer than :data:`MIN_SIZES` sizes: "not enough sizes". Episodes below 1 count
    as 1."""
    x, y = np.asarray(sizes, dtype=float), np.log(np.maximum(np.asarray(episodes, float), 1.0))
    nan = float("nan")
    if len(x) < MIN_SIZES:
        return {
            "n_sizes": len(x),
            "p": nan,
            "r2_poly": nan,
            "r": nan,
            "r2_exp": nan,
            "better": "not enough sizes",
        }
    p, r2_poly = _line(np.log(x), y)
    r, r2_exp = _line(x, y)
    better = "polynomial" if r2_poly > r2_exp else "exponential" if r2_exp > r2_poly else "neither"
    return {
        "n_sizes": len(x),
        "p": p,
        "r2_poly": r2_poly,
        "r": r,
        "r2_exp": r2_exp,
        "better": better,
    }


def growth(table: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per family x agent: :func:`fit_growth` of the (censored) median episodes to solve over
    the sizes where at least one seed solved."""
    out = []
    for family, agent in dict.fromkeys((r["family"], r["agent"]) for r in table):
        rows = [r for r in table if (r["family"], r["agent"]) == (family, agent)]
        solved = [r for r in rows if r["seeds_solved"] > 0]
        fit = fit_growth(
            [r["size"] for r in solved], [r["median_episodes_to_solve"] for r in solved]
        )
        out.append({"family": family, "agent": agent, **fit})
    return out


# ------------------------------------------------------------------------------------------------
# Outputs: tables, figures and report, from the saved files only.
# ------------------------------------------------------------------------------------------------


def write_outputs(out: Path, study: dict[str, Any], runs: Runs) -> None:
    """runs.csv (per run), table.csv (per family x size x agent), growth.csv (per family x
    agent), table.md, one figure per family and report.md."""
    rows = per_run(runs)
    table = summarise(rows)
    fits = growth(table)
    for name, data in (("runs", rows), ("table", table), ("growth", fits)):
        with (out / f"{name}.csv").open("w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=list(data[0]))
            writer.writeheader()
            writer.writerows(data)
    (out / "table.md").write_text(_markdown_table(table) + "\n" + _markdown_growth(fits))
    for family in dict.fromkeys(r["family"] for r in table):
        _plot(family, table, fits, out / "figures" / f"{family}.png")
    _write_report(out, study, table, fits)


def _median(value: float, censored: bool) -> str:
    return (">" if censored else "") + fmt(float(value))


def _markdown_table(table: list[dict[str, Any]]) -> str:
    head = [
        "family",
        "size",
        "budget",
        "agent",
        "solved",
        "held",
        "median episodes to solve",
        "median steps to solve",
        "median episodes to first reward",
    ]
    cells = [
        [
            r["family"],
            str(r["size"]),
            f"{r['budget']:,}",
            r["agent"],
            f"{r['seeds_solved']}/{r['seeds']}",
            f"{r['seeds_held']}/{r['seeds']}",
            _median(r["median_episodes_to_solve"], r["episodes_censored"]),
            _median(r["median_steps_to_solve"], r["steps_censored"]),
            _median(r["median_episodes_to_first_reward"], r["first_reward_censored"]),
        ]
        for r in table
    ]
    return runner.markdown_table(head, cells)


def _fit_text(fit: dict[str, Any], key: str) -> str:
    r2 = fit["r2_poly" if key == "p" else "r2_exp"]
    return f"{key} = {fmt(fit[key])} (R² {fmt(r2)})"


def _markdown_growth(fits: list[dict[str, Any]]) -> str:
    head = [
        "family",
        "agent",
        "sizes fitted",
        "polynomial exponent p",
        "exponential rate r",
        "fits better",
    ]
    cells = []
    for f in fits:
        fitted = f["better"] != "not enough sizes"
        p, r = (_fit_text(f, "p"), _fit_text(f, "r")) if fitted else ("", "")
        cells.append([f["family"], f["agent"], str(f["n_sizes"]), p, r, f["better"]])
    return runner.markdown_table(head, cells)


def _plot(family: str, table: list[dict[str, Any]], fits: list[dict[str, Any]], file: Path) -> None:
    from matplotlib.ticker import NullLocator

    fam = FAMILIES[family]
    rows = [r for r in table if r["family"] == family]
    with figure(file, 1, 2, figsize=(11, 4.2)) as (_, (ax0, ax1)):
        for agent in dict.fromkeys(r["agent"] for r in rows):
            mine = [r for r in rows if r["agent"] == agent]
            color = COLORS.get(agent)
            x = np.array([r["size"] for r in mine], dtype=float)
            ax0.plot(
                x, [r["seeds_solved"] / r["seeds"] for r in mine], "o-", color=color, label=agent
            )
            solved = [r for r in mine if r["seeds_solved"] > 0]
            for r in solved:  # a censored median (a lower bound) is an open marker
                face = "none" if r["episodes_censored"] else color
                ax1.plot(r["size"], r["median_episodes_to_solve"], "o", color=color, mfc=face)
            fit = next(f for f in fits if (f["family"], f["agent"]) == (family, agent))
            if fit["better"] != "not enough sizes":
                xs = np.array([r["size"] for r in solved], dtype=float)
                ys = np.log([max(r["median_episodes_to_solve"], 1.0) for r in solved])
                c = np.mean(ys - fit["p"] * np.log(xs))
                grid = np.geomspace(xs.min(), xs.max(), 50)
                ax1.plot(
                    grid,
                    np.exp(c) * grid ** fit["p"],
                    "--",
                    color=color,
                    lw=1,
                    label=f"{agent}: p = {fit['p']:.2g}",
                )
            elif solved:
                ax1.plot([], [], "o", color=color, label=agent)
        ax0.set_ylim(-0.05, 1.05)
        runner.finish_axes(ax0, fam.size, "fraction of seeds solved", f"{family}: solved")
        ax1.set_xscale("log")
        ax1.set_yscale("log")
        sizes = sorted({r["size"] for r in rows})
        for ax in (ax0, ax1):  # ticks at the sizes run
            ax.set_xticks(sizes, [str(s) for s in sizes])
            ax.xaxis.set_minor_locator(NullLocator())
        ax1.set_xlabel(fam.size)
        ax1.set_ylabel("median training episodes to solve")
        ax1.set_title(f"{family}: episodes to solve (open: lower bound),\npolynomial fit dashed")
        if ax1.get_legend_handles_labels()[0]:  # nothing to list where no seed solved
            ax1.legend(fontsize=8)
        ax1.grid(alpha=0.3)


_TEXT_HEAD = (
    "Each agent runs with one config on every task and size: the library's default for the task "
    "(`preset=auto`) and its own overrides, nothing tuned per task. A run **solved** a task when "
    "some greedy evaluation's mean return reached the family's threshold; *episodes to solve* "
    "counts the training episodes finished at the first such evaluation (*steps to solve* "
    "likewise), so its resolution is the evaluation interval. *Held*: the final evaluation is at "
    "the threshold. *First reward*: the first training episode whose return shows the reward was "
    "reached. An unsolved seed counts as its run's total (episodes, steps): a censored value, so a "
    "median marked `>` is a lower bound."
)
_GROWTH_NOTE = (
    "Growth of the median episodes to solve against the size, over the sizes where at least one "
    "seed solved (at least 3 such sizes, else *not enough sizes*): least-squares fits of "
    "log(episodes) on log(size) (polynomial, exponent p) and on size (exponential, rate r), with "
    "their R²; the one with the higher R² fits better. The medians include censored seeds, so an "
    "agent that fails at a size enters the fit with a lower bound there, and its true growth is "
    "at least as steep. With three sizes both fits can have a high R²: read the two together."
)


def command(study: dict[str, Any], out: Path) -> str:
    """The command line that runs the study saved in ``study`` (a study.json) into ``out``."""
    settings = runner.settings_of(STUDY, study)
    line = ["farsighter", "explore"]
    if dataclasses.replace(settings, workers=0) == QUICK:
        line.append("--quick")
    else:
        for name in ("families", "sizes", "seeds", "steps", "agents"):
            value = getattr(settings, name)
            if value != getattr(StudyConfig(), name):
                values = value if isinstance(value, tuple) else (value,)
                line += [f"--{name}", *map(str, values)]
    return shlex.join([*line, "--out", str(out)])


def _claims(table: list[dict[str, Any]], fits: list[dict[str, Any]]) -> list[str]:
    """Per family: does Farsighter's growth look polynomial where DDQN's looks exponential (or
    DDQN fails where Farsighter solves)? Then the agent that solved the most (family, size)."""
    lines = []
    fit = {(f["family"], f["agent"]): f for f in fits}
    for family in dict.fromkeys(r["family"] for r in table):
        rows = [r for r in table if r["family"] == family]
        head = f"- **{family}**: "
        if not {"Farsighter", "DDQN"} <= {r["agent"] for r in rows}:
            lines.append(head + "not tested: needs both the Farsighter and the DDQN agent.")
            continue
        f, d = fit[family, "Farsighter"], fit[family, "DDQN"]
        by = {(r["agent"], r["size"]): r for r in rows}
        sizes = sorted({r["size"] for r in rows})
        if len(sizes) < MIN_SIZES:
            lines.append(head + f"not tested: {len(sizes)} size(s) in this study (needs 3).")
            continue
        fails = [
            s
            for s in sizes
            if by["Farsighter", s]["seeds_solved"] and not by["DDQN", s]["seeds_solved"]
        ]
        fails_text = (
            "DDQN solves no seed at size(s) "
            + ", ".join(
                f"{s} (Farsighter {by['Farsighter', s]['seeds_solved']}/"
                f"{by['Farsighter', s]['seeds']})"
                for s in fails
            )
            if fails
            else "DDQN solves a seed at every size where Farsighter does"
        )
        f_poly = f["better"] == "polynomial"
        d_exp = d["better"] == "exponential"
        evidence = f"Farsighter: {_fit_desc(f)}; DDQN: {_fit_desc(d)}; {fails_text}"
        if f_poly and (d_exp or fails):
            ddqn = "DDQN's grow exponentially" if d_exp else "DDQN fails at sizes Farsighter solves"
            lines.append(
                head + f"shown: Farsighter's episodes to solve grow polynomially while {ddqn}. "
                f"{evidence}."
            )
        else:
            if f["better"] == "not enough sizes":
                why = f"Farsighter solves a seed at fewer than {MIN_SIZES} sizes"
            elif not f_poly:
                why = "Farsighter's growth does not fit a polynomial better than an exponential"
            else:
                why = "DDQN's growth does not fit an exponential better and DDQN solves a seed "
                why += "wherever Farsighter does"
            lines.append(head + f"not shown: {why}. {evidence}.")
    lines.append(_most_solved(table))
    return lines


def _fit_desc(fit: dict[str, Any]) -> str:
    if fit["better"] == "not enough sizes":
        return f"not enough sizes ({fit['n_sizes']} solved by a seed)"
    return f"{_fit_text(fit, 'p')}, {_fit_text(fit, 'r')}, {fit['better']} fits better"


def _most_solved(table: list[dict[str, Any]]) -> str:
    """The agent(s) with the most (family, size) pairs solved by more than half of the seeds."""
    count: dict[str, int] = {}
    for r in table:
        count[r["agent"]] = count.get(r["agent"], 0) + int(2 * r["seeds_solved"] > r["seeds"])
    top = max(count.values())
    leaders = [a for a, n in count.items() if n == top]
    tally = ", ".join(f"{a} {n}" for a, n in sorted(count.items(), key=lambda kv: -kv[1]))
    pairs = len({(r["family"], r["size"]) for r in table})
    if top == 0:
        return f"- No agent solved any of the {pairs} (family, size) pairs in most of its seeds."
    return (
        f"- Most (family, size) pairs solved by more than half of the seeds: "
        f"{' and '.join(f'**{a}**' for a in leaders)} with {top} of {pairs} ({tally})."
    )


def _write_report(
    out: Path, study: dict[str, Any], table: list[dict[str, Any]], fits: list[dict[str, Any]]
) -> None:
    families = list(dict.fromkeys(r["family"] for r in table))
    lines = [
        "# Exploration suite",
        "",
        f"Made by `{command(study, out)}`. Agents: {', '.join(study['agents'])}; seeds "
        f"{list(study['seeds'])}.",
        "",
        _TEXT_HEAD,
        "",
        "## Tasks and budgets",
        "",
    ]
    tasks = [
        [
            r["family"],
            str(r["size"]),
            f"`{r['env']}`",
            f"{r['budget']:,}",
            f"{FAMILIES[r['family']].eval_episodes} episode(s) every "
            f"{FAMILIES[r['family']].eval_every:,} steps",
            f"mean return >= {fmt(FAMILIES[r['family']].threshold)}",
        ]
        for r in dict((r["env"], r) for r in table).values()
    ]
    head = ["family", "size", "environment", "budget (steps)", "evaluation", "solved at"]
    lines += runner.markdown_table(head, tasks).splitlines()
    lines += [""]
    lines += [f"- {name}: {FAMILIES[name].solved}." for name in families]
    lines += [
        "",
        "## Table",
        "",
        _markdown_table(table),
        "## Growth with size",
        "",
        _GROWTH_NOTE,
        "",
        _markdown_growth(fits),
        "## Claims",
        "",
        "Farsighter (the default agent) against DDQN: shown where Farsighter's growth fits a "
        "polynomial better while DDQN's fits an exponential better, or DDQN solves no seed at a "
        "size where Farsighter solves one.",
        "",
        *_claims(table, fits),
        "",
        "## Figures",
        "",
    ]
    for name in families:
        lines += [f"![{name}](figures/{name}.png)", ""]
    lines += [f"Redraw from the saved runs with `farsighter explore --plot-only {out}`.", ""]
    (out / "report.md").write_text("\n".join(lines))


STUDY = runner.Study(
    kind="explore",
    description="The exploration suite: task families with a size knob (chain, MiniGrid "
    "DoorKey, KeyCorridor, MultiRoom, MountainCar), every agent with one config; how the "
    "episodes to solve grow with the size. --quick (the chain at L = 5, 10, 20) takes a few "
    "minutes on 2 cores.",
    agents=AGENTS,
    full=StudyConfig(),
    quick=QUICK,
    run_config=run_config,
    write_outputs=write_outputs,
    run_files=("metrics.csv", "eval.csv"),
    args=Args,
    check=_check,
    tasks=tasks,
)


def main(argv: Sequence[str]) -> int:
    """``farsighter explore ARGV``."""
    return runner.main(STUDY, argv)
