"""The bridge-maze study's table, claims, figures and report (:mod:`farsighter.studies.maze`),
drawn from the saved run files only, so ``--plot-only`` redraws them; re-exported by
:mod:`farsighter.studies.maze`."""

from __future__ import annotations

import csv
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from farsighter import algorithms
from farsighter.envs.maze import DEFAULT_MAX_EPISODE_STEPS, ENV_ID
from farsighter.envs.maze import DEFAULT_START_VALUE as Q_STAR
from farsighter.plots import band, figure, finish_axes, markdown_table
from farsighter.studies import runner
from farsighter.studies.claims import (
    CONFIDENCE,
    N_BOOT,
    NOT_TESTED,
    VERDICT_TEXT,
    Claim,
    Measure,
    compare,
    fmt,
)
from farsighter.studies.runner import Runs

# ------------------------------------------------------------------------------------------------
# The table: per agent, per-seed values and their summaries (from the saved files only).
# ------------------------------------------------------------------------------------------------

# The per-seed values that the claims compare (one entry per seed in each row's "per_seed").
PER_SEED_METRICS = (
    "abs_error",  # |Q_i(start) - 75|
    "q_start",  # Q_i(start), the final greedy value at the start state
    "success_last_quarter",  # fraction of training episodes in the last quarter that succeed
    "right_side_fraction",  # fraction of state visits right of the bridge
    "final_eval_return",  # return of the last greedy evaluation
    "greedy_solved",  # 1 if the final greedy policy reaches the apple, else 0
    "variance_last_over_peak",  # final Q-variance / its peak (NaN where no variance is kept)
    "own_uncertainty_at_start",  # the agent's own variance at the start state (see ESTIMATORS)
)

# What an agent's own uncertainty at the start state is: two estimators that are not comparable,
# so the table names it per row and no claim ranks that column across estimators.
ESTIMATORS: dict[str, str] = {
    "farsighter": "BLR phi^T Cov phi",  # Farsighter and BDQN
    "ob2i": "variance over heads",
}
"""Agent module (``Algorithm.agent``) -> its estimator."""


def estimator(algo: str) -> str:
    """The name of ``algo``'s own uncertainty estimator at the start state ("n/a" if none)."""
    if algo not in algorithms.ALGORITHMS:
        return "n/a"
    return ESTIMATORS.get(algorithms.get(algo).agent, "n/a")


def _last_over_peak_one(curve: np.ndarray) -> float:
    """Final Q-variance / its peak for one seed (< 1: the variance shrank); NaN if undefined."""
    c = np.asarray(curve, dtype=float)
    if not np.isfinite(c).any() or np.nanmax(c) <= 0:
        return float("nan")
    return float(c[-1] / np.nanmax(c))


