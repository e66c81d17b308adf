"""MinAtar (Young & Tian 2019, "MinAtar: An Atari-inspired testbed for thorough and reproducible
reinforcement learning experiments"): five Atari games on a 10x10 grid, the CPU-scale Atari.

The ``minatar`` package (the Atari extra) registers ``MinAtar/<Game>-v0`` and ``MinAtar/<Game>-v1``
with Gymnasium when ``minatar.gym.register_envs()`` is called (not on import); this module calls
it the first time a MinAtar id is named. As of minatar 1.0.15:

* ``-v1`` uses the game's minimal action set (Asterix 5 actions, Breakout 3, Freeway 3, Seaquest
  6, SpaceInvaders 4); ``-v0`` uses all six actions (no-op, left, up, right, down, fire) in every
  game. ``minatar_id`` names the ``-v1`` ids.
* Observations are (10, 10, C) bool arrays, one plane per object kind (C = 4, 4, 7, 10, 6 for
  Asterix, Breakout, Freeway, Seaquest, SpaceInvaders); ``MinAtarChannelsFirst`` turns them into
  (C, 10, 10) uint8 planes in {0, 1} for the convolutional torso. ``info`` is always empty.
* Sticky actions are on by default: with probability 0.1 the previous action is repeated
  (``sticky_action_prob=0.1``, as in Young & Tian's experiments); difficulty ramping is on. We
  keep both defaults (the ALE's ``atari.repeat_action_probability`` does not apply here).
* No time limit is registered: Freeway ends after 2,500 frames, the other games only when the
  agent fails (Breakout refills its bricks), so a strong agent's episodes can be long;
  evaluation episodes are capped by ``eval_max_steps``.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from farsighter.config import is_minatar_id
from farsighter.errors import EnvError

__all__ = [
    "ATARI_EXTRA",
    "MINATAR_GAMES",
    "MinAtarChannelsFirst",
    "is_minatar_id",
    "minatar_id",
    "register_minatar",
]

MINATAR_GAMES = ("Asterix", "Breakout", "Freeway", "Seaquest", "SpaceInvaders")
ATARI_EXTRA = "install the Atari extra: pip install 'farsighter[atari]'"


def minatar_id(game: str) -> str:
    """The Gymnasium id of a MinAtar game (minimal action set): ``MinAtar/Breakout-v1``."""
    if game not in MINATAR_GAMES:
        raise EnvError(f"unknown MinAtar game '{game}'; accepted: {', '.join(MINATAR_GAMES)}")
    return f"MinAtar/{game}-v1"


def register_minatar(env_id: str) -> None:
    """Register MinAtar's ids the first time one of them is named (nothing for other ids;
    ``is_minatar_id``, from farsighter.config, also accepts a ``module:`` prefix)."""
    if not is_minatar_id(env_id) or minatar_id(MINATAR_GAMES[0]) in gym.registry:
        return
    try:
        import minatar.gym
    except ImportError:
        raise EnvError(f"'{env_id}' is a MinAtar task; {ATARI_EXTRA}") from None
    minatar.gym.register_envs()


class MinAtarChannelsFirst(gym.ObservationWrapper):
    """A MinAtar observation, (10, 10, C) bool, as (C, 10, 10) uint8 planes in {0, 1} (bytes in
    the replay; the torso casts them to float without scaling)."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        shape = env.observation_space.shape
        assert shape is not None and len(shape) == 3
        height, width, channels = shape
        self.observation_space = gym.spaces.Box(0, 1, (channels, height, width), dtype=np.uint8)

    def observation(self, observation: Any) -> np.ndarray:
        return np.ascontiguousarray(np.asarray(observation).transpose(2, 0, 1), dtype=np.uint8)
