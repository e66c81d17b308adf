"""The exploration study's outputs, drawn from the saved runs only (so ``--plot-only`` redraws
them): runs.csv, table.csv, growth.csv, table.md, one figure per family and report.md with its
claims.
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

import numpy as np

from farsighter.plots import figure, finish_axes, markdown_table
from farsighter.studies.claims import fmt
from farsighter.studies.explore.agents import COLORS
from farsighter.studies.explore.families import (
    DEEP_SEA_MAX_EPISODES,
    DEEP_SEA_MIN_EPISODES,
    FAMILIES,
)
from farsighter.studies.explore.growth import BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED, MIN_SIZES, growth
from farsighter.studies.explore.measures import (
    SOLVE_MEASURES,
    SolveMeasure,
    measures_of,
    per_run,
    primary_measure,
    summarise,
)
from farsighter.studies.runner import Runs


def write_outputs(out: Path, study: dict[str, Any], runs: Runs, command: str) -> None:
    """runs.csv (per run), table.csv (per family x size x agent), growth.csv (per family x
    agent x solve measure), table.md, one figure per family and report.md, which names the
    ``command`` that made the study."""
    rows = per_run(runs)
    table = summarise(rows)
    fits = growth(rows)
    for name, data in (("runs", rows), ("table", table), ("growth", fits)):
        with (out / f"{name}.csv").open("w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=list(data[0]))
            writer.writeheader()
            writer.writerows(data)
    (out / "table.md").write_text(_markdown_table(table) + "\n" + _markdown_growth(fits))
    for family in dict.fromkeys(r["family"] for r in table):
        _plot(family, table, fits, out / "figures" / f"{family}.png")
    _write_report(out, study, command, table, fits)


def _median(value: float, censored: bool) -> str:
    return (">" if censored else "") + fmt(float(value))


def _bsuite_cells(r: dict[str, Any]) -> list[str]:
    """The table's bsuite columns of one row ("n/a" off deep sea or without bad flags)."""
    if r["seeds_bsuite"] is None:
        return ["n/a", "n/a"]
    return [
        f"{r['seeds_bsuite_solved']}/{r['seeds_bsuite']}",
        _median(r["median_bsuite_episode"], r["bsuite_censored"]),
    ]


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
        "bsuite solved",
        "median bsuite episode",
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
            *_bsuite_cells(r),
        ]
        for r in table
    ]
    return markdown_table(head, cells)


def _fitted(fit: dict[str, Any]) -> bool:
    return bool(fit["better"] != "not enough sizes")


def _fit_text(fit: dict[str, Any], key: str) -> str:
    r2 = fit["r2_poly" if key == "p" else "r2_exp"]
    return f"{key} = {fmt(fit[key])} (R² {fmt(r2)})"


def _interval(fit: dict[str, Any]) -> str:
    return f"[{fmt(fit['p_lo'])}, {fmt(fit['p_hi'])}]"


def _markdown_growth(fits: list[dict[str, Any]]) -> str:
    head = [
        "family",
        "agent",
        "measure",
        "sizes fitted",
        "lower-bound medians",
        "polynomial exponent p",
        "p: 95% bootstrap interval",
        "exponential rate r",
        "fits better",
    ]
    cells = []
    for f in fits:
        p, ci, r = (
            (_fit_text(f, "p"), _interval(f), _fit_text(f, "r")) if _fitted(f) else ("", "", "")
        )
        cells.append(
            [
                f["family"],
                f["agent"],
                f["measure"],
                str(f["n_sizes"]),
                str(f["censored_medians"]),
                p,
                ci,
                r,
                f["better"],
            ]
        )
    return markdown_table(head, cells)


