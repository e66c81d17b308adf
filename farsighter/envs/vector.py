"""Gymnasium's synchronous vector env with a leaner step for array observations.

A small task's environment step costs a few microseconds; Gymnasium's ``SyncVectorEnv.step``
adds about as much again per call through machinery every space needs (an iterator over the
action space, ``concatenate`` dispatched on the observation space, ``deepcopy``). For a ``Box``
observation space with same-step autoreset (what the training loop uses) the same work is plain
array writes. :class:`LeanSyncVectorEnv` does that and nothing else differs: the same
environments stepped in the same order, the same observations, rewards, flags and infos (each
environment's info through Gymnasium's own ``_add_info``). Other spaces and modes take
Gymnasium's step unchanged.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np


class LeanSyncVectorEnv(gym.vector.SyncVectorEnv):
    """``SyncVectorEnv`` whose ``step`` writes array observations straight into its batch."""

    def __init__(self, env_fns: Any, **kwargs: Any) -> None:
        kwargs.setdefault("autoreset_mode", gym.vector.AutoresetMode.SAME_STEP)
        super().__init__(env_fns, **kwargs)
        self._lean = (
            isinstance(self.single_observation_space, gym.spaces.Box)
            and self.autoreset_mode == gym.vector.AutoresetMode.SAME_STEP
            and isinstance(self._observations, np.ndarray)
        )

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        if not self._lean:
            return super().step(actions)
        infos: dict[str, Any] = {}
        batch = self._observations
        for i, env in enumerate(self.envs):
            obs, reward, terminated, truncated, info = env.step(actions[i])
            self._rewards[i], self._terminations[i], self._truncations[i] = (
                reward,
                terminated,
                truncated,
            )
            if terminated or truncated:
                infos = self._add_info(infos, {"final_obs": obs, "final_info": info}, i)
                obs, info = env.reset()
            self._env_obs[i] = obs
            batch[i] = obs
            if info:  # an empty info adds nothing
                infos = self._add_info(infos, info, i)
        self._autoreset_envs = np.logical_or(self._terminations, self._truncations)
        return (
            batch.copy() if self.copy else batch,
            self._rewards.copy(),
            self._terminations.copy(),
            self._truncations.copy(),
            infos,
        )
