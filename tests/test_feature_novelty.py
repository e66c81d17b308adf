"""The novel fraction of a new cell's random features (benchmarks/feature_novelty.py)."""

import numpy as np

from benchmarks.feature_novelty import deep_sea_psi, novelty


def test_a_row_in_the_seen_span_is_not_novel_and_an_orthogonal_one_is() -> None:
    seen = np.eye(4)[:2] * 0.5  # two seen rows spanning the first two axes
    inside = novelty(np.array([0.3, -0.2, 0.0, 0.0]), seen, visits=10)
    outside = novelty(np.array([0.0, 0.0, 0.5, 0.0]), seen, visits=10)
    assert inside["novel_fraction"] < 1e-12
    assert abs(outside["novel_fraction"] - 1.0) < 1e-12
    # the posterior keeps its prior width only off the seen span
    assert outside["sd_new_over_seen"] > 1.5 > inside["sd_new_over_seen"]


def test_the_random_layer_runs_out_of_directions_once_cells_outnumber_it() -> None:
    psi = deep_sea_psi(12, 32, seed=1)  # 144 cells over 32 random features
    assert psi.shape == (144, 32) and (psi >= 0).all()
    few, many = psi[:10], psi[:100]
    new = psi[143]
    assert novelty(new, few, 10)["novel_fraction"] > 0.2
    assert novelty(new, many, 10)["novel_fraction"] < 1e-9  # 100 rows span all 32 directions


def test_a_run_is_told_when_its_observation_outgrows_the_random_layer() -> None:
    from farsighter.train import random_features_note

    assert random_features_note(0, (576,), "e") is None  # no random layer: nothing to say
    assert random_features_note(512, (400,), "e") is None
    wide = random_features_note(512, (576,), "farsighter/DeepSea24-v0")
    assert wide is not None and "576 entries" in wide and "512 random features" in wide
    image = random_features_note(512, (4, 84, 84), "ALE/Breakout-v5")
    assert image is not None and "images" in image