def _plot(family: str, table: list[dict[str, Any]], fits: list[dict[str, Any]], file: Path) -> None:
    """Seeds solved against size (bsuite's dashed), then per solve measure the median episodes
    to solve with the polynomial fit."""
    from matplotlib.ticker import NullLocator

    fam = FAMILIES[family]
    measures = measures_of(family)
    rows = [r for r in table if r["family"] == family]
    width = 5.5 * (1 + len(measures))
    with figure(file, 1, 1 + len(measures), figsize=(width, 4.2)) as (_, axes):
        ax0, panels = axes[0], axes[1:]
        for agent in dict.fromkeys(r["agent"] for r in rows):
            mine = [r for r in rows if r["agent"] == agent]
            color = COLORS.get(agent)
            x = np.array([r["size"] for r in mine], dtype=float)
            ax0.plot(
                x, [r["seeds_solved"] / r["seeds"] for r in mine], "o-", color=color, label=agent
            )
            if fam.bsuite and all(r["seeds_bsuite"] for r in mine):
                frac = [r["seeds_bsuite_solved"] / r["seeds_bsuite"] for r in mine]
                ax0.plot(x, frac, "s--", color=color, mfc="none", label=f"{agent} (bsuite)")
            for ax, measure in zip(panels, measures, strict=True):
                m = SOLVE_MEASURES[measure]
                fit = next(
                    f
                    for f in fits
                    if (f["family"], f["agent"], f["measure"]) == (family, agent, measure)
                )
                _plot_medians(ax, [r for r in mine if r[m.solved]], m, fit, agent, color)
        ax0.set_ylim(-0.05, 1.05)
        finish_axes(ax0, fam.size, "fraction of seeds solved", f"{family}: solved")
        sizes = sorted({r["size"] for r in rows})
        for ax in axes:  # ticks at the sizes run
            if ax is not ax0:
                ax.set_xscale("log")
                ax.set_yscale("log")
            ax.set_xticks(sizes, [str(s) for s in sizes])
            ax.xaxis.set_minor_locator(NullLocator())
        for ax, measure in zip(panels, measures, strict=True):
            ax.set_xlabel(fam.size)
            ax.set_ylabel(f"median {SOLVE_MEASURES[measure].name} episodes to solve")
            ax.set_title(
                f"{family}: {SOLVE_MEASURES[measure].name} episodes to solve (open: lower "
                "bound),\npolynomial fit dashed",
                fontsize=10,
            )
            if ax.get_legend_handles_labels()[0]:  # nothing to list where no seed solved
                ax.legend(fontsize=8)
            ax.grid(alpha=0.3)


def _plot_medians(
    ax: Any,
    solved: list[dict[str, Any]],
    m: SolveMeasure,
    fit: dict[str, Any],
    agent: str,
    color: Any,
) -> None:
    """One agent's medians of measure ``m`` at the sizes some seed solved (a censored median, a
    lower bound, is an open marker) and its polynomial fit."""
    for r in solved:
        face = "none" if r[m.censored] else color
        ax.plot(r["size"], r[m.median], "o", color=color, mfc=face)
    if _fitted(fit):
        xs = np.array([r["size"] for r in solved], dtype=float)
        ys = np.log([max(r[m.median], 1.0) for r in solved])
        c = np.mean(ys - fit["p"] * np.log(xs))
        grid = np.geomspace(xs.min(), xs.max(), 50)
        label = f"{agent}: p = {fit['p']:.2g} [{fit['p_lo']:.2g}, {fit['p_hi']:.2g}]"
        ax.plot(grid, np.exp(c) * grid ** fit["p"], "--", color=color, lw=1, label=label)
    elif solved:
        ax.plot([], [], "o", color=color, label=agent)


