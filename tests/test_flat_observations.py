"""Observation spaces that are neither flat vectors nor images (FrozenLake's state index,
Blackjack's tuple, a Box grid) reach the torso as float32 vectors made by Gymnasium's own
flattening; a space with no fixed-size vector is refused in one line."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from farsighter import load_agent, train
from farsighter.envs import check_spaces, make_env
from farsighter.envs.factory import flattenable
from farsighter.errors import EnvError
from tests.conftest import tiny


def test_a_discrete_state_becomes_its_one_hot_vector(tmp_path: Path) -> None:
    env = make_env(tiny("ddqn", tmp_path, env="FrozenLake-v1"), seed=0)
    assert env.observation_space == gym.spaces.Box(0.0, 1.0, (16,), np.float32)
    obs, _ = env.reset(seed=0)
    assert obs.dtype == np.float32 and obs.tolist() == [1.0] + [0.0] * 15  # the start, state 0
    for _ in range(50):  # every step: one 1, at the state the unwrapped env is in
        obs, _, terminated, truncated, _ = env.step(env.action_space.sample())
        state = int(env.unwrapped.s)  # type: ignore[attr-defined]
        assert obs.sum() == 1.0 and obs[state] == 1.0
        if terminated or truncated:
            obs, _ = env.reset()


def test_a_tuple_of_discrete_spaces_becomes_concatenated_one_hot_blocks(tmp_path: Path) -> None:
    env = make_env(tiny("ddqn", tmp_path, env="Blackjack-v1"), seed=0)
    assert env.observation_space.shape == (32 + 11 + 2,)
    obs, _ = env.reset(seed=3)
    raw = env.unwrapped._get_obs()  # type: ignore[attr-defined]  # (player sum, dealer card, ace)
    blocks = np.split(obs, [32, 43])
    assert [int(b.argmax()) for b in blocks] == [int(v) for v in raw]
    assert [float(b.sum()) for b in blocks] == [1.0, 1.0, 1.0]


def test_which_spaces_are_flattened() -> None:
    box = gym.spaces.Box
    assert not flattenable(box(0, 1, (4,)))  # a flat vector: as it is
    assert not flattenable(box(0, 255, (4, 84, 84), np.uint8))  # an image: the CNN's
    assert flattenable(box(0, 1, (4, 4)))  # a grid
    assert flattenable(gym.spaces.MultiDiscrete([3, 4]))
    assert flattenable(gym.spaces.Dict({"a": gym.spaces.Discrete(2), "b": box(0, 1, (3,))}))
    assert not flattenable(gym.spaces.Text(5))
    sequence = gym.spaces.Sequence(gym.spaces.Discrete(3))  # no fixed length
    assert not flattenable(gym.spaces.Tuple((gym.spaces.Discrete(2), sequence)))
    with pytest.raises(EnvError, match=r"^observation space Text\(.*accepted: Box .*Discrete"):
        check_spaces("ddqn", gym.spaces.Text(5), gym.spaces.Discrete(2))


@pytest.mark.parametrize("algo", ["ddqn", "farsighter"])
def test_a_tabular_task_trains_and_its_saved_policy_acts(tmp_path: Path, algo: str) -> None:
    values: dict[str, Any] = {"total_steps": 600, "learning_starts": 100, "checkpoint_every": 300}
    train(tiny(algo, tmp_path / "run", env="FrozenLake-v1", **values))
    policy = load_agent(tmp_path / "run")
    env = policy.make_env(seed=1)
    obs, _ = env.reset(seed=1)
    action = policy.act(obs[None])
    assert action.shape == (1,) and 0 <= int(action[0]) < 4
