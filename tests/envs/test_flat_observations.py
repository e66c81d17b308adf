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


class NeverEnds(gym.Env):  # type: ignore[type-arg]
    """A task with no end of its own: a walk on a line that no action finishes."""

    observation_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
    action_space = gym.spaces.Discrete(2)

    def reset(self, *, seed: int | None = None, options: Any = None) -> tuple[Any, dict[str, Any]]:
        super().reset(seed=seed)
        self.x = 0.0
        return np.array([self.x], np.float32), {}

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        self.x = float(np.clip(self.x + (0.1 if action else -0.1), -1.0, 1.0))
        return np.array([self.x], np.float32), -1.0, False, False, {}


def test_a_time_limit_ends_the_episodes_of_a_task_that_has_none(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A task registered without a time limit (as CliffWalking-v1 is) and that no policy ends:
    the run says so once, with the flag to use; with ``max_episode_steps`` every training and
    evaluation episode ends at the limit, truncated (so the loop bootstraps from its last
    state), and CliffWalking-v1's own environments take it too."""
    env_id = "FarsighterTests/NeverEnds-v0"
    if env_id not in gym.registry:
        gym.register(env_id, entry_point=NeverEnds)
    common: dict[str, Any] = {"learning_starts": 20_000, "eval_max_steps": 300}
    summary = train(tiny("ddqn", tmp_path / "none", env=env_id, total_steps=10_500, **common))
    err = capsys.readouterr().err
    assert summary["episodes"] == 0
    assert err.count(f"no episode of {env_id} has ended in 10,000 steps") == 1
    assert "has no time limit" in err and "give one with --max-episode-steps N" in err
    run = tmp_path / "limited"
    cfg = tiny("ddqn", run, env=env_id, total_steps=1_000, max_episode_steps=40, **common)
    assert train(cfg)["episodes"] == 1_000 // 40
    lengths = np.loadtxt(run / "metrics.csv", delimiter=",", skiprows=1, usecols=3)
    assert set(lengths.tolist()) == {40.0}
    evals = np.loadtxt(run / "eval.csv", delimiter=",", skiprows=1, usecols=1)
    assert set(evals.tolist()) == {-40.0}  # not eval_max_steps' -300
    assert "no episode" not in capsys.readouterr().err
    cliff = make_env(tiny("ddqn", run, env="CliffWalking-v1", max_episode_steps=40), seed=0)
    cliff.reset(seed=0)
    for t in range(1, 41):
        _, _, terminated, truncated, _ = cliff.step(0)  # up from the start, then at the wall
        assert not terminated and truncated == (t == 40)