_TEXT_HEAD = (
    "Each agent runs with one config on every task and size: the library's default for the task "
    "(`preset=auto`) and its own overrides, nothing tuned per task. A run **solved** a task when "
    "some greedy evaluation's mean return (stochastic deep sea: its success rate, the fraction of "
    "its episodes that took the treasure) reached the family's threshold; *episodes to solve* "
    "counts the training episodes finished at the first such evaluation (*steps to solve* "
    "likewise), so its resolution is the evaluation interval. *Held*: the final evaluation is at "
    "the threshold. *First reward*: the first training episode whose return shows the reward was "
    "reached (stochastic deep sea: the first that took the treasure). An unsolved seed counts as "
    "its run's total (episodes, steps): a censored value, so a median marked `>` is a lower bound."
)
_BSUITE_NOTE = (
    "Deep sea is also scored as bsuite scores it (`bsuite/experiments/deep_sea/analysis.py`), "
    "from every training episode's bad flag (the agent left the diagonal by a wrong move; "
    "`bad_episodes.csv` of each run): a run is solved at the first episode where the bad episodes "
    "so far number less than 0.9 of the episodes so far (stochastic deep sea: 0.8, and only from "
    "episode 100 on), and *bsuite solved* counts the seeds solved so before episode 2^N + 100, "
    "the seeds that beat dithering. *Median bsuite episode*: that episode, an unsolved seed "
    "counting as its run's episodes (a lower bound). {budgets} bsuite checks only the episodes it "
    "logs (1-10, 12, 14, 17, 20, 25, ...); here every episode counts, so an episode can read a "
    "little earlier. At small N luck passes the criterion: one episode on the diagonal among the "
    "first 9 brings the fraction below 0.9, which a random policy does with probability about "
    "9/2^N (0.13 at N = 6, 0.009 at N = 10; bsuite's sweep starts at N = 10)."
)
_BSUITE_BUDGETS = (
    "The budgets are 2^N + 100 episodes, at "
    f"least {DEEP_SEA_MIN_EPISODES:,} and at most {DEEP_SEA_MAX_EPISODES:,}: at N = 6 and 8 the "
    "runs go on past episode 2^N + 100, which changes no bsuite verdict (bsuite itself runs "
    "10,000 episodes at every size and counts a solve only before 2^N + 100) and gives the "
    "greedy criterion time; from N = 12 on a seed must beat dithering within "
    f"{DEEP_SEA_MAX_EPISODES:,} episodes."
)


def _bsuite_note(episodes: int) -> str:
    """The report's note on bsuite's criterion, with the deep sea budgets of the study
    (``--episodes``, or each size's own)."""
    if not episodes:
        return _BSUITE_NOTE.format(budgets=_BSUITE_BUDGETS)
    budgets = (
        f"Every deep sea run here is {episodes:,} episodes (`--episodes`; bsuite itself runs "
        "10,000 at every size and counts a solve only before 2^N + 100)."
    )
    return _BSUITE_NOTE.format(budgets=budgets)


_GROWTH_NOTE = (
    "Growth of the median episodes to solve against the size, over the sizes where at least one "
    "seed solved (at least 3 such sizes, else *not enough sizes*): least-squares fits of "
    "log(episodes) on log(size) (polynomial, exponent p) and on size (exponential, rate r), with "
    "their R²; the one with the higher R² fits better. *Measure*: greedy, the training episodes "
    "to the first greedy evaluation at the threshold; bsuite (deep sea), bsuite's episode to "
    "solve. The 95% interval on p is a percentile bootstrap: each size's seeds drawn again with "
    f"replacement, {BOOTSTRAP_RESAMPLES:,} times (seed {BOOTSTRAP_SEED}), the censored medians "
    "recomputed and p refitted; with few seeds it is coarse. The medians include censored seeds, "
    "so an agent that fails at a size enters the fit with a lower bound there (counted in "
    "*lower-bound medians*), and its true growth is at least as steep. With three sizes both fits "
    "can have a high R²: read the two together."
)


