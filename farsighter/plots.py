"""Figures drawn from a run directory's saved metrics (so they can always be redrawn)."""

from __future__ import annotations

import csv
from pathlib import Path

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
