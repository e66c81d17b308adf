"""Atari: the 49 games of the paper's Table 2 and the standard DQN preprocessing (SPEC section 3)."""

from __future__ import annotations

import re
from typing import Any, NamedTuple

import gymnasium as gym
import numpy as np


class PaperScores(NamedTuple):
    """Raw scores of Table 2 (OB2I's from Bai et al. 2021, at 20M frames)."""

    title: str
    farsighter: float
    ddqn: float
    bdqn: float
    ob2i: float


# The 49 games of Table 2, keyed by their ALE name (``ALE/<name>-v5``). Listed once, here.
TABLE2: dict[str, PaperScores] = {
    "Alien": PaperScores("Alien", 3762.50, 1620.00, 3167.20, 916.90),
    "Amidar": PaperScores("Amidar", 1934.20, 978.00, 1815.30, 94.00),
    "Assault": PaperScores("Assault", 7439.30, 4280.40, 5439.40, 2996.20),
    "Asterix": PaperScores("Asterix", 39556.40, 4359.00, 44438.30, 2719.00),
    "Asteroids": PaperScores("Asteroids", 2603.70, 1364.50, 2363.20, 959.90),
    "Atlantis": PaperScores("Atlantis", 3959257.80, 279987.00, 2823842.40, 3146300.00),
    "BankHeist": PaperScores("Bank Heist", 983.70, 455.00, 834.50, 378.60),
    "BattleZone": PaperScores("Battle Zone", 47936.70, 29900.00, 45348.40, 13454.50),
    "BeamRider": PaperScores("Beam Rider", 19504.80, 8627.50, 9456.30, 3736.70),
    "Bowling": PaperScores("Bowling", 54.62, 50.40, 38.40, 30.00),
    "Boxing": PaperScores("Boxing", 91.77, 88.00, 79.30, 75.10),
    "Breakout": PaperScores("Breakout", 597.20, 385.50, 392.60, 423.10),
    "Centipede": PaperScores("Centipede", 5936.10, 4657.70, 7134.70, 2661.80),
    "ChopperCommand": PaperScores("Chopper Command", 13940.60, 6126.00, 17363.60, 1100.30),
    "CrazyClimber": PaperScores("Crazy Climber", 149507.70, 110763.00, 137693.80, 53346.70),
    "DemonAttack": PaperScores("Demon Attack", 32233.61, 12149.40, 23595.40, 6794.60),
    "DoubleDunk": PaperScores("Double Dunk", 3.50, -6.60, -1.30, -18.20),
    "Enduro": PaperScores("Enduro", 1604.70, 729.00, 1496.50, 719.00),
    "FishingDerby": PaperScores("Fishing Derby", 3.80, -4.90, 27.30, -60.10),
    "Freeway": PaperScores("Freeway", 48.02, 30.80, 30.10, 32.10),
    "Frostbite": PaperScores("Frostbite", 1795.30, 797.40, 1643.60, 1277.30),
    "Gopher": PaperScores("Gopher", 19418.90, 8777.40, 13742.80, 6359.50),
    "Gravitar": PaperScores("Gravitar", 1175.81, 473.00, 589.30, 393.60),
    "Hero": PaperScores("H.E.R.O.", 22010.70, 20437.80, 21532.70, 3302.50),
    "IceHockey": PaperScores("Ice Hockey", -0.70, -1.90, -2.70, -4.20),
    "Jamesbond": PaperScores("James Bond", 1707.25, 768.50, 1593.70, 434.30),
    "Kangaroo": PaperScores("Kangaroo", 14651.80, 7259.00, 13596.30, 2387.00),
    "Krull": PaperScores("Krull", 13263.91, 8422.30, 9643.60, 45388.80),
    "KungFuMaster": PaperScores("Kung-Fu Master", 38734.99, 26059.00, 40563.70, 16272.20),
    "MontezumaRevenge": PaperScores("Montezumas Revenge", 413.60, 0.00, 0.00, 0.00),
    "MsPacman": PaperScores("Ms. Pac-Man", 3796.19, 3085.60, 3295.50, 1794.90),
    "NameThisGame": PaperScores("Name This Game", 12312.80, 8207.80, 10536.70, 8576.80),
    "Pong": PaperScores("Pong", 20.25, 19.50, 19.80, 18.70),
    "PrivateEye": PaperScores("Private Eye", 494.50, 146.70, 149.70, 1174.10),
    "Qbert": PaperScores("Q*Bert", 20788.47, 13117.30, 19530.60, 4275.00),
    "Riverraid": PaperScores("River Raid", 12597.50, 7377.60, 15830.70, 2926.50),
    "RoadRunner": PaperScores("Road Runner", 55823.20, 39544.00, 51062.70, 21831.40),
    "Robotank": PaperScores("Robotank", 66.61, 63.90, 60.70, 13.50),
    "Seaquest": PaperScores("Seaquest", 6880.48, 5860.60, 7934.70, 332.10),
    "SpaceInvaders": PaperScores("Space Invaders", 5684.02, 1692.30, 7830.80, 904.90),
    "StarGunner": PaperScores("Star Gunner", 96013.91, 54282.00, 79403.70, 1290.20),
    "Tennis": PaperScores("Tennis", 19.10, 12.20, -1.00, -1.00),
    "TimePilot": PaperScores("Time Pilot", 6402.11, 4870.00, 7932.70, 3404.50),
    "Tutankham": PaperScores("Tutankham", 201.70, 68.10, 230.60, 297.00),
    "UpNDown": PaperScores("Up and Down", 17328.92, 9989.90, 23056.90, 5100.80),
    "Venture": PaperScores("Venture", 951.36, 163.00, 693.80, 16.10),
    "VideoPinball": PaperScores("Video Pinball", 529524.60, 196760.40, 47246.80, 80607.00),
    "WizardOfWor": PaperScores("Wizard Of Wor", 7429.40, 2704.00, 9450.80, 480.70),
    "Zaxxon": PaperScores("Zaxxon", 8934.95, 5363.00, 8394.70, 2842.00),
}

