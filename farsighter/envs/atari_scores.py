"""Random and human reference scores of the 49 Atari games of Table 2, and human-normalised scores.

A human-normalised score maps a game's raw score linearly so that random play is 0 and the human
reference is 1: ``(score - random) / (human - random)``.

Source of the numbers: DQN Zoo (Quan and Ostrovski, DeepMind 2020), ``dqn_zoo/atari_data.py`` of
https://github.com/google-deepmind/dqn_zoo (read at commit 359945dcb6f6a04f16e380b210c4f22b57681905,
unchanged at 45061f4bbbcfa87d11bbba3cfc2305a650a41c26). Only the numbers are taken over. That file
describes them as undiscounted returns averaged over at least 3 episodes of a uniformly random
agent and of a professional human game tester, each episode starting with 1 to 30 (uniform) no-op
actions and capped at 108,000 frames (30 minutes); it names no paper. The random-agent and
professional-tester baselines were introduced by Mnih et al. (2015, Nature, "Human-level control
through deep reinforcement learning"); the human values here are the later ones (e.g. Alien 7127.7,
not the Nature paper's 6875) that DeepMind's no-op-start results report, e.g. Wang et al. (2016,
"Dueling network architectures for deep reinforcement learning", ICML). The attribution to those
papers is ours, not DQN Zoo's; the numbers are DQN Zoo's.

Keys are the ALE names of `farsighter.envs.atari.TABLE2` (``ALE/<key>-v5``). DQN Zoo spells them in
snake case; every one of the 49 is that key's CamelCase split at the capitals and lower-cased
(``Hero`` = ``hero``, ``Jamesbond`` = ``jamesbond``, ``Qbert`` = ``qbert``, ``Riverraid`` =
``riverraid``, ``MontezumaRevenge`` = ``montezuma_revenge``, ``PrivateEye`` = ``private_eye``,
``UpNDown`` = ``up_n_down``). The 8 Atari-57 games outside Table 2 (Berzerk, Defender, Phoenix,
Pitfall, Skiing, Solaris, Surround, YarsRevenge) are left out.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import NamedTuple

from farsighter.envs.atari import ale_name, game_of
from farsighter.errors import ConfigError


class Baseline(NamedTuple):
    """Reference scores of one game (raw, undiscounted episode returns)."""

    random: float
    """Uniformly random actions."""
    human: float
    """Professional human game tester."""


BASELINES: dict[str, Baseline] = {
    "Alien": Baseline(227.8, 7127.7),
    "Amidar": Baseline(5.8, 1719.5),
    "Assault": Baseline(222.4, 742.0),
    "Asterix": Baseline(210.0, 8503.3),
    "Asteroids": Baseline(719.1, 47388.7),
    "Atlantis": Baseline(12850.0, 29028.1),
    "BankHeist": Baseline(14.2, 753.1),
    "BattleZone": Baseline(2360.0, 37187.5),
    "BeamRider": Baseline(363.9, 16926.5),
    "Bowling": Baseline(23.1, 160.7),
    "Boxing": Baseline(0.1, 12.1),
    "Breakout": Baseline(1.7, 30.5),
    "Centipede": Baseline(2090.9, 12017.0),
    "ChopperCommand": Baseline(811.0, 7387.8),
    "CrazyClimber": Baseline(10780.5, 35829.4),
    "DemonAttack": Baseline(152.1, 1971.0),
    "DoubleDunk": Baseline(-18.6, -16.4),
    "Enduro": Baseline(0.0, 860.5),
    "FishingDerby": Baseline(-91.7, -38.7),
    "Freeway": Baseline(0.0, 29.6),
    "Frostbite": Baseline(65.2, 4334.7),
    "Gopher": Baseline(257.6, 2412.5),
    "Gravitar": Baseline(173.0, 3351.4),
    "Hero": Baseline(1027.0, 30826.4),
    "IceHockey": Baseline(-11.2, 0.9),
    "Jamesbond": Baseline(29.0, 302.8),
    "Kangaroo": Baseline(52.0, 3035.0),
    "Krull": Baseline(1598.0, 2665.5),
    "KungFuMaster": Baseline(258.5, 22736.3),
    "MontezumaRevenge": Baseline(0.0, 4753.3),
    "MsPacman": Baseline(307.3, 6951.6),
    "NameThisGame": Baseline(2292.3, 8049.0),
    "Pong": Baseline(-20.7, 14.6),
    "PrivateEye": Baseline(24.9, 69571.3),
    "Qbert": Baseline(163.9, 13455.0),
    "Riverraid": Baseline(1338.5, 17118.0),
    "RoadRunner": Baseline(11.5, 7845.0),
    "Robotank": Baseline(2.2, 11.9),
    "Seaquest": Baseline(68.4, 42054.7),
    "SpaceInvaders": Baseline(148.0, 1668.7),
    "StarGunner": Baseline(664.0, 10250.0),
    "Tennis": Baseline(-23.8, -8.3),
    "TimePilot": Baseline(3568.0, 5229.2),
    "Tutankham": Baseline(11.4, 167.6),
    "UpNDown": Baseline(533.4, 11693.2),
    "Venture": Baseline(0.0, 1187.5),
    # Random play scores close to the human reference here, so normalised scores are large.
    "VideoPinball": Baseline(16256.9, 17667.9),
    "WizardOfWor": Baseline(563.5, 4756.5),
    "Zaxxon": Baseline(32.5, 9173.3),
}


def baseline(game: str) -> Baseline:
    """The reference scores of ``game`` (a key of TABLE2 such as ``Breakout``); a one-line
    ConfigError for any other name."""
    try:
        return BASELINES[game]
    except KeyError:
        raise ConfigError(_unknown_game(game)) from None


def _unknown_game(game: str) -> str:
    hint = ""
    key = game_of(game)
    if key is not None:
        hint = f" (an environment id; its game is '{key}')"
    else:
        near = [g for g in BASELINES if g.lower() == (ale_name(game) or game).lower()]
        if near:
            hint = f" (did you mean '{near[0]}'?)"
    return (
        f"unknown Atari game '{game}'{hint}; accepted: the game of an id ALE/<game>-v5 among "
        f"the {len(BASELINES)} games of Table 2, spelt as there, e.g. Breakout, MontezumaRevenge "
        "(farsighter.envs.atari.ATARI_49)"
    )


def human_normalized(game: str, score: float) -> float:
    """``(score - random) / (human - random)`` of ``game``: 0 is random play, 1 the human
    reference (DQN Zoo's numbers; see the module docstring)."""
    ref = baseline(game)
    return (float(score) - ref.random) / (ref.human - ref.random)


def normalized_scores(game_to_score: Mapping[str, float]) -> dict[str, float]:
    """Human-normalised score of each game of ``{game: raw score}``, in the mapping's order.
    Every game is checked before any is computed, so one unknown name fails the whole call."""
    for game in game_to_score:
        baseline(game)
    return {game: human_normalized(game, score) for game, score in game_to_score.items()}
