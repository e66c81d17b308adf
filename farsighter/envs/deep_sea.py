"""bsuite's deep sea (Osband et al. 2020, "Behaviour Suite for Reinforcement Learning") behind a
Gymnasium adapter.

``farsighter/DeepSea<N>-v0`` and ``farsighter/DeepSeaStochastic<N>-v0`` (any N >= 2, registered
on first use) wrap ``bsuite.environments.deep_sea.DeepSea`` itself, so the dynamics, the hidden
action mapping and the "bad episode" bookkeeping are bsuite's own:

- an N x N grid; the agent starts top left and falls one row per step, so every episode lasts
  exactly N steps;
- in each cell one of the two actions, hidden and fixed per cell, moves right (and costs
  0.01 / N), the other moves left; the reward 1 waits bottom right, N right moves away, so
  dithering needs about 2^N episodes to find it;
- a wrong move does not end the episode: the agent drifts left and the episode goes on;
- the stochastic version: a right move fails with probability 1/N, and the two bottom corners
  add N(0, 1) noise to the reward.

Observations are the grid flattened (float32, N * N, one-hot). ``info["bad_episode"]`` says
whether the agent has left the diagonal by a wrong move so far this episode (bsuite's "bad
episode", which bsuite's analysis counts), final at the episode's last step.
``info["is_success"]`` (after every step, as the loop's success.csv and eval_success.csv read it)
says whether the episode has collected the treasure's +1 so far, final at the last step (the only
step that can pay it: the right action in the last column, which pays even when the stochastic
version's move fails). It is read from the rise of bsuite's noise-free
``bsuite_info()["denoised_return"]`` during the episode, so the stochastic version's corner noise
never makes or unmakes a success, as it can a return. The action mapping
comes from ``mapping_seed`` (bsuite's sweep uses 42 for every size), so that every copy of the
environment (training, evaluation, vectorised) holds the same lock; the transition and reward
noise of the stochastic version is seeded by ``reset(seed=...)``.
"""

from __future__ import annotations

import re
from typing import Any

import gymnasium
import numpy as np
from numpy.typing import NDArray

__all__ = ["DEEP_SEA_ID", "DeepSeaEnv", "deep_sea_id", "register_deep_sea"]

DEEP_SEA_ID = re.compile(r"^farsighter/DeepSea(Stochastic)?(\d+)-v0$")
ENTRY_POINT = "farsighter.envs.deep_sea:DeepSeaEnv"
BSUITE_MAPPING_SEED = 42
"""bsuite's deep sea sweep uses mapping_seed 42 at every size."""
BSUITE_EXTRA = "install the exploration extra: pip install 'farsighter[explore]'"


def deep_sea_id(size: int, stochastic: bool = False) -> str:
    """The registered id of deep sea of side ``size``."""
    return f"farsighter/DeepSea{'Stochastic' if stochastic else ''}{size}-v0"


class DeepSeaEnv(gymnasium.Env[NDArray[np.float32], np.int64]):
    """bsuite's ``DeepSea`` as a Gymnasium environment (see the module docstring).

    Args:
        size: N, the side of the grid (>= 2).
        deterministic: False for the stochastic version.
        mapping_seed: seeds the hidden right action of each cell.
    """

    metadata = {"render_modes": []}

    def __init__(
        self, size: int = 10, deterministic: bool = True, mapping_seed: int = BSUITE_MAPPING_SEED
    ) -> None:
        if size < 2:
            raise ValueError(f"size must be >= 2, got {size}")
        try:
            from bsuite.environments.deep_sea import DeepSea
        except ImportError:
            raise ImportError(f"deep sea needs the bsuite package; {BSUITE_EXTRA}") from None
        self.size = int(size)
        self.deterministic = bool(deterministic)
        self._env = DeepSea(
            self.size, deterministic=self.deterministic, seed=0, mapping_seed=mapping_seed
        )
        self.observation_space = gymnasium.spaces.Box(
            0.0, 1.0, (self.size * self.size,), np.float32
        )
        self.action_space = gymnasium.spaces.Discrete(2)
        self.optimal_return = float(self._env._optimal_return)  # noqa: SLF001  (bsuite's value)
        self._bad_before = 0
        self._treasure_before = 0.0

    def _info(self) -> dict[str, Any]:
        bad = self._env.bsuite_info()["total_bad_episodes"]
        # bsuite counts a bad episode at its end; inside an episode its flag is the live one.
        live = bool(self._env._bad_episode)  # noqa: SLF001
        return {"bad_episode": live or bad > self._bad_before}

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        super().reset(seed=seed)
        if seed is not None:  # bsuite draws its noise from a RandomState of its own
            self._env._rng = np.random.RandomState(seed)  # noqa: SLF001
        totals = self._env.bsuite_info()
        self._bad_before = totals["total_bad_episodes"]
        self._treasure_before = float(totals["denoised_return"])
        step = self._env.reset()
        return np.asarray(step.observation, np.float32).ravel(), self._info()

    def step(self, action: Any) -> tuple[NDArray[np.float32], float, bool, bool, dict[str, Any]]:
        step = self._env.step(int(action))
        obs = np.asarray(step.observation, np.float32).ravel()
        info = self._info()
        # bsuite's denoised return rises by 1 only when the treasure is taken (no noise, no cost)
        treasure = float(self._env.bsuite_info()["denoised_return"]) - self._treasure_before
        info["is_success"] = treasure > 0.5
        return obs, float(step.reward), bool(step.last()), False, info


def register_deep_sea(env_id: str) -> bool:
    """Register ``env_id`` if it names deep sea; True if it does."""
    match = DEEP_SEA_ID.match(env_id)
    if match is None:
        return False
    if env_id not in gymnasium.registry:
        size = int(match.group(2))
        gymnasium.register(
            id=env_id,
            entry_point=ENTRY_POINT,
            max_episode_steps=size + 1,  # episodes end after N steps by themselves
            kwargs={"size": size, "deterministic": match.group(1) is None},
        )
    return True
