"""MinAtar (Young & Tian 2019): its ids, channels-first 0/1 planes, the MinAtar CNN, the
one-line error without the extra, the auto preset, and every discrete agent training on it."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

pytest.importorskip("minatar", reason="MinAtar tests need the atari extra")

import farsighter  # noqa: E402
from farsighter.config import is_atari_id, make_config, resolve_preset_name  # noqa: E402
from farsighter.envs import frame_stack_of, make_env  # noqa: E402
from farsighter.envs.minatar import (  # noqa: E402
    MINATAR_GAMES,
    is_minatar_id,
    minatar_id,
    register_minatar,
)
from farsighter.errors import EnvError  # noqa: E402
from farsighter.networks import (  # noqa: E402
    MinAtarCNN,
    MinAtarConvTrunk,
    NatureCNN,
    make_torso,
    make_trunk,
)

torch.set_num_threads(1)

# Object planes and minimal action sets of minatar 1.0.15 (``-v1`` ids).
CHANNELS = {"Asterix": 4, "Breakout": 4, "Freeway": 7, "Seaquest": 10, "SpaceInvaders": 6}
ACTIONS = {"Asterix": 5, "Breakout": 3, "Freeway": 3, "Seaquest": 6, "SpaceInvaders": 4}


def test_ids_register() -> None:
    assert MINATAR_GAMES == tuple(CHANNELS)
    assert minatar_id("Breakout") == "MinAtar/Breakout-v1"
    assert is_minatar_id("MinAtar/Seaquest-v1") and is_minatar_id("minatar.gym:MinAtar/Freeway-v0")
    assert not is_minatar_id("ALE/Breakout-v5") and not is_minatar_id("CartPole-v1")
    with pytest.raises(EnvError, match="accepted: Asterix"):
        minatar_id("Pong")
    register_minatar("MinAtar/Breakout-v1")
    for game in MINATAR_GAMES:
        assert minatar_id(game) in gym.registry
        assert f"MinAtar/{game}-v0" in gym.registry  # the full six-action set


@pytest.mark.parametrize("game", MINATAR_GAMES)
def test_observations_are_channels_first_bytes(game: str) -> None:
    cfg = make_config("ddqn", minatar_id(game))
    assert frame_stack_of(cfg) == 1
    env = make_env(cfg, seed=0)
    c = CHANNELS[game]
    assert env.observation_space.shape == (c, 10, 10)
    assert env.observation_space.dtype == np.uint8
    assert isinstance(env.action_space, gym.spaces.Discrete)
    assert env.action_space.n == ACTIONS[game]
    obs, _ = env.reset(seed=0)
    seen = [obs]
    for _ in range(50):
        obs, _, terminated, truncated, _ = env.step(env.action_space.sample())
        seen.append(obs)
        if terminated or truncated:
            obs, _ = env.reset()
            seen.append(obs)
    for o in seen:
        assert o.shape == (c, 10, 10) and o.dtype == np.uint8 and o.flags.c_contiguous
        assert set(np.unique(o)) <= {0, 1}
        assert env.observation_space.contains(o)
    assert any(o.any() for o in seen)
    env.close()


def test_minatar_torso_and_trunk() -> None:
    space = gym.spaces.Box(0, 1, (4, 10, 10), dtype=np.uint8)
    torso = make_torso(space, (64, 64))
    assert isinstance(torso, MinAtarCNN) and torso.out_dim == 128
    conv = torso.conv[0]
    assert isinstance(conv, torch.nn.Conv2d)
    assert (conv.out_channels, conv.kernel_size, conv.stride) == (16, (3, 3), (1, 1))
    planes = torch.randint(0, 2, (5, 4, 10, 10), dtype=torch.uint8)
    out = torso(planes)
    assert out.shape == (5, 128)
    assert torch.equal(out, torso(planes.bool()))  # 0/1 planes, not scaled by 255
    trunk, width = make_trunk(space, (64, 64))
    assert isinstance(trunk, MinAtarConvTrunk) and (trunk.out_dim, width) == (1024, 128)
    assert trunk(planes).shape == (5, 1024)
    # Atari frames keep the Nature CNN.
    assert isinstance(make_torso(gym.spaces.Box(0, 255, (4, 84, 84), np.uint8), ()), NatureCNN)


def test_missing_package_is_one_line(monkeypatch: pytest.MonkeyPatch) -> None:
    for key in [k for k in gym.registry if k.startswith("MinAtar/")]:
        monkeypatch.delitem(gym.registry, key)
    monkeypatch.setitem(sys.modules, "minatar", None)  # import raises ImportError
    monkeypatch.setitem(sys.modules, "minatar.gym", None)
    register_minatar("CartPole-v1")  # other ids never import it
    cfg = make_config("ddqn", "MinAtar/Breakout-v1")
    with pytest.raises(EnvError) as err:
        make_env(cfg, seed=0)
    message = str(err.value)
    assert "\n" not in message
    assert message == (
        "'MinAtar/Breakout-v1' is a MinAtar task; install the Atari extra: "
        "pip install 'farsighter[atari]'"
    )


def test_auto_preset_is_minatar_not_atari() -> None:
    # MinAtar is not ALE: no Atari preprocessing or frame stack; auto gives the minatar preset.
    assert not is_atari_id("MinAtar/Breakout-v1")
    for algo in ("ddqn", "kddqn", "bdqn", "farsighter", "ob2i", "rnd"):
        assert resolve_preset_name("auto", "MinAtar/Breakout-v1", algo) == "minatar"
    cfg = make_config("farsighter", "MinAtar/Breakout-v1")
    assert cfg.preset == "minatar" and frame_stack_of(cfg) == 1
    # Young & Tian's DQN: 100k buffer, one update per step, target copied every 1k steps.
    assert (cfg.buffer_size, cfg.train_every, cfg.target_update_every) == (100_000, 1, 1_000)


@pytest.mark.parametrize("algo", ["ddqn", "kddqn", "bdqn", "farsighter", "ob2i", "rnd"])
def test_every_discrete_agent_trains_on_minatar(tmp_path: Path, algo: str) -> None:
    cfg = make_config(
        algo,
        "MinAtar/Breakout-v1",
        total_steps=300,
        learning_starts=100,
        buffer_size=1_000,
        target_update_every=100,
        eval_every=0,
        eval_episodes=1,
        eval_max_steps=500,
        checkpoint_every=0,
        save_replay=False,
        blr__posterior_every=100,
        blr__posterior_samples=200,
        progress=False,
        torch_threads=1,
        run_dir=str(tmp_path / algo),
    )
    summary = farsighter.train(cfg)
    saved = json.loads((tmp_path / algo / "summary.json").read_text())
    assert saved["global_step"] == summary["global_step"] == 300
    assert np.isfinite(summary["final_eval_return"])
