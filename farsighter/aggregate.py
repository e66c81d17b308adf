"""Statistics across environments, after Agarwal et al. 2021 ("Deep RL at the edge of the
statistical precipice"), computed with the ``rliable`` library.

Scores are a dict from agent label to an array of shape ``(runs, tasks)`` (one row per seed, the
same task order for every agent), usually normalised so that 0 is random and 1 is a reference
agent. The functions report the interquartile mean (IQM), mean, median and optimality gap with
stratified bootstrap confidence intervals (runs are resampled within each task), the probability
of improvement of one agent over another, and performance profiles (score distributions).

All functions are pure: the same inputs and ``seed`` give the same output. rliable 1.2 draws its
bootstrap indices from NumPy's *global* random state and ignores its ``random_state`` argument, so
each call seeds the global state for its duration and restores it afterwards (not thread-safe).
rliable is an optional dependency (the ``stats`` extra) and is imported on first use.
"""

from __future__ import annotations

import csv
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from farsighter.errors import FarsighterError

Scores = dict[str, np.ndarray]
"""Per agent label, an array of shape (runs, tasks); the same task order for all agents."""

METRICS: tuple[str, ...] = ("iqm", "mean", "median", "optimality_gap")
METRIC_TITLES: tuple[str, ...] = ("IQM", "Mean", "Median", "Optimality gap")
AGGREGATE_KEYS: tuple[str, ...] = (
    "agent",
    "runs",
    "tasks",
    *(f"{m}{suffix}" for m in METRICS for suffix in ("", "_lo", "_hi")),
)
PER_TASK_KEYS: tuple[str, ...] = ("agent", "task", "mean", "std", "runs")
POI_KEYS: tuple[str, ...] = ("x", "y", "probability", "lo", "hi")


def _rliable() -> tuple[Any, Any]:
    """rliable's ``library`` and ``metrics`` modules, or a FarsighterError saying why not."""
    try:
        from rliable import library, metrics
    except Exception as e:  # ImportError, or arch 7.x failing to import under pandas>=3
        raise FarsighterError(
            f"rliable could not be imported ({type(e).__name__}: {e}); install 'rliable>=1.2' "
            "(its dependency arch 7.x needs pandas<3)"
        ) from e
    return library, metrics


@contextmanager
def _global_seed(seed: int) -> Iterator[None]:
    """Seed NumPy's global random state for the block, then restore the previous state."""
    state = np.random.get_state()  # noqa: NPY002 - rliable resamples with np.random.choice
    np.random.seed(seed)  # noqa: NPY002
    try:
        yield
    finally:
        np.random.set_state(state)  # noqa: NPY002


def minmax_normalized(scores: Mapping[str, Any]) -> Scores:
    """Scores rescaled per task so that the lowest run of any agent is 0 and the highest 1 (a
    task where every run scored the same is 0): for tasks without reference scores."""
    checked = validate_scores(scores)
    stacked = np.concatenate(list(checked.values()))  # (all runs, tasks)
    lo, hi = stacked.min(axis=0), stacked.max(axis=0)
    span = np.where(hi > lo, hi - lo, 1.0)
    return {agent: np.where(hi > lo, (x - lo) / span, 0.0) for agent, x in checked.items()}


def validate_scores(scores: Mapping[str, Any], tasks: Sequence[str] | None = None) -> Scores:
    """Check a score dict and return it as float64 arrays (a new dict, same agent order).

    Raises FarsighterError (one line) on an empty dict, an array that is not 2-D or has no runs
    or no tasks, task counts that differ between agents or from ``len(tasks)``, and NaN or inf.
    """
    if not scores:
        raise FarsighterError("scores is empty: give at least one agent")
    out: Scores = {}
    for agent, value in scores.items():
        x = np.asarray(value, dtype=np.float64)
        if x.ndim != 2:
            raise FarsighterError(
                f"scores[{agent!r}] must be 2-D (runs, tasks), got shape {x.shape}"
            )
        if x.shape[0] == 0 or x.shape[1] == 0:
            raise FarsighterError(f"scores[{agent!r}] has no runs or no tasks (shape {x.shape})")
        if not np.isfinite(x).all():
            raise FarsighterError(f"scores[{agent!r}] holds NaN or inf values")
        out[agent] = x
    counts = {agent: x.shape[1] for agent, x in out.items()}
    if len(set(counts.values())) > 1:
        raise FarsighterError(f"agents have different task counts: {counts}")
    if tasks is not None and len(tasks) != next(iter(counts.values())):
        raise FarsighterError(
            f"task count {next(iter(counts.values()))} != len(tasks) {len(tasks)} ({list(tasks)})"
        )
    return out


