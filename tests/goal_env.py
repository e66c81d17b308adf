"""A tiny goal-conditioned task with gymnasium-robotics' dict-observation convention, for tests:
a point in the plane must reach a goal; sparse reward -1 until within 0.1; 20-step time limit.

``gym.make("tests.goal_env:PointGoal-v0")`` imports this module, which registers the id.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

THRESHOLD = 0.1


class PointGoalEnv(gym.Env):
    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(self) -> None:
        box = gym.spaces.Box(-2.0, 2.0, (2,), np.float64)
        self.observation_space = gym.spaces.Dict(
            {
                "observation": gym.spaces.Box(-np.inf, np.inf, (4,), np.float64),
                "achieved_goal": box,
                "desired_goal": box,
            }
        )
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.pos = np.zeros(2)
        self.vel = np.zeros(2)
        self.goal = np.zeros(2)

    def compute_reward(self, achieved_goal: Any, desired_goal: Any, info: Any) -> np.ndarray:
        d = np.linalg.norm(np.asarray(achieved_goal) - np.asarray(desired_goal), axis=-1)
        return -(d > THRESHOLD).astype(np.float32)

    def _obs(self) -> dict[str, np.ndarray]:
        return {
            "observation": np.concatenate([self.pos, self.vel]),
            "achieved_goal": self.pos.copy(),
            "desired_goal": self.goal.copy(),
        }

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        super().reset(seed=seed)
        self.pos = self.np_random.uniform(-1, 1, 2)
        self.vel = np.zeros(2)
        self.goal = self.np_random.uniform(-1, 1, 2)
        return self._obs(), {"is_success": 0.0}

    def step(
        self, action: np.ndarray
    ) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        self.vel = 0.2 * np.clip(np.asarray(action, dtype=np.float64), -1, 1)
        self.pos = np.clip(self.pos + self.vel, -2, 2)
        reward = float(self.compute_reward(self.pos, self.goal, None))
        return self._obs(), reward, False, False, {"is_success": float(reward == 0.0)}


gym.register("PointGoal-v0", entry_point=PointGoalEnv, max_episode_steps=20)
