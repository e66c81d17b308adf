"""Adaptive horizon k of Farsighter (paper section 4.5, Algorithm 1 line 7, SPEC 2.1).

After every posterior refresh the agent measures the Q-variance (mean over the refresh states of
phi^T Cov_a phi at the greedy action, see ``farsighter.ops.blr.greedy_predictive_variance``) and
nudges k by one step towards the variance target epsilon: too little uncertainty means look
further ahead (k + 1), too much means look less far (k - 1).
"""

from __future__ import annotations

import math
import numbers

from farsighter.config import AdaptiveKConfig

__all__ = ["adapt_k", "after_refresh"]


def adapt_k(k: int, q_variance: float, target: float, k_min: int, k_max: int) -> int:
    """One step of Algorithm 1 line 7.

    If ``q_variance < target``: k + 1; if ``q_variance > target``: k - 1; if equal: k unchanged.
    The result is clamped to [k_min, k_max] (so a k outside the bounds is brought back inside).

    Args:
        k: current horizon.
        q_variance: measured Q-variance (finite, >= 0 in practice).
        target: the variance target epsilon.
        k_min: smallest allowed k, an integer >= 1.
        k_max: largest allowed k, an integer >= k_min.

    Returns:
        The new k.

    Raises:
        ValueError: k, k_min or k_max is not an integer, the bounds are invalid, or q_variance /
            target is NaN.
    """
    for name, value in (("k", k), ("k_min", k_min), ("k_max", k_max)):
        if not isinstance(value, numbers.Integral) or isinstance(value, bool):
            raise ValueError(f"{name} must be an integer, got {value!r}")
    if k_min < 1:
        raise ValueError(f"k_min must be an integer >= 1, got {k_min}")
    if k_min > k_max:
        raise ValueError(f"k_min must be <= k_max, got k_min={k_min}, k_max={k_max}")
    if math.isnan(q_variance) or math.isnan(target):
        raise ValueError(
            f"q_variance and target must be numbers (not NaN), got {q_variance}, {target}"
        )
    if q_variance < target:
        k += 1
    elif q_variance > target:
        k -= 1
    return int(min(max(k, k_min), k_max))


def after_refresh(k: int, q_variance: float, ak: AdaptiveKConfig) -> tuple[int, bool]:
    """Algorithm 1 line 7 after a posterior refresh: the new k, and whether to empty the replay.

    With adaptive k off, k stays and nothing is emptied. Otherwise k moves by :func:`adapt_k`, and
    the replay is emptied at every refresh (``ak.empty_every_refresh``, the line read literally)
    or when k changed (``ak.empty_buffer``).
    """
    if not ak.enabled:
        return k, False
    new_k = adapt_k(k, q_variance, ak.variance_target, ak.k_min, ak.k_max)
    return new_k, ak.empty_every_refresh or (ak.empty_buffer and new_k != k)
