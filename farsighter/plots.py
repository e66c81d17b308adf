"""Figures and tables: a run's learning curve drawn from its saved metrics (so it can always be
redrawn), and the pieces the studies' and the sweeps' reports share (Markdown tables, figure
files, mean-and-band curves, step-count axes)."""

from __future__ import annotations

import csv
import warnings
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from farsighter.errors import RunDirError
from farsighter.rundir import EVAL_FILE, METRICS_FILE


def read_csv(file: Path) -> dict[str, np.ndarray]:
    """Columns of a metrics CSV as float arrays."""
    with file.open() as fh:
        rows = list(csv.DictReader(fh))
    if not rows:
        return {}
    return {
        key: np.array([float(r[key]) if r[key] != "" else np.nan for r in rows]) for key in rows[0]
    }


def smooth(values: np.ndarray, window: int) -> np.ndarray:
    if len(values) < window or window <= 1:
        return values
    kernel = np.ones(window) / window
    head = np.cumsum(values[: window - 1]) / np.arange(1, window)
    return np.concatenate([head, np.convolve(values, kernel, mode="valid")])


def plot_run(run_dir: str | Path, out: str | Path | None = None) -> Path:
    """Learning curve of one run: training episode returns and evaluation returns vs steps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(run_dir)
    if not (path / METRICS_FILE).exists():
        raise RunDirError(f"{path} holds no metrics ({METRICS_FILE}); is it a run directory?")
    metrics = read_csv(path / METRICS_FILE)
    evals = read_csv(path / EVAL_FILE) if (path / EVAL_FILE).exists() else {}
    fig, ax = plt.subplots(figsize=(7, 4))
    if metrics:
        steps, ret = metrics["global_step"], metrics["episodic_return"]
        ax.plot(steps, ret, color="0.8", lw=0.8, label="training episodes")
        ax.plot(steps, smooth(ret, 20), color="C0", lw=1.5, label="training (moving avg 20)")
    if evals:
        m, s = evals["eval_return_mean"], evals["eval_return_std"]
        ax.plot(evals["global_step"], m, "o-", color="C3", label="evaluation (greedy)")
        ax.fill_between(evals["global_step"], m - s, m + s, color="C3", alpha=0.15)
    ax.set_xlabel("environment steps")
    ax.set_ylabel("episodic return")
    ax.set_title(path.name)
    ax.legend(loc="best", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    target = Path(out) if out else path / "learning_curve.png"
    fig.savefig(target, dpi=120)
    plt.close(fig)
    return target


def markdown_table(head: Sequence[str], rows: Iterable[Sequence[str]]) -> str:
    """A Markdown table: the header, the rule, one line per row of cells (already text)."""
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(cells) + " |" for cells in rows]
    return "\n".join(lines) + "\n"


@contextmanager
def figure(file: Path, *args: Any, **kwargs: Any) -> Iterator[tuple[Any, Any]]:
    """``plt.subplots(*args, **kwargs)``, saved to ``file`` when the block ends."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(*args, **kwargs)
    try:
        yield fig, axes
        fig.tight_layout()
        fig.savefig(file, dpi=120)
    finally:
        plt.close(fig)


def band(ax: Any, x: np.ndarray, curves: np.ndarray, color: Any, label: str | None) -> None:
    """The mean over seeds (rows of ``curves``, NaN where a seed has no value) and a band of one
    standard deviation."""
    with warnings.catch_warnings():  # a point where every seed is NaN stays NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        mean, std = np.nanmean(curves, axis=0), np.nanstd(curves, axis=0)
    ax.plot(x, mean, color=color, label=label)
    ax.fill_between(x, mean - std, mean + std, color=color, alpha=0.15)


def short_count(x: float) -> str:
    """A step count for an axis: 0, 500, 10k, 12.5k, 1.5M."""
    for div, unit in ((1e6, "M"), (1e3, "k")):
        if abs(x) >= div:
            return f"{x / div:g}{unit}"
    return f"{x:g}"


def finish_axes(ax: Any, xlabel: str, ylabel: str, title: str, **legend: Any) -> None:
    """Labels, title, legend and grid of a curve plot; step counts read 10k, 1.5M."""
    from matplotlib.ticker import FuncFormatter

    ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: short_count(x)))
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(**{"fontsize": 8, **legend})
    ax.grid(alpha=0.3)