def iqm(x: np.ndarray) -> float:
    """Interquartile mean of all values of ``x``: rliable's 25% trimmed mean over the flat array."""
    _, metrics = _rliable()
    return float(metrics.aggregate_iqm(np.asarray(x, dtype=np.float64)))


def per_task(scores: Mapping[str, Any], tasks: Sequence[str]) -> list[dict[str, Any]]:
    """One row per (agent, task): agent, task, mean, std (ddof=1; 0.0 for one run) and runs."""
    rows = []
    for agent, x in validate_scores(scores, tasks).items():
        runs = x.shape[0]
        for j, task in enumerate(tasks):
            col = x[:, j]
            std = float(np.std(col, ddof=1)) if runs > 1 else 0.0
            rows.append(
                {"agent": agent, "task": task, "mean": float(col.mean()), "std": std, "runs": runs}
            )
    return rows


def aggregate(
    scores: Mapping[str, Any],
    *,
    reps: int = 2000,
    seed: int = 0,
    confidence: float = 0.95,
    gap_threshold: float = 1.0,
) -> list[dict[str, Any]]:
    """One row per agent: IQM, mean, median and optimality gap with stratified-bootstrap CIs.

    Keys: agent, runs, tasks, and for each metric ``m`` in ``METRICS`` the point estimate ``m``
    and the percentile interval ``m_lo`` / ``m_hi`` (``confidence`` coverage, ``reps``
    resamples of the runs within each task). The optimality gap is the mean of
    ``max(gap_threshold - score, 0)``; lower is better. One run gives a degenerate interval.
    """
    checked = validate_scores(scores)
    rly, metrics = _rliable()

    def all_metrics(x: np.ndarray) -> np.ndarray:
        return np.array(
            [
                metrics.aggregate_iqm(x),
                metrics.aggregate_mean(x),
                metrics.aggregate_median(x),
                metrics.aggregate_optimality_gap(x, gap_threshold),
            ]
        )

    with _global_seed(seed):
        points, intervals = rly.get_interval_estimates(
            checked, all_metrics, reps=reps, confidence_interval_size=confidence
        )
    rows = []
    for agent, x in checked.items():
        row: dict[str, Any] = {"agent": agent, "runs": x.shape[0], "tasks": x.shape[1]}
        for i, m in enumerate(METRICS):
            row[m] = float(points[agent][i])
            row[f"{m}_lo"] = float(intervals[agent][0, i])
            row[f"{m}_hi"] = float(intervals[agent][1, i])
        rows.append(row)
    return rows


def default_pairs(scores: Mapping[str, Any]) -> list[tuple[str, str]]:
    """The first agent (dict order) against each other agent: ``[(first, other), ...]``."""
    agents = list(scores)
    return [(agents[0], other) for other in agents[1:]]


def probability_of_improvement(
    scores: Mapping[str, Any],
    pairs: Sequence[tuple[str, str]],
    *,
    reps: int = 2000,
    seed: int = 0,
    confidence: float = 0.95,
) -> list[dict[str, Any]]:
    """For each pair ``(x, y)``: P(X > Y) averaged over tasks, with a bootstrap CI.

    Per task, P(X > Y) is the Mann-Whitney U statistic over all run pairs divided by their
    number, so ties count 1/2 (rliable's definition). The runs of X and Y are resampled
    independently within each task, so the two agents may have different run counts.
    Rows: x, y, probability, lo, hi.
    """
    checked = validate_scores(scores)
    for pair in pairs:
        missing = [a for a in pair if a not in checked]
        if missing:
            raise FarsighterError(f"pair {tuple(pair)}: unknown agent(s) {missing}")
    rly, metrics = _rliable()
    rows = []
    with _global_seed(seed):
        for x, y in pairs:
            point, interval = rly.get_interval_estimates(
                {"pair": (checked[x], checked[y])},
                metrics.probability_of_improvement,
                reps=reps,
                confidence_interval_size=confidence,
            )
            lo, hi = np.ravel(interval["pair"])
            rows.append(
                {
                    "x": x,
                    "y": y,
                    "probability": float(point["pair"]),
                    "lo": float(lo),
                    "hi": float(hi),
                }
            )
    return rows


