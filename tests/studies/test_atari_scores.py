"""Random/human reference scores of the 49 games of Table 2, human-normalised scores, the ALE-id
mapping, and the evaluation protocol's episode cap (108,000 frames)."""

from __future__ import annotations

import math

import pytest

from farsighter.envs.atari import ATARI_49, TABLE2, ale_id, ale_name, game_of
from farsighter.envs.atari_scores import (
    BASELINES,
    Baseline,
    baseline,
    human_normalized,
    normalized_scores,
)
from farsighter.errors import ConfigError


def test_every_game_of_table_2_has_random_and_human_scores() -> None:
    assert len(ATARI_49) == 49
    assert list(BASELINES) == list(ATARI_49) == list(TABLE2)
    for game, ref in BASELINES.items():
        assert math.isfinite(ref.random) and math.isfinite(ref.human), game
        assert ref.human > ref.random, game  # so the normalisation never divides by <= 0


def test_values_that_needed_a_name_mapping() -> None:
    # DQN Zoo, dqn_zoo/atari_data.py (google-deepmind/dqn_zoo at 359945dc): its snake-case names
    # hero, jamesbond, montezuma_revenge, private_eye, qbert, riverraid, up_n_down.
    assert BASELINES["Hero"] == Baseline(1027.0, 30826.4)
    assert BASELINES["Jamesbond"] == Baseline(29.0, 302.8)
    assert BASELINES["MontezumaRevenge"] == Baseline(0.0, 4753.3)
    assert BASELINES["PrivateEye"] == Baseline(24.9, 69571.3)
    assert BASELINES["Qbert"] == Baseline(163.9, 13455.0)
    assert BASELINES["Riverraid"] == Baseline(1338.5, 17118.0)
    assert BASELINES["UpNDown"] == Baseline(533.4, 11693.2)


def test_human_is_one_and_random_is_zero_on_every_game() -> None:
    for game, ref in BASELINES.items():
        assert human_normalized(game, ref.human) == pytest.approx(1.0, abs=1e-12), game
        assert human_normalized(game, ref.random) == pytest.approx(0.0, abs=1e-12), game


def test_normalised_scores_on_hand_computed_values() -> None:
    # Breakout: random 1.7, human 30.5 (DQN Zoo, dqn_zoo/atari_data.py); Farsighter's Table 2
    # score 597.2 -> (597.2 - 1.7) / (30.5 - 1.7) = 595.5 / 28.8 = 20.6770833...
    assert baseline("Breakout") == Baseline(1.7, 30.5)
    assert human_normalized("Breakout", 597.2) == pytest.approx(595.5 / 28.8)
    assert human_normalized("Breakout", 597.2) == pytest.approx(20.6770833, abs=1e-6)
    # Pong: random -20.7, human 14.6; 20.25 -> 40.95 / 35.3 = 1.1600566...
    assert human_normalized("Pong", 20.25) == pytest.approx(1.1600566, abs=1e-6)
    # Double Dunk: random -18.6, human -16.4; the midpoint -17.5 -> 0.5; a score below random
    # is negative: -20.8 -> -2.2 / 2.2 = -1.
    assert human_normalized("DoubleDunk", -17.5) == pytest.approx(0.5)
    assert human_normalized("DoubleDunk", -20.8) == pytest.approx(-1.0)


def test_normalized_scores_of_a_mapping() -> None:
    raw = {"Pong": 14.6, "Breakout": 1.7, "DoubleDunk": -17.5}
    out = normalized_scores(raw)
    assert list(out) == list(raw)  # the mapping's order and keys
    assert out == pytest.approx({"Pong": 1.0, "Breakout": 0.0, "DoubleDunk": 0.5})
    assert all(type(v) is float for v in out.values())
    assert normalized_scores({}) == {}
    # All of Table 2's Farsighter column normalises.
    table = normalized_scores({g: s.farsighter for g, s in TABLE2.items()})
    assert len(table) == 49 and table["Breakout"] == pytest.approx(595.5 / 28.8)


