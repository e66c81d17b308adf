"""Small statistics for comparing agents over a handful of seeds.

A study runs each agent for a few seeds (2-5), so "agent A beats agent B" cannot be read from a
bare comparison of two means. :func:`bootstrap_diff` gives a percentile-bootstrap confidence
interval for the difference of a per-seed statistic between two groups, and :func:`verdict` turns
that interval into one of three outcomes: ``"holds"``, ``"does not hold"`` or ``"undecided"``.

All functions are pure: the same inputs (and ``seed``) give the same output.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

Stat = Literal["mean", "var"]
Verdict = Literal["holds", "does not hold", "undecided"]

STATS: tuple[str, ...] = ("mean", "var")
VERDICTS: tuple[str, ...] = ("holds", "does not hold", "undecided")

# Resampled statistics that agree to this relative precision count as equal, so that two identical
# constant groups give a difference of exactly 0 (and not +-1 ulp of rounding, which would read as
# a "difference" of zero width and decide a claim).
_RTOL = 1e-12


@dataclass(frozen=True)
class DiffCI:
    """A point estimate and confidence interval for ``stat(a) - stat(b)``.

    ``diff`` is the statistic of the observed groups, ``[lo, hi]`` the percentile bootstrap
    interval, ``n_a`` / ``n_b`` the group sizes (seeds), ``method`` a one-line description.
    With an empty group every number is NaN.
    """

    diff: float
    lo: float
    hi: float
    n_a: int
    n_b: int
    method: str


def _as_values(x: Sequence[float] | np.ndarray, name: str) -> np.ndarray:
    values = np.asarray(x, dtype=np.float64).reshape(-1)
    if not np.isfinite(values).all():
        raise ValueError(f"{name} holds non-finite values ({values}); drop them first")
    return values


def statistic(values: Sequence[float] | np.ndarray, stat: Stat = "mean") -> float:
    """``stat`` of one group: its mean, or its population variance (``ddof=0``); NaN if empty."""
    if stat not in STATS:
        raise ValueError(f"stat must be one of {STATS}, got {stat!r}")
    x = np.asarray(values, dtype=np.float64).reshape(-1)
    if x.size == 0:
        return float("nan")
    return float(x.mean() if stat == "mean" else x.var())


def _resampled(x: np.ndarray, stat: Stat, n_boot: int, rng: np.random.Generator) -> np.ndarray:
    """``stat`` of ``n_boot`` resamples of ``x`` with replacement, shape ``(n_boot,)``."""
    samples = x[rng.integers(0, x.size, size=(n_boot, x.size))]
    return samples.mean(axis=1) if stat == "mean" else samples.var(axis=1)


def _snapped(sa: np.ndarray, sb: np.ndarray, scale: float) -> np.ndarray:
    """``sa - sb``, with differences within rounding of each other set to exactly 0."""
    diff = sa - sb
    diff[np.abs(diff) <= _RTOL * scale] = 0.0
    return diff


def bootstrap_diff(
    a: Sequence[float] | np.ndarray,
    b: Sequence[float] | np.ndarray,
    *,
    stat: Stat = "mean",
    n_boot: int = 10_000,
    confidence: float = 0.95,
    seed: int = 0,
) -> DiffCI:
    """Percentile bootstrap confidence interval of ``stat(a) - stat(b)``.

    ``a`` and ``b`` hold one value per seed. Each bootstrap replicate resamples the seeds of each
    group independently, with replacement and at the group's own size, and takes the difference
    of the two statistics; ``[lo, hi]`` are the ``(1 - confidence) / 2`` and
    ``(1 + confidence) / 2`` quantiles of the ``n_boot`` replicates. ``stat`` is ``"mean"`` or
    ``"var"`` (population variance, ``ddof=0``). The draws come from
    ``numpy.random.default_rng(seed)``, so a call is deterministic.

    Values must be finite (a caller drops missing seeds first). An empty group gives NaN
    throughout; a single seed gives a zero-width interval, which :func:`verdict` calls undecided.
    """
    if stat not in STATS:
        raise ValueError(f"stat must be one of {STATS}, got {stat!r}")
    if n_boot < 1:
        raise ValueError(f"n_boot must be >= 1, got {n_boot}")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")
    x, y = _as_values(a, "a"), _as_values(b, "b")
    method = (
        f"percentile bootstrap of {stat}(a) - {stat}(b) over seeds, each group resampled "
        f"independently with replacement, {n_boot:,} resamples, {confidence:.0%} interval"
    )
    if x.size == 0 or y.size == 0:
        nan = float("nan")
        return DiffCI(nan, nan, nan, int(x.size), int(y.size), method)
    scale = float(max(np.abs(x).max(), np.abs(y).max()))
    if stat == "var":
        scale *= scale
    rng = np.random.default_rng(seed)
    sa = _resampled(x, stat, n_boot, rng)
    sb = _resampled(y, stat, n_boot, rng)
    diffs = _snapped(sa, sb, scale)
    alpha = 1.0 - confidence
    lo, hi = np.quantile(diffs, [alpha / 2, 1.0 - alpha / 2])
    point = _snapped(np.array([statistic(x, stat)]), np.array([statistic(y, stat)]), scale)
    return DiffCI(float(point[0]), float(lo), float(hi), int(x.size), int(y.size), method)


def verdict(ci: DiffCI, *, higher_is_better: bool = True) -> Verdict:
    """Three-outcome reading of a claim "group a is better than group b" from ``ci``.

    The claim is ``stat(a) > stat(b)`` when ``higher_is_better``, else ``stat(a) < stat(b)``.

    - ``"holds"``: the interval excludes 0 on the claimed side (``lo > 0``, or ``hi < 0`` when
      lower is better).
    - ``"does not hold"``: the interval excludes 0 on the other side, or it is exactly
      ``[0, 0]``: every resample of the two groups gives the same statistic (e.g. two identical
      constant groups, both solving 0/5 seeds), so the claimed improvement is absent.
    - ``"undecided"``: otherwise, i.e. the interval contains 0 with nonzero width (the seeds
      cannot tell the groups apart at this budget); also whenever a group has fewer than 2 seeds
      or the interval is not finite.
    """
    if ci.n_a < 2 or ci.n_b < 2 or not (np.isfinite(ci.lo) and np.isfinite(ci.hi)):
        return "undecided"
    if ci.lo == 0.0 and ci.hi == 0.0:
        return "does not hold"
    if higher_is_better:
        if ci.lo > 0.0:
            return "holds"
        if ci.hi < 0.0:
            return "does not hold"
    else:
        if ci.hi < 0.0:
            return "holds"
        if ci.lo > 0.0:
            return "does not hold"
    return "undecided"


def fmt(v: Any) -> str:
    """A number as the tables and the evidence show it (3 significant digits, "n/a" if NaN)."""
    if isinstance(v, float):
        return "n/a" if not np.isfinite(v) else f"{v:.3g}" if abs(v) < 1000 else f"{v:.0f}"
    return str(v)
