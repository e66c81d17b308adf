"""A combination-lock chain: deep exploration with a size knob.

``farsighter/Chain<L>-v0`` (any L >= 2, registered on first use) is a row of L states. In each
state one action, hidden and fixed per state, moves one state on; every other action ends the
episode with reward 0. The move on costs ``move_cost / L`` (a myopic agent prefers to stop), and
reaching the end pays 1. The best return is ``1 - move_cost``; a policy that acts uniformly at
random finds the reward with probability ``num_actions ** -L`` per episode, so epsilon-greedy
needs on the order of ``num_actions ** L`` episodes, while an agent that explores deeply needs a
number polynomial in L (Osband et al. 2019, "Deep exploration via randomized value functions",
whose deep sea has the same structure).

Observations are one-hot vectors of the position (float32, length L). The hidden actions are a
function of (L, ``layout_seed``) only, so that every copy of the environment (training,
evaluation, vectorised) holds the same lock.

``farsighter/DriftChain<L>-v0`` is the same lock where a wrong action does not end the episode:
it drifts one state back (none below the first) and the episode goes on, to a time limit of L
steps, so the end is still reached only by L right moves in a row (the lock of issue #25's
first report). The observation holds the position alone, not the time, and a wrong move
revisits a state, so a value that bootstraps through the time limit sees every state the
reward is a few steps from: the right and the wrong move differ by a step's delay where the
reward is known, and by nothing where it is not. Same hidden actions and move cost as the
chain of that length.
"""

from __future__ import annotations

import re
from typing import Any

import gymnasium
import numpy as np
from numpy.typing import NDArray

__all__ = ["CHAIN_ID", "DRIFT_CHAIN_ID", "ChainEnv", "chain_id", "drift_chain_id", "register_chain"]

CHAIN_ID = re.compile(r"^farsighter/Chain(\d+)-v0$")
DRIFT_CHAIN_ID = re.compile(r"^farsighter/DriftChain(\d+)-v0$")
ENTRY_POINT = "farsighter.envs.chain:ChainEnv"
SOLVED_RETURN = 0.5
"""A return above this reached the end of the chain (the best is 1 - move_cost)."""


def chain_id(length: int) -> str:
    """The registered id of the chain of ``length`` states."""
    return f"farsighter/Chain{length}-v0"


def drift_chain_id(length: int) -> str:
    """The registered id of the drifting chain of ``length`` states (a wrong move goes back)."""
    return f"farsighter/DriftChain{length}-v0"


class ChainEnv(gymnasium.Env[NDArray[np.float32], np.int64]):
    """Combination lock of ``length`` states (see the module docstring).

    Args:
        length: L, the number of states (>= 2); the reward is L right moves away.
        num_actions: actions per state (>= 2); one of them moves on.
        move_cost: total cost of the L right moves (each costs move_cost / L).
        layout_seed: seeds the hidden right action of each state.
        drift: a wrong action moves one state back (not below the first) and the episode goes
            on, instead of ending it.
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        length: int = 10,
        num_actions: int = 2,
        move_cost: float = 0.01,
        layout_seed: int = 0,
        drift: bool = False,
    ) -> None:
        if length < 2:
            raise ValueError(f"length must be >= 2, got {length}")
        if num_actions < 2:
            raise ValueError(f"num_actions must be >= 2, got {num_actions}")
        if not 0 <= move_cost < 1:
            raise ValueError(f"move_cost must be in [0, 1), got {move_cost}")
        self.length = int(length)
        self.move_cost = float(move_cost)
        self.drift = bool(drift)
        rng = np.random.default_rng([int(layout_seed), self.length])
        self.right_L = rng.integers(0, num_actions, size=self.length)
        self.observation_space = gymnasium.spaces.Box(0.0, 1.0, (self.length,), np.float32)
        self.action_space = gymnasium.spaces.Discrete(num_actions)
        self._pos = 0

    def _obs(self) -> NDArray[np.float32]:
        obs = np.zeros(self.length, dtype=np.float32)
        obs[min(self._pos, self.length - 1)] = 1.0
        return obs

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        super().reset(seed=seed)
        self._pos = 0
        return self._obs(), {"position": 0}

    def step(self, action: Any) -> tuple[NDArray[np.float32], float, bool, bool, dict[str, Any]]:
        if int(action) != int(self.right_L[self._pos]):
            if self.drift:
                self._pos = max(self._pos - 1, 0)
            return self._obs(), 0.0, not self.drift, False, {"position": self._pos}
        self._pos += 1
        reward = -self.move_cost / self.length
        done = self._pos == self.length
        if done:
            reward += 1.0
        return self._obs(), reward, done, False, {"position": self._pos}


def register_chain(env_id: str) -> bool:
    """Register ``env_id`` if it names a chain (``farsighter/Chain<L>-v0``, time limit L + 1,
    never reached) or a drifting chain (``farsighter/DriftChain<L>-v0``, time limit L); True if
    it does."""
    drift = DRIFT_CHAIN_ID.match(env_id)
    match = drift or CHAIN_ID.match(env_id)
    if match is None:
        return False
    if env_id not in gymnasium.registry:
        length = int(match.group(1))
        gymnasium.register(
            id=env_id,
            entry_point=ENTRY_POINT,
            max_episode_steps=length if drift else length + 1,
            kwargs={"length": length, "drift": drift is not None},
        )
    return True
