"""blr.random_features: fixed random features of the observation beside the learned ones, so
that the posterior's uncertainty is about states."""

from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch

from farsighter import make_config, train
from farsighter.cli import main
from farsighter.config import validate
from farsighter.errors import ConfigError
from farsighter.networks import MLPTorso, RandomFeatureTorso
from farsighter.ops.blr import BLRHead
from farsighter.seeds import batchable
from tests.conftest import inner


def test_the_torso_appends_fixed_random_relu_features() -> None:
    torch.manual_seed(0)
    torso = RandomFeatureTorso(MLPTorso(6, (8, 5)), 6, 16)
    assert torso.out_dim == 5 + 16
    # the random layer is not trained: buffers, not parameters, and saved with the weights
    assert list(torso.parameters()) == list(torso.torso.parameters())
    assert {"rf_weight", "rf_bias"} <= set(torso.state_dict())
    x = torch.randn(3, 6)
    out = torso(x)
    torch.testing.assert_close(out[:, :5], torso.torso(x))
    psi = torch.relu(x @ torso.rf_weight.T + torso.rf_bias) / math.sqrt(16)
    torch.testing.assert_close(out[:, 5:], psi)
    twin = copy.deepcopy(torso)  # the target torso: the same random features
    torch.testing.assert_close(twin(x), out)
    # a one-hot observation's features have a squared norm of about 1 (E relu(N(0, 2))^2 = 1)
    wide = RandomFeatureTorso(MLPTorso(400, (8,)), 400, 4096)
    norms = wide(torch.eye(400))[:, 8:].square().sum(1)
    assert norms.mean().item() == pytest.approx(1.0, abs=0.05)


def test_an_online_torso_and_its_target_share_their_random_features(tmp_path: Path) -> None:
    """online_and_target computes psi(s') once for both torsos: the same numbers as two
    forwards, after training moved the online torso away from its target, and the random
    layers equal in both after the target copy and a checkpoint load (what the sharing needs)."""
    from farsighter.agents import build_agent
    from farsighter.networks import online_and_target

    cfg = make_config(
        "farsighter",
        "farsighter/DeepSea6-v0",
        total_steps=1_200,
        learning_starts=200,
        target_update_every=700,
        eval_every=0,
        eval_episodes=1,
        progress=False,
        run_dir=str(tmp_path / "run"),
        torch_threads=1,
        **{"blr.random_features": 32},
    )
    train(cfg)
    env = gym.make("farsighter/DeepSea6-v0")
    agent = build_agent(
        cfg, env.observation_space, env.action_space, frame_stack=1, device=torch.device("cpu")
    )
    agent.load_state_dict(
        torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=False)["agent"]
    )
    online, target = inner(agent).torso.net, inner(agent).loss.torso_target.net
    assert isinstance(online, RandomFeatureTorso) and isinstance(target, RandomFeatureTorso)
    assert torch.equal(online.rf_weight, target.rf_weight)
    assert torch.equal(online.rf_bias, target.rf_bias)
    obs = torch.from_numpy(np.eye(36, dtype=np.float32))
    with torch.no_grad():
        shared_online, shared_target = online_and_target(online, target, obs)
        assert not torch.equal(online(obs), target(obs))  # the online torso has moved
        assert torch.equal(shared_online, online(obs))
        assert torch.equal(shared_target, target(obs))


def _sd_by_visits(
    random_features: int, tmp: Path, **overrides: Any
) -> tuple[float, float, BLRHead]:
    """Farsighter on deep sea N = 6 for 600 episodes (learning from step 1,000): the median
    predictive sd of the cells the run never can reach (above the diagonal) and of the six cells
    it visited most, and the trained posterior."""
    n, seen = 6, {}

    class Keep:
        def on_step(self, global_step: int, info: dict[str, Any], agent: Any) -> None:
            pass

        def on_finish(self, run_dir: Path, agent: Any) -> None:
            seen["agent"] = agent

    cfg = make_config(
        "farsighter",
        f"farsighter/DeepSea{n}-v0",
        total_steps=n * 600,
        eval_every=0,
        eval_episodes=1,
        progress=False,
        run_dir=str(tmp / f"rf{random_features}{len(overrides)}"),
        torch_threads=1,
        **{"blr.random_features": random_features, **overrides},
    )
    train(cfg, [Keep()])
    agent = seen["agent"]
    replay = inner(agent).replay
    rows = int(replay.count[0])
    frames = replay.frames[0, :rows].reshape(rows, -1)
    visits = np.bincount(frames[frames.max(1) > 0].argmax(1), minlength=n * n).reshape(n, n)
    _, var = agent.q_estimate(np.eye(n * n, dtype=np.float32))
    sd = np.sqrt(var).max(1).reshape(n, n)
    row, col = np.indices((n, n))
    often = visits >= np.sort(visits[col <= row])[-6]  # the six most visited cells
    head = inner(agent).parts[0].head
    return float(np.median(sd[col > row])), float(np.median(sd[often])), head


