"""A study's claim, checked on per-seed values: one row of its table against another.

A claim says that row ``a`` beats row ``b`` on a :class:`Measure`; :func:`compare` decides it by a
percentile-bootstrap confidence interval of the difference (:mod:`farsighter.stats`) and writes
the evidence the report shows beside the verdict.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from farsighter.stats import DiffCI, Stat, bootstrap_diff, fmt, statistic, verdict

N_BOOT = 10_000
CONFIDENCE = 0.95
NOT_TESTED = "not tested"
VERDICT_TEXT = {
    "holds": "holds",
    "does not hold": "does not hold",
    "undecided": "undecided at this budget",
    NOT_TESTED: "not tested here",
}
"""The verdicts as the report writes them."""


@dataclass(frozen=True)
class Claim:
    """One checked claim: its text, the evidence, and the verdict (see :data:`VERDICT_TEXT`)."""

    claim: str
    evidence: str
    verdict: str
    ci: DiffCI | None = None


@dataclass(frozen=True)
class Measure:
    """How a per-seed metric is compared and shown."""

    key: str  # in each row's "per_seed"
    name: str  # shown in the evidence
    higher_is_better: bool
    stat: Stat = "mean"
    count: bool = False  # a 0/1 indicator: show the groups as solved/seeds


def _finite(x: Any) -> np.ndarray:
    v = np.asarray(x, dtype=float).reshape(-1)
    return v[np.isfinite(v)]


def _group(row: dict[str, Any], m: Measure, values: np.ndarray) -> str:
    if m.count:
        return f"{row['agent']} {int(values.sum())}/{values.size}"
    return f"{row['agent']} {fmt(statistic(values, m.stat))}"


def compare(claim: str, a: dict[str, Any], b: dict[str, Any], m: Measure) -> Claim:
    """``claim``: row ``a`` is better than row ``b`` on measure ``m``, read from the per-seed
    values of the rows (``row["per_seed"][m.key]``; NaN values are left out)."""
    x, y = _finite(a["per_seed"][m.key]), _finite(b["per_seed"][m.key])
    ci = bootstrap_diff(x, y, stat=m.stat, n_boot=N_BOOT, confidence=CONFIDENCE, seed=0)
    evidence = (
        f"{m.name}: {_group(a, m, x)}, {_group(b, m, y)}; difference {fmt(ci.diff)} "
        f"[{CONFIDENCE:.0%} CI {fmt(ci.lo)}, {fmt(ci.hi)}]"
    )
    return Claim(claim, evidence, verdict(ci, higher_is_better=m.higher_is_better), ci)
