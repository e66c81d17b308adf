"""benchmarks.weights_hash: the refactoring check hashes every float tensor, in any order, and
can leave out a statistic a change adds."""

from __future__ import annotations

import torch

from benchmarks.weights_hash import _drop, weights_hash


def test_the_hash_sees_any_changed_value_but_not_the_order_and_can_leave_out_a_key() -> None:
    a, b = torch.arange(4.0), torch.ones(3)
    state = {"net": {"w": a, "b": b}, "blr": [{"mean": a * 2}], "steps": torch.tensor(5)}
    digest, leaves = weights_hash(state)
    assert leaves == 3  # the integer counter is not a weight
    regrouped = {"blr": {"m": a * 2}, "x": [b, a]}
    assert weights_hash(regrouped)[0] == digest
    moved = {"net": {"w": a, "b": b}, "blr": [{"mean": a * 2 + 1e-6}]}
    assert weights_hash(moved)[0] != digest
    added = {**state, "blr": [{"mean": a * 2, "weight_A": torch.ones(2)}]}
    assert weights_hash(added)[0] != digest
    assert weights_hash(_drop(added, frozenset({"weight_A"})))[0] == digest