def _training(run: dict[str, Any], max_steps: int) -> tuple[float, float, float]:
    """One run's success rate in the last quarter of training, the step of its first success
    (NaN if none) and the fraction of its state visits right of the bridge."""
    m = run["metrics"]
    ret, steps = m.get("episodic_return", np.array([])), m.get("global_step", np.array([]))
    ok = ret > -max_steps  # a failed episode is exactly max_steps steps of -1
    last = steps > 0.75 * steps.max() if len(steps) else np.array([], bool)
    v = run["visits"]
    return (
        float(ok[last].mean()) if last.any() else 0.0,
        float(steps[ok][0]) if ok.any() else float("nan"),
        float(v[:, v.shape[1] // 2 + 2 :].sum() / v.sum()),
    )


def _per_seed(
    items: list[dict[str, Any]], max_steps: int
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """One value per seed for each of :data:`PER_SEED_METRICS`, and the steps to first success."""
    q_final = np.array([r["probe"]["q_start"][-1] for r in items], dtype=float)
    success, first, right = np.array([_training(r, max_steps) for r in items], dtype=float).T
    final_eval = np.array([r["eval"]["eval_return_mean"][-1] for r in items], dtype=float)
    per_seed = {
        "abs_error": np.abs(q_final - Q_STAR),
        "q_start": q_final,
        "success_last_quarter": success,
        "right_side_fraction": right,
        "final_eval_return": final_eval,
        # the final greedy policy reaches the apple (a failure is exactly -max_steps)
        "greedy_solved": (final_eval > -max_steps).astype(float),
        "variance_last_over_peak": np.array(
            [_last_over_peak_one(r["probe"]["q_variance"]) for r in items]
        ),
        "own_uncertainty_at_start": np.array(
            [r["probe"]["q_start_var"][-1] for r in items], dtype=float
        ),
    }
    return per_seed, first


def summarise(runs: Runs, max_steps: int = DEFAULT_MAX_EPISODE_STEPS) -> list[dict[str, Any]]:
    """The table, one row per agent: bias and variance of Q(start), success, exploration.

    Each row also keeps, under ``"per_seed"``, one array per :data:`PER_SEED_METRICS` entry with
    a value per seed, which the claims compare (:func:`_claims`).
    """
    rows = []
    for label, items in runs.items():
        per_seed, first = _per_seed(items, max_steps)
        q = per_seed["q_start"]
        rows.append(
            {
                "agent": label,
                "seeds": len(items),
                "q_start_mean": float(q.mean()),
                "bias": float(abs(q.mean() - Q_STAR)),
                "mean_abs_error": float(per_seed["abs_error"].mean()),
                # the same estimator for every agent: the spread of the final Q(start) over seeds
                "q_start_var_across_seeds": float(q.var()),
                "own_uncertainty_at_start": runner.nanmean(per_seed["own_uncertainty_at_start"]),
                "estimator": estimator(str(items[0]["config"].get("algo", ""))),
                "success_rate_last_quarter": float(np.mean(per_seed["success_last_quarter"])),
                "final_eval_return": float(per_seed["final_eval_return"].mean()),
                "steps_to_first_success": runner.nanmean(first),
                "seeds_with_success": int(np.isfinite(first).sum()),
                "right_side_visit_fraction": float(np.mean(per_seed["right_side_fraction"])),
                "greedy_success_seeds": int(per_seed["greedy_solved"].sum()),
                "variance_last_over_peak": runner.nanmean(per_seed["variance_last_over_peak"]),
                "per_seed": per_seed,
            }
        )
    return rows


# The Markdown table: (heading, key of a row).
MARKDOWN_COLUMNS: tuple[tuple[str, str], ...] = (
    ("agent", "agent"),
    ("Q(start) mean", "q_start_mean"),
    ("bias vs 75", "bias"),
    ("mean abs error vs 75", "mean_abs_error"),
    ("Q(start) var across seeds", "q_start_var_across_seeds"),
    ("own uncertainty at start", "own_uncertainty_at_start"),
    ("estimator", "estimator"),
    ("success (last 25%)", "success_rate_last_quarter"),
    ("final eval return", "final_eval_return"),
    ("greedy solves (seeds)", "greedy_solves"),
    ("steps to 1st success", "steps_to_first_success"),
    ("right-side visits", "right_side_visit_fraction"),
)


def _write_table(rows: list[dict[str, Any]], out: Path) -> None:
    with (out / "table.csv").open("w", newline="") as fh:
        # "per_seed" (the claims' input) stays out of the CSV
        columns = [key for key in rows[0] if key != "per_seed"]
        writer = csv.DictWriter(fh, fieldnames=columns, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    (out / "table.md").write_text(_markdown_table(rows))


def _markdown_table(rows: list[dict[str, Any]]) -> str:
    cells = []
    for r in rows:
        r = {**r, "greedy_solves": f"{r['greedy_success_seeds']}/{r['seeds']}"}
        cells.append([fmt(r[key]) for _, key in MARKDOWN_COLUMNS])
    return markdown_table([head for head, _ in MARKDOWN_COLUMNS], cells)


# ------------------------------------------------------------------------------------------------
# The paper's claims, each one row against one other on per-seed values.
# ------------------------------------------------------------------------------------------------

STATISTIC_NOTE = (
    "Each claim compares one agent with one other on per-seed values: the difference of the two "
    "groups' statistic (the mean over seeds, or for Fig. 1c the variance of Q(start) across "
    f"seeds), with a {CONFIDENCE:.0%} percentile bootstrap confidence interval ({N_BOOT:,} "
    "resamples; the seeds of each group are resampled independently, with replacement). A claim "
    "**holds** when the whole interval lies on the claimed side of 0, **does not hold** when it "
    "lies wholly on the other side or is exactly [0, 0] (the two groups do not differ at all, "
    "so the claimed improvement is absent), and is **undecided at this budget** otherwise (the "
    "interval contains 0), and always when a group has fewer than 2 seeds. A claim about "
    "Farsighter is checked for every Farsighter row separately."
)


ABS_ERROR = Measure("abs_error", "mean |Q(start) - 75|", higher_is_better=False)
RIGHT_SIDE = Measure("right_side_fraction", "mean right-side visit fraction", True)
SUCCESS = Measure("success_last_quarter", "mean success rate in the last quarter", True)
VAR_KEPT = Measure("variance_last_over_peak", "mean final / peak Q-variance", True)
SOLVES = Measure("greedy_solved", "greedy solves", True, count=True)
EVAL_RETURN = Measure("final_eval_return", "mean final greedy return", True)
Q_VARIANCE = Measure("q_start", "variance of Q(start) across seeds", True, stat="var")

_NOVELTY = (
    "{f} explores a distant reward better than a novelty bonus ({b}; appendix 9.1.1, the paper "
    "shows it on Atari): its final greedy policy reaches the apple in more seeds."
)

# The claims about Farsighter, checked for every Farsighter row {f} against the baseline {b}
# where that baseline ran: (baseline, claim, measure).
FARSIGHTER_CLAIMS: tuple[tuple[str, str, Measure], ...] = (
    (
        "BDQN",
        "{f}'s Q-estimate at the start state is less biased than BDQN's (paper: BDQN ~62 vs "
        "Q* = 75, Farsighter the least biased).",
        ABS_ERROR,
    ),
    ("BDQN", "{f} visits the right side of the bridge more than BDQN (Fig. 1d vs 1f).", RIGHT_SIDE),
    ("BDQN", "{f} reaches the apple more reliably than BDQN (Fig. 1b).", SUCCESS),
    (
        "BDQN",
        "BDQN's posterior variance vanishes over training while {f} keeps its uncertainty "
        "(Fig. 1g).",
        VAR_KEPT,
    ),
    (
        "DDQN",
        "On this distant-reward task {f}'s final greedy policy reaches the apple in more seeds "
        "than epsilon-greedy DDQN's.",
        SOLVES,
    ),
    ("DDQN", "{f} outperforms epsilon-greedy DDQN (section 5.2).", EVAL_RETURN),
    ("RND", _NOVELTY, SOLVES),
    ("k-RND (k=10)", _NOVELTY, SOLVES),
)

# Claims about two fixed rows, checked where both ran: (row, other row, claim, measure).
PAIR_CLAIMS: tuple[tuple[str, str, str, Measure], ...] = (
    (
        "Farsighter (k=10)",
        "Farsighter (k=1)",
        "k alone: Farsighter (k=10) beats Farsighter (k=1) (greedy solves).",
        SOLVES,
    ),
    (
        "Farsighter (k=10)",
        "Farsighter (k=1)",
        "k alone: Farsighter (k=10) beats Farsighter (k=1) (success in the last quarter).",
        SUCCESS,
    ),
    ("OB2I", "BDQN", "OB2I's Q-estimate is less biased than BDQN's (Fig. 1c).", ABS_ERROR),
)


def _ob2i_variance_claims(by: dict[str, dict[str, Any]]) -> list[Claim]:
    """Fig. 1c compared like with like: the spread of the final Q(start) over seeds, the same
    estimator for every agent (the agents' own uncertainties are not comparable)."""
    if "OB2I" not in by:
        return [
            Claim(
                "OB2I is less biased than BDQN but with the largest variance (Fig. 1c).",
                "OB2I is not part of this run (--agents)",
                NOT_TESTED,
            )
        ]
    o = by["OB2I"]
    return [
        compare(
            "OB2I's Q-estimate at the start state has the largest variance (Fig. 1c): "
            f"larger than {other}'s.",
            o,
            row,
            Q_VARIANCE,
        )
        for other, row in by.items()
        if row is not o
    ]


def _claims(rows: list[dict[str, Any]]) -> list[Claim]:
    """The paper's claims checked on this run's rows (from :func:`summarise`).

    Every claim compares one row with one other on per-seed values
    (:func:`farsighter.studies.claims.compare`); a claim about Farsighter is emitted once for
    each row whose label starts with "Farsighter", so no best-of selection enters a verdict.
    """
    by = {r["agent"]: r for r in rows}
    claims = [
        compare(text.format(f=name, b=baseline), f, by[baseline], m)
        for name, f in by.items()
        if name.startswith("Farsighter")
        for baseline, text, m in FARSIGHTER_CLAIMS
        if baseline in by
    ]
    claims += [compare(text, by[a], by[b], m) for a, b, text, m in PAIR_CLAIMS if {a, b} <= set(by)]
    return claims + _ob2i_variance_claims(by)


# ------------------------------------------------------------------------------------------------
# Outputs: figures, table and report, from the saved files only.
# ------------------------------------------------------------------------------------------------


def write_outputs(out: Path, study: dict[str, Any], runs: Runs) -> None:
    """Figures, table (CSV and Markdown) and report.md."""
    rows = summarise(runs)
    figures = out / "figures"
    _plot_learning_curves(runs, study["steps"], figures / "learning_curves.png")
    _plot_q_estimate(runs, figures / "q_estimate.png")
    _plot_heatmaps(runs, figures / "heatmaps.png")
    _plot_variance(runs, figures / "posterior_variance.png")
    _write_table(rows, out)
    _write_report(rows, study, out)


COLORS = {
    "DDQN": "C0",
    "BDQN": "C1",
    "Farsighter (k=10)": "C2",
    "Farsighter (adaptive k)": "C3",
    "OB2I": "C4",
    "RND": "C5",
    "k-RND (k=10)": "C6",
    "BDQN (redraw every step)": "C7",
    "Farsighter (k=1)": "C8",
}


def _binned_curve(steps: np.ndarray, values: np.ndarray, edges: np.ndarray) -> np.ndarray:
    out = np.full(len(edges) - 1, np.nan)
    for i in range(len(edges) - 1):
        sel = (steps > edges[i]) & (steps <= edges[i + 1])
        if sel.any():
            out[i] = values[sel].mean()
    # carry the last value forward through bins without a finished episode
    for i in range(1, len(out)):
        if np.isnan(out[i]):
            out[i] = out[i - 1]
    return out


def _plot_learning_curves(runs: Runs, steps: int, file: Path) -> None:
    edges = np.linspace(0, steps, 41)
    centers = (edges[:-1] + edges[1:]) / 2
    with figure(file, figsize=(7, 4.2)) as (_, ax):
        for label, items in runs.items():
            curves = np.array(
                [
                    _binned_curve(
                        r["metrics"]["global_step"], r["metrics"]["episodic_return"], edges
                    )
                    for r in items
                    if len(r["metrics"])
                ]
            )
            band(ax, centers, curves, COLORS.get(label), label)
        ax.axhline(Q_STAR, ls="--", color="k", lw=1, label="optimal return (75)")
        finish_axes(
            ax,
            "environment steps",
            "training episode return",
            "Bridge maze: learning curves (mean ± std over seeds)",
            loc="lower right",
        )


def _plot_q_estimate(runs: Runs, file: Path) -> None:
    labels = list(runs)
    kw = {"figsize": (11, 4.8), "gridspec_kw": {"width_ratios": [1, 1.4]}}
    with figure(file, 1, 2, **kw) as (_, (ax0, ax1)):
        for i, label in enumerate(labels):
            q = np.array([r["probe"]["q_start"][-1] for r in runs[label]])
            c = COLORS.get(label)
            x = np.full(len(q), i) + np.linspace(-0.12, 0.12, len(q))
            ax0.scatter(x, q, color=c, s=18, alpha=0.7)
            ax0.errorbar(i, q.mean(), yerr=q.std(), fmt="o", color="k", capsize=6, ms=7)
            post = np.array([r["probe"]["q_start_var"][-1] for r in runs[label]])
            if np.isfinite(post).all():
                sd = np.sqrt(post.mean())
                ax0.errorbar(i + 0.28, q.mean(), yerr=sd, fmt="s", color=c, capsize=4, ms=5)
            steps = runs[label][0]["probe"]["global_step"]
            curves = np.array([r["probe"]["q_start"][: len(steps)] for r in runs[label]])
            band(ax1, steps, curves, c, label)
        for ax in (ax0, ax1):
            ax.axhline(Q_STAR, ls="--", color="k", lw=1)
            ax.grid(alpha=0.3)
        ax0.set_xticks(range(len(labels)))
        ax0.set_xticklabels(labels, fontsize=8, rotation=35, ha="right")
        ax0.set_ylabel("Q-estimate at the start state")
        ax0.set_title(
            "Final estimate: seeds (dots), mean ± std (black),\nsd of own uncertainty (square)",
            fontsize=9,
        )
        ax1.set_xlabel("environment steps")
        ax1.set_title("Q-estimate at the start over training (Q* = 75 dashed)", fontsize=9)
        ax1.legend(fontsize=8)


def _plot_heatmaps(runs: Runs, file: Path) -> None:
    import gymnasium as gym
    import matplotlib.pyplot as plt

    maze: Any = gym.make(ENV_ID).unwrapped
    labels = list(runs)
    with figure(file, 1, len(labels), figsize=(3.6 * len(labels), 3.6)) as (fig, axes):
        for ax, label in zip(np.atleast_1d(axes), labels, strict=True):
            visits = np.sum([r["visits"] for r in runs[label]], axis=0).astype(float)
            shown = np.ma.masked_array(np.log10(visits + 1), mask=maze.wall_mask)
            cmap = plt.get_cmap("viridis").with_extremes(bad="black")
            im = ax.imshow(shown, cmap=cmap, origin="upper")
            for r, c in maze.bridge_cells:
                ax.add_patch(
                    plt.Rectangle((c - 0.5, r - 0.5), 1, 1, fill=False, ec="white", lw=1.5)
                )
            for (row, col), text, color in ((maze.start, "S", "white"), (maze.goal, "G", "red")):
                kw = {"ha": "center", "va": "center", "fontsize": 9, "weight": "bold"}
                ax.text(col, row, text, color=color, **kw)
            ax.set_title(label, fontsize=9)
            ax.set_xticks([])
            ax.set_yticks([])
            fig.colorbar(im, ax=ax, fraction=0.046, pad=0.03, label="log10(visits + 1)")
        fig.suptitle("State visits during training (all seeds); wall black, bridge outlined")


def _plot_variance(runs: Runs, file: Path) -> None:
    with figure(file, figsize=(7, 4.2)) as (_, ax):
        drawn = False
        for label, items in runs.items():
            steps = items[0]["probe"]["global_step"]
            curves = np.array([r["probe"]["q_variance"][: len(steps)] for r in items])
            if not np.isfinite(curves).any():
                continue  # DDQN has no posterior
            drawn = True
            with warnings.catch_warnings():  # steps before the first refresh are NaN for all seeds
                warnings.simplefilter("ignore", RuntimeWarning)
                mean = np.nanmean(curves, axis=0)
            ax.plot(steps, mean, color=COLORS.get(label), label=label)
        ax.set_yscale("log")
        ax.set_xlabel("environment steps")
        ax.set_ylabel("Q-variance, phi^T Cov phi (greedy a)")
        ax.set_title("Posterior variance over training (mean over seeds)")
        if drawn:
            ax.legend(fontsize=8)
        ax.grid(alpha=0.3)


REPORT_HEAD = (
    "Environment `{env}`: 15x13 grid, a 3-column wall crossed by a one-cell-high bridge, start "
    "bottom-left, apple top-right, reward +100 at the apple and -1 per other step, gamma = 1, "
    "200-step time limit; the optimal value of the start state is exactly 75 (value iteration)."
)
TABLE_NOTE = (
    "Q(start) is the greedy value at the start state under the final Q (posterior mean for "
    "BDQN/Farsighter). *Bias vs 75* is |mean Q(start) - 75|, *mean abs error* the mean over "
    "seeds of |Q(start) - 75|. *Q(start) var across seeds* is the variance of the final "
    "Q(start) over seeds, the same estimator for every agent. *Own uncertainty at start* is "
    "the agent's own variance there, by the estimator named in the next column (the BLR "
    "posterior's phi^T Cov phi, or the variance over OB2I's heads): different estimators, so "
    "that column is not ranked across them. Success: training episodes that reached the "
    "apple in the last quarter of training. With gamma = 1 a time-limit truncation "
    "bootstraps, so the value of never reaching the apple is unbounded below: an agent that "
    "has not found it can estimate Q(start) far below -200."
)
FIGURES = (
    ("Learning curves (Fig. 1b)", "learning curves", "learning_curves"),
    ("Q-estimate at the start state against Q* = 75 (Fig. 1c)", "Q estimate", "q_estimate"),
    ("State-visit heatmaps (Fig. 1d-f)", "heatmaps", "heatmaps"),
    ("Posterior variance over time (Fig. 1g)", "posterior variance", "posterior_variance"),
)


def _write_report(rows: list[dict[str, Any]], study: dict[str, Any], out: Path) -> None:
    lines = [
        "# Bridge maze study (paper section 5.1, Figure 1)",
        "",
        f"Agents: {', '.join(study['agents'])}; seeds {list(study['seeds'])}; "
        f"{study['steps']:,} environment steps each. " + REPORT_HEAD.format(env=ENV_ID),
        "",
        "## Table",
        "",
        TABLE_NOTE,
        "",
        _markdown_table(rows),
        "## The paper's claims, checked",
        "",
        STATISTIC_NOTE,
        "",
    ]
    lines += [f"- **{c.claim}** {c.evidence}: {VERDICT_TEXT[c.verdict]}." for c in _claims(rows)]
    lines += ["", "## Figures", ""]
    for caption, alt, name in FIGURES:
        lines += [f"{caption}:", "", f"![{alt}](figures/{name}.png)", ""]
    lines += [
        f"Redraw the figures from the saved runs with `farsighter maze --plot-only {out}`.",
        "",
    ]
    (out / "report.md").write_text("\n".join(lines))