def _claims(table: list[dict[str, Any]], fits: list[dict[str, Any]]) -> list[str]:
    """Per family, on its :func:`primary_measure`: does Farsighter's growth look polynomial where
    DDQN's looks exponential (or DDQN fails where Farsighter solves)? Then, plainly, whether
    each one's growth is polynomial. Last, the agent that solved the most (family, size)."""
    lines = []
    fit = {(f["family"], f["agent"], f["measure"]): f for f in fits}
    for family in dict.fromkeys(r["family"] for r in table):
        rows = [r for r in table if r["family"] == family]
        measure = SOLVE_MEASURES[primary_measure(family)]
        head = f"- **{family}**: "
        if not {"Farsighter", "DDQN"} <= {r["agent"] for r in rows}:
            lines.append(head + "not tested: needs both the Farsighter and the DDQN agent.")
            continue
        f, d = fit[family, "Farsighter", measure.name], fit[family, "DDQN", measure.name]
        by = {(r["agent"], r["size"]): r for r in rows}
        sizes = sorted({r["size"] for r in rows})
        if len(sizes) < MIN_SIZES:
            lines.append(head + f"not tested: {len(sizes)} size(s) in this study (needs 3).")
            continue
        solved = measure.solved
        fails = [s for s in sizes if by["Farsighter", s][solved] and not by["DDQN", s][solved]]
        fails_text = (
            "DDQN solves no seed at size(s) "
            + ", ".join(
                f"{s} (Farsighter {by['Farsighter', s][solved]}/"
                f"{by['Farsighter', s]['seeds' if measure.name == 'greedy' else 'seeds_bsuite']})"
                for s in fails
            )
            if fails
            else "DDQN solves a seed at every size where Farsighter does"
        )
        f_poly = f["better"] == "polynomial"
        d_exp = d["better"] == "exponential"
        evidence = (
            f"Fitted: {measure.text}. Farsighter: {_fit_desc(f)}; DDQN: {_fit_desc(d)}; "
            f"{fails_text}"
        )
        if f_poly and (d_exp or fails):
            ddqn = "DDQN's grow exponentially" if d_exp else "DDQN fails at sizes Farsighter solves"
            lines.append(
                head + f"shown: Farsighter's episodes to solve grow polynomially while {ddqn}. "
                f"{evidence}."
            )
        else:
            if not _fitted(f):
                why = f"Farsighter solves a seed at fewer than {MIN_SIZES} sizes"
            elif not f_poly:
                why = "Farsighter's growth does not fit a polynomial better than an exponential"
            else:
                why = "DDQN's growth does not fit an exponential better and DDQN solves a seed "
                why += "wherever Farsighter does"
            lines.append(head + f"not shown: {why}. {evidence}.")
        lines += [
            f"  - {_verdict(agent, fit[family, agent, measure.name])}"
            for agent in ("Farsighter", "DDQN")
        ]
    lines.append(_most_solved(table))
    return lines


def _verdict(agent: str, fit: dict[str, Any]) -> str:
    """Plainly: is ``agent``'s growth polynomial by this fit?"""
    bounds = fit["censored_medians"]
    caveat = (
        f"; {bounds} of its {fit['n_sizes']} medians are lower bounds, so it grows at least this "
        "fast"
        if bounds
        else ""
    )
    if not _fitted(fit):
        return (
            f"{agent}: growth not measured: a seed solved at {fit['n_sizes']} size(s), "
            f"{MIN_SIZES} needed."
        )
    p = f"p = {fmt(fit['p'])}, 95% bootstrap interval {_interval(fit)}"
    if fit["better"] == "polynomial":
        return f"{agent}: growth is polynomial (a polynomial fits better; {p}){caveat}."
    if fit["better"] == "exponential":
        return (
            f"{agent}: growth is not polynomial (an exponential fits better: "
            f"{_fit_text(fit, 'r')} against {_fit_text(fit, 'p')}){caveat}."
        )
    return f"{agent}: neither a polynomial nor an exponential fits better ({p}){caveat}."


def _fit_desc(fit: dict[str, Any]) -> str:
    if not _fitted(fit):
        return f"not enough sizes ({fit['n_sizes']} solved by a seed)"
    return (
        f"{_fit_text(fit, 'p')}, p's 95% interval {_interval(fit)}, {_fit_text(fit, 'r')}, "
        f"{fit['better']} fits better"
    )


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
    out: Path,
    study: dict[str, Any],
    command: str,
    table: list[dict[str, Any]],
    fits: list[dict[str, Any]],
) -> None:
    families = list(dict.fromkeys(r["family"] for r in table))
    lines = [
        "# Exploration suite",
        "",
        f"Made by `{command}`. Agents: {', '.join(study['agents'])}; seeds {list(study['seeds'])}.",
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
            f"{FAMILIES[r['family']].eval_every_at(r['size']):,} steps",
            FAMILIES[r["family"]].rule_at(r["size"]),
        ]
        for r in dict((r["env"], r) for r in table).values()
    ]
    head = ["family", "size", "environment", "budget (steps)", "evaluation", "solved at"]
    lines += markdown_table(head, tasks).splitlines()
    lines += [""]
    lines += [f"- {name}: {FAMILIES[name].solved}." for name in families]
    if any(FAMILIES[name].bsuite for name in families):
        lines += ["", _bsuite_note(int(study.get("episodes", 0)))]
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
        "size where Farsighter solves one. On deep sea the claim fits bsuite's episode to solve "
        "and counts the seeds that beat dithering (the growth table gives the greedy fit too); "
        "elsewhere it fits the greedy episodes to solve. Under each family, plainly, whether "
        "Farsighter's and DDQN's growth is polynomial.",
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