def test_with_random_features_the_posterior_is_wide_where_the_run_has_not_been(
    tmp_path: Path,
) -> None:
    unreachable, visited, _ = _sd_by_visits(128, tmp_path)
    with_random = unreachable / visited
    assert with_random > 2.5  # measured: 20.5 (0.58 against 0.028; 3.5 when they fitted values)
    # over the learned features alone the sd barely follows the visits (measured: 2.0)
    unreachable, visited, _ = _sd_by_visits(0, tmp_path)
    assert with_random > 2 * unreachable / visited


def test_random_features_that_fit_no_target_widen_the_draws_where_the_run_has_not_been(
    tmp_path: Path,
) -> None:
    """blr.random_features_fit False: the values are the learned features' alone (the random
    block's mean stays exactly 0), and the random block still widens the draws where the run
    has not been."""
    unreachable, visited, head = _sd_by_visits(128, tmp_path, **{"blr.random_features_fit": False})
    assert head.fit_dim == head.dim - 128
    assert torch.count_nonzero(head.mean_AD[:, head.fit_dim :]) == 0
    assert torch.count_nonzero(head.mean_AD[:, : head.fit_dim]) > 0
    cov_ADD = head.cov_ADD
    assert torch.count_nonzero(cov_ADD[:, : head.fit_dim, head.fit_dim :]) == 0
    assert unreachable / visited > 5  # measured: 20 (0.58 against 0.028)


def test_random_features_are_checked_and_their_seeds_batch(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(ConfigError, match="blr.random_features must be >= 0"):
        validate(make_config("farsighter", "CartPole-v1", **{"blr.random_features": -1}))
    with pytest.raises(ConfigError, match="blr.random_features_max must be >= 0"):
        validate(make_config("farsighter", "CartPole-v1", **{"blr.random_features_max": -1}))
    cfg = make_config("farsighter", "CartPole-v1", **{"blr.random_features": 32})
    learned = make_config("farsighter", "CartPole-v1", **{"blr.random_features": 0})
    # the fixed random layer stacks as buffers, so seeds batch with or without it
    assert batchable(cfg) and batchable(learned)
    # image observations keep the learned features, and the run says so in one line
    from farsighter.agents.farsighter_posterior import seeded_torso
    from farsighter.networks import MinAtarCNN

    image = gym.spaces.Box(0, 1, (4, 10, 10), np.float32)
    torso, init_AD = seeded_torso(cfg, image, 3)
    assert isinstance(torso, MinAtarCNN) and init_AD.shape == (3, torso.out_dim)
    flat, _ = seeded_torso(cfg, gym.spaces.Box(-1, 1, (4,), np.float32), 2)
    assert isinstance(flat, RandomFeatureTorso) and flat.out_dim == 128 + 32
    run = tmp_path / "img"
    argv = ["train", "--algo", "farsighter", "--env", "MinAtar/Breakout-v1", "--total-steps"]
    argv += ["20", "--eval-every", "0", "--eval-episodes", "1", "--no-progress"]
    code = main([*argv, "--blr.random-features", "8", "--run-dir", str(run)])
    err = capsys.readouterr().err.strip()
    assert code == 0 and "keep the learned features alone" in err


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
    sea N = 30: 900 cells), never narrower than random_features, never wider than the cap (1,024
    by default); 0 keeps the fixed width, and no random features stays none."""
    from farsighter.agents.farsighter_posterior import seeded_torso
    from farsighter.config import BLRConfig

    blr = BLRConfig(random_features=512, random_features_max=1024)
    widths = [blr.random_feature_width(n) for n in (4, 512, 576, 900, 1024, 28_224)]
    assert widths == [512, 512, 576, 900, 1024, 1024]
    assert BLRConfig(random_features=512).random_feature_width(900) == 900  # the default cap
    fixed = BLRConfig(random_features=512, random_features_max=0)
    assert fixed.random_feature_width(900) == 512  # 0: the width as given
    assert BLRConfig(random_features_max=1024).random_feature_width(900) == 0  # none stays none
    cfg = make_config(
        "farsighter",
        "farsighter/DeepSea30-v0",
        hidden_sizes=(8,),
        blr__random_features=512,
        blr__random_features_max=1024,
    )
    space = gym.spaces.Box(0.0, 1.0, (900,), dtype=np.float32)
    torso, init_AD = seeded_torso(cfg, space, 2)
    assert isinstance(torso, RandomFeatureTorso) and torso.width == 900
    assert init_AD.shape == (2, 8 + 900)  # the posterior is over all of them
    from farsighter.train import random_features_note

    assert random_features_note(blr.random_feature_width(900), (900,), "e") is None
