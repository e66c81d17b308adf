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


def test_the_random_layer_widens_to_the_observation_up_to_its_cap() -> None:
    """blr.random_features_max: the layer is as wide as a one-hot observation has entries (deep
    sea N = 30: 900 cells), never narrower than random_features, never wider than the cap; 0
    keeps the fixed width (the general preset's), and no random features stays none."""
    import gymnasium as gym

    from farsighter.agents.farsighter_posterior import seeded_torso
    from farsighter.config import BLRConfig
    from farsighter.config.presets import make_config
    from farsighter.networks import RandomFeatureTorso

    blr = BLRConfig(random_features=512, random_features_max=1024)
    widths = [blr.random_feature_width(n) for n in (4, 512, 576, 900, 1024, 28_224)]
    assert widths == [512, 512, 576, 900, 1024, 1024]
    assert BLRConfig(random_features=512).random_feature_width(900) == 512  # no cap: fixed
    assert BLRConfig(random_features_max=1024).random_feature_width(900) == 0  # none stays none
    cfg = make_config(
        "farsighter", "farsighter/DeepSea30-v0", hidden_sizes=(8,), blr__random_features_max=1024
    )
    space = gym.spaces.Box(0.0, 1.0, (900,), dtype=np.float32)
    torso, init_AD = seeded_torso(cfg, space, 2)
    assert isinstance(torso, RandomFeatureTorso) and torso.width == 900
    assert init_AD.shape == (2, 8 + 900)  # the posterior is over all of them
    from farsighter.train import random_features_note

    assert random_features_note(blr.random_feature_width(900), (900,), "e") is None
