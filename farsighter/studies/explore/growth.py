"""How the episodes to solve grow with the size: polynomial and exponential least-squares fits of
the censored medians, and a bootstrap interval on the polynomial exponent.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from farsighter.studies.explore.measures import by_cell, censored_median, measures_of, seed_values


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


BOOTSTRAP_RESAMPLES = 1_000
BOOTSTRAP_SEED = 0


def bootstrap_exponent(
    sizes: Sequence[float],
    samples: Sequence[Sequence[float]],
    resamples: int = BOOTSTRAP_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> tuple[float, float]:
    """A 95% percentile-bootstrap interval on the polynomial exponent p of :func:`fit_growth`:
    ``resamples`` times, each size's per-seed values (``samples``, censored ones at their lower
    bound) are drawn again with replacement within that size, their median taken (so the
    censored median) and p refitted by least squares; the 2.5 and 97.5 percentiles of the p's.
    Fewer than :data:`MIN_SIZES` sizes: (NaN, NaN)."""
    if len(sizes) < MIN_SIZES:
        return float("nan"), float("nan")
    rng = np.random.default_rng(seed)
    log_y = np.empty((resamples, len(sizes)))
    for j, values in enumerate(samples):
        v = np.asarray(values, dtype=float)
        draws = v[rng.integers(len(v), size=(resamples, len(v)))]
        log_y[:, j] = np.log(np.maximum(np.median(draws, axis=1), 1.0))
    x = np.log(np.asarray(sizes, dtype=float))
    x = x - x.mean()
    p = (log_y - log_y.mean(axis=1, keepdims=True)) @ x / (x @ x)
    lo, hi = np.percentile(p, [2.5, 97.5])
    return float(lo), float(hi)


def growth(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per family x agent x solve measure (:func:`measures_of`), from the :func:`per_run` rows:
    :func:`fit_growth` of the censored median episodes to solve over the sizes where at least
    one seed solved, how many of those medians are lower bounds, and :func:`bootstrap_exponent`'s
    interval on p (p_lo, p_hi)."""
    cells = by_cell(rows)
    out = []
    for family, agent in dict.fromkeys((f, a) for f, _, a in cells):
        for measure in measures_of(family):
            sizes, medians, samples, censored = [], [], [], 0
            for (f, size, a), rs in cells.items():
                if (f, a) != (family, agent):
                    continue
                values, unsolved = seed_values(rs, measure)
                if all(unsolved):  # no seed solved (or no data)
                    continue
                median, lower_bound = censored_median(values, unsolved)
                sizes.append(size)
                medians.append(median)
                samples.append(values)
                censored += lower_bound
            fit = fit_growth(sizes, medians)
            lo, hi = bootstrap_exponent(sizes, samples)
            out.append(
                {
                    "family": family,
                    "agent": agent,
                    "measure": measure,
                    "n_sizes": fit["n_sizes"],
                    "censored_medians": censored,
                    "p": fit["p"],
                    "p_lo": lo,
                    "p_hi": hi,
                    "r2_poly": fit["r2_poly"],
                    "r": fit["r"],
                    "r2_exp": fit["r2_exp"],
                    "better": fit["better"],
                }
            )
    return out
