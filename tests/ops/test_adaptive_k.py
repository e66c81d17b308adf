"""Tests of the adaptive-k rule of Algorithm 1 line 7."""

from __future__ import annotations

import pytest

from farsighter.ops.adaptive_k import adapt_k


def test_moves_towards_target() -> None:
    assert adapt_k(10, q_variance=0.1, target=0.5, k_min=1, k_max=100) == 11  # too little: k + 1
    assert adapt_k(10, q_variance=0.9, target=0.5, k_min=1, k_max=100) == 9  # too much: k - 1
    assert adapt_k(10, q_variance=0.5, target=0.5, k_min=1, k_max=100) == 10  # equal: unchanged


def test_respects_bounds() -> None:
    assert adapt_k(100, q_variance=0.0, target=1.0, k_min=1, k_max=100) == 100
    assert adapt_k(1, q_variance=2.0, target=1.0, k_min=1, k_max=100) == 1
    assert adapt_k(5, q_variance=2.0, target=1.0, k_min=5, k_max=5) == 5
    assert adapt_k(5, q_variance=0.0, target=1.0, k_min=5, k_max=5) == 5
    # a k outside the bounds is clamped back inside
    assert adapt_k(150, q_variance=0.5, target=0.5, k_min=1, k_max=20) == 20
    assert adapt_k(0, q_variance=0.5, target=0.5, k_min=3, k_max=20) == 3


def test_repeated_steps_walk_to_the_bound() -> None:
    k = 150
    for _ in range(200):
        k = adapt_k(k, q_variance=10.0, target=1.0, k_min=2, k_max=150)
    assert k == 2


@pytest.mark.parametrize(
    ("k_min", "k_max", "match"),
    [(0, 10, "k_min must be an integer >= 1"), (5, 4, "k_min must be <= k_max"), (1.5, 4, "int")],
)
def test_rejects_bad_bounds(k_min: int, k_max: int, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        adapt_k(3, q_variance=1.0, target=1.0, k_min=k_min, k_max=k_max)


def test_rejects_nan() -> None:
    with pytest.raises(ValueError, match="NaN"):
        adapt_k(3, q_variance=float("nan"), target=1.0, k_min=1, k_max=10)