def performance_profile(
    scores: Mapping[str, Any],
    taus: Sequence[float] | np.ndarray,
    *,
    reps: int = 2000,
    seed: int = 0,
    confidence: float = 0.95,
) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per agent ``(profile, lo, hi)``: the fraction of all runs x tasks scores above each tau.

    The interval is a stratified bootstrap over runs, like :func:`aggregate`.
    """
    checked = validate_scores(scores)
    rly, _ = _rliable()
    tau_list = np.asarray(taus, dtype=np.float64)
    with _global_seed(seed):
        profiles, cis = rly.create_performance_profile(
            checked, tau_list, reps=reps, confidence_interval_size=confidence
        )
    return {
        agent: (np.asarray(profiles[agent]), np.asarray(cis[agent][0]), np.asarray(cis[agent][1]))
        for agent in checked
    }


def _write_csv(path: Path, keys: Sequence[str], rows: list[dict[str, Any]]) -> Path:
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(keys))
        writer.writeheader()
        writer.writerows(rows)
    return path


def _markdown(rows: list[dict[str, Any]], note: str) -> str:
    header = ["Agent", "Runs", "Tasks", *METRIC_TITLES]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for r in rows:
        cells = [f"{r[m]:.2f} [{r[m + '_lo']:.2f}, {r[m + '_hi']:.2f}]" for m in METRICS]
        lines.append(
            "| " + " | ".join([str(r["agent"]), str(r["runs"]), str(r["tasks"]), *cells]) + " |"
        )
    return "\n".join(lines) + f"\n\n{note}\n"


def write_outputs(
    out: Path,
    scores: Mapping[str, Any],
    tasks: Sequence[str],
    *,
    normalized_name: str = "score",
    pairs: Sequence[tuple[str, str]] | None = None,
    reps: int = 2000,
    seed: int = 0,
    gap_threshold: float = 1.0,
) -> dict[str, Path]:
    """Write tables and figures under ``out`` and return their paths by name.

    Files: ``per_task.csv``, ``aggregate.csv``, ``aggregate.md`` (cells "IQM [lo, hi]"),
    ``probability_of_improvement.csv`` (when there are pairs; by default the first agent against
    each other agent), ``figures/aggregate.png`` and ``figures/profiles.png`` (score
    distributions over 101 thresholds spanning all scores, with shaded CIs).
    """
    checked = validate_scores(scores, tasks)
    out = Path(out)
    (out / "figures").mkdir(parents=True, exist_ok=True)
    paths = {"per_task": _write_csv(out / "per_task.csv", PER_TASK_KEYS, per_task(checked, tasks))}
    rows = aggregate(checked, reps=reps, seed=seed, gap_threshold=gap_threshold)
    paths["aggregate"] = _write_csv(out / "aggregate.csv", AGGREGATE_KEYS, rows)
    note = (
        f"CIs: 95% stratified bootstrap over runs (resampled within each task), {reps} reps, "
        f"seed {seed}; scores: {normalized_name}; optimality gap at {gap_threshold:g}."
    )
    paths["aggregate_md"] = out / "aggregate.md"
    paths["aggregate_md"].write_text(_markdown(rows, note))
    pairs = default_pairs(checked) if pairs is None else list(pairs)
    if pairs:
        poi = probability_of_improvement(checked, pairs, reps=reps, seed=seed)
        paths["probability_of_improvement"] = _write_csv(
            out / "probability_of_improvement.csv", POI_KEYS, poi
        )
    all_scores = np.concatenate([x.ravel() for x in checked.values()])
    taus = np.linspace(all_scores.min(), all_scores.max(), 101)
    profiles = performance_profile(checked, taus, reps=reps, seed=seed)
    paths.update(_plot(out / "figures", rows, taus, profiles, normalized_name))
    return paths


def _plot(
    figures: Path,
    rows: list[dict[str, Any]],
    taus: np.ndarray,
    profiles: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]],
    normalized_name: str,
) -> dict[str, Path]:
    """Draw ``aggregate.png`` and ``profiles.png`` with rliable's plot helpers (Agg backend)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from rliable import plot_utils

    points = {r["agent"]: np.array([r[m] for m in METRICS]) for r in rows}
    intervals = {
        r["agent"]: np.array([[r[f"{m}_lo"] for m in METRICS], [r[f"{m}_hi"] for m in METRICS]])
        for r in rows
    }
    height = 0.6 * len(rows)  # inches: the label goes below the tick labels, whatever the rows
    fig, _ = plot_utils.plot_interval_estimates(
        points,
        intervals,
        metric_names=METRIC_TITLES,
        xlabel=normalized_name,
        row_height=0.6,
        xlabel_y_coordinate=-0.55 / height,
    )
    aggregate_png = figures / "aggregate.png"
    fig.savefig(aggregate_png, dpi=120, bbox_inches="tight")
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(7, 4))
    plot_utils.plot_performance_profiles(
        {a: p[0] for a, p in profiles.items()},
        taus,
        performance_profile_cis={a: (p[1], p[2]) for a, p in profiles.items()},
        ax=ax,
        xlabel=rf"{normalized_name} ($\tau$)",
        legend=True,
    )
    profiles_png = figures / "profiles.png"
    fig.savefig(profiles_png, dpi=120, bbox_inches="tight")
    plt.close(fig)
    return {"aggregate_png": aggregate_png, "profiles_png": profiles_png}