@pytest.mark.parametrize(
    ("name", "hint"),
    [
        ("breakout", "did you mean 'Breakout'?"),
        ("montezumarevenge", "did you mean 'MontezumaRevenge'?"),
        ("ALE/Breakout-v5", "an environment id; its game is 'Breakout'"),
        ("ALE/breakout-v5", "did you mean 'Breakout'?"),
        ("Pitfall", ""),  # an Atari-57 game outside Table 2
        ("CartPole-v1", ""),
    ],
)
def test_unknown_game_is_a_one_line_config_error(name: str, hint: str) -> None:
    with pytest.raises(ConfigError) as info:
        human_normalized(name, 1.0)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"unknown Atari game '{name}'")
    assert hint in message
    assert "accepted: the game of an id ALE/<game>-v5 among the 49 games of Table 2" in message
    with pytest.raises(ConfigError):
        normalized_scores({"Pong": 0.0, name: 1.0})


def test_ale_id_maps_back_to_the_game() -> None:
    for game in ATARI_49:
        assert game_of(ale_id(game)) == game
    assert game_of("ALE/Breakout-v5") == "Breakout"
    assert game_of("BreakoutNoFrameskip-v4") == "Breakout"
    assert game_of("ale_py:ALE/MontezumaRevenge-v5") == "MontezumaRevenge"
    # An ALE game outside Table 2 has no key (ale_name still reads it).
    assert game_of("ALE/Pitfall-v5") is None and ale_name("ALE/Pitfall-v5") == "Pitfall"
    assert game_of("ALE/breakout-v5") is None and ale_name("ALE/breakout-v5") == "breakout"
    for other in ("CartPole-v1", "farsighter/BridgeMaze-v0", "MiniGrid-DoorKey-8x8-v0", "ALE/"):
        assert game_of(other) is None and ale_name(other) is None, other
    assert game_of("Breakout") is None  # a game key is not an id


def test_every_game_is_a_registered_ale_id() -> None:
    ale_py = pytest.importorskip("ale_py")
    import gymnasium as gym

    gym.register_envs(ale_py)
    assert [g for g in ATARI_49 if ale_id(g) not in gym.registry] == []


def test_atari_evaluation_protocol_defaults() -> None:
    pytest.importorskip("ale_py")
    from farsighter.config import make_config
    from farsighter.envs import make_env

    cfg = make_config("ddqn", "ALE/Breakout-v5")
    # 27,000 agent steps x frame skip 4 = ALE v5's 108,000-frame episode cap.
    assert cfg.eval_max_steps * cfg.atari.frame_skip == 108_000
    assert cfg.atari.noop_max == 30 and cfg.atari.repeat_action_probability == 0.0
    env = make_env(cfg, seed=0, training=False)
    ale = env.unwrapped.ale  # type: ignore[attr-defined]
    assert ale.getInt("max_num_frames_per_episode") == 108_000
    assert ale.getFloat("repeat_action_probability") == 0.0
    env.close()


@pytest.mark.parametrize("training", [False, True])
def test_wrap_atari_truncates_at_the_frame_cap(training: bool) -> None:
    # The cap counts emulator frames: 400 frames are 100 agent steps at frame skip 4. Breakout
    # never launches its ball without FIRE, so only the cap can end a NOOP episode.
    ale_py = pytest.importorskip("ale_py")
    import gymnasium as gym

    from farsighter.envs.atari import wrap_atari

    gym.register_envs(ale_py)
    base = gym.make(
        "ALE/Breakout-v5",
        frameskip=1,
        repeat_action_probability=0.0,
        max_num_frames_per_episode=400,
    )
    env = wrap_atari(
        base,
        frame_skip=4,
        noop_max=0,
        screen_size=84,
        frame_stack=4,
        training=training,
        terminal_on_life_loss=True,
        clip_rewards=True,
    )
    env.reset(seed=0)
    steps, terminated, truncated, info = 0, False, False, {}
    while not (terminated or truncated) and steps < 200:
        _, _, terminated, truncated, info = env.step(0)
        steps += 1
    assert (steps, terminated, truncated) == (100, False, True)
    assert info["episode"]["l"] == 100
    env.reset()  # a truncated game restarts, also behind the training life-loss wrapper
    assert env.unwrapped.ale.getEpisodeFrameNumber() == 0  # type: ignore[attr-defined]
    env.close()