ATARI_49: tuple[str, ...] = tuple(TABLE2)


def ale_id(game: str) -> str:
    """``Breakout`` -> ``ALE/Breakout-v5``."""
    return f"ALE/{game}-v5"


# The two id forms that farsighter.config.is_atari_id treats as Atari.
_ALE_ID = re.compile(r"ALE/([A-Za-z0-9]+)-v\d+|([A-Za-z0-9]+)NoFrameskip-v\d+")


def ale_name(env_id: str) -> str | None:
    """The game named by an ALE id as written there (``ALE/Pitfall-v5`` -> ``Pitfall``, also
    ``PitfallNoFrameskip-v4`` and a ``module:`` prefix), whether or not it is in Table 2; None
    for any other id."""
    match = _ALE_ID.fullmatch(env_id.split(":")[-1])
    if match is None:
        return None
    return match.group(1) or match.group(2)


def game_of(env_id: str) -> str | None:
    """The Table 2 key of an ALE id, the inverse of `ale_id`: ``ALE/Breakout-v5`` ->
    ``Breakout`` (also ``BreakoutNoFrameskip-v4``); None for a non-ALE id and for an ALE game
    outside the 49 (``ALE/Pitfall-v5``), so a key it returns always indexes TABLE2."""
    name = ale_name(env_id)
    return name if name in TABLE2 else None


class EpisodicLife(gym.Wrapper):
    """A life loss ends the training episode; the game itself continues (Mnih et al. 2015).

    ``reset`` only restarts the game when it is really over, otherwise it takes one no-op step,
    so the agent learns from shorter episodes without losing the game's state.
    """

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self._lives = 0
        self._game_over = True

    def step(self, action: Any) -> tuple[Any, Any, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._game_over = bool(terminated or truncated)
        lives = int(info.get("lives", 0))
        if 0 < lives < self._lives:
            terminated = True
        self._lives = lives
        return obs, reward, terminated, truncated, info

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        if self._game_over:
            obs, info = self.env.reset(**kwargs)
        else:
            obs, _, terminated, truncated, info = self.env.step(0)
            if terminated or truncated:
                obs, info = self.env.reset(**kwargs)
        self._lives = int(info.get("lives", 0))
        self._game_over = False
        return obs, info


class ClipReward(gym.RewardWrapper):
    """Training only: clip rewards to their sign (Mnih et al. 2015)."""

    def reward(self, reward: Any) -> float:
        return float(np.sign(reward))


def wrap_atari(
    env: gym.Env,
    *,
    frame_skip: int,
    noop_max: int,
    screen_size: int,
    frame_stack: int,
    training: bool,
    terminal_on_life_loss: bool,
    clip_rewards: bool,
) -> gym.Env:
    """Frame skip with max-pool, no-op starts, 84x84 grey, episode statistics (unclipped, whole
    games), then for training life-loss terminals and reward clipping, then a zero-padded stack."""
    env = gym.wrappers.AtariPreprocessing(
        env,
        noop_max=noop_max,
        frame_skip=frame_skip,
        screen_size=screen_size,
        terminal_on_life_loss=False,
        grayscale_obs=True,
        scale_obs=False,
    )
    env = gym.wrappers.RecordEpisodeStatistics(env)
    if training and terminal_on_life_loss:
        env = EpisodicLife(env)
    if training and clip_rewards:
        env = ClipReward(env)
    # Zero padding matches the replay, which rebuilds stacks with zeros before an episode start.
    return gym.wrappers.FrameStackObservation(env, frame_stack, padding_type="zero")
