"""bsuite's deep sea behind the Gymnasium adapter (:mod:`farsighter.envs.deep_sea`): the optimal
path, a wrong first move, the seeding of the stochastic version, and bsuite's own DeepSea stepped
side by side with the adapter."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from farsighter.config import make_config
from farsighter.envs import make_env
from farsighter.envs.deep_sea import BSUITE_MAPPING_SEED, deep_sea_id

pytest.importorskip("bsuite")


def _env(size: int, stochastic: bool = False) -> gym.Env:
    """Deep sea as a run makes it (the registered id, the factory's wrappers)."""
    return make_env(make_config("ddqn", deep_sea_id(size, stochastic)), seed=0)


def _right(env: gym.Env, obs: np.ndarray) -> int:
    """The action that moves right in the cell ``obs`` shows (bsuite's hidden mapping)."""
    inner: Any = env.unwrapped
    size = inner.size
    row, col = divmod(int(np.argmax(obs)), size)
    return int(inner._env._action_mapping[row, col])


def _episode(env: gym.Env, first: int | None = None, seed: int | None = None) -> dict[str, Any]:
    """One episode moving right at every step (``first``: the first action instead)."""
    obs, info = env.reset(seed=seed)
    steps, total, flags, observations = 0, 0.0, [info["bad_episode"]], [obs]
    done = False
    while not done:
        action = first if steps == 0 and first is not None else _right(env, obs)
        obs, reward, terminated, truncated, info = env.step(action)
        assert not truncated
        steps, total, done = steps + 1, total + float(reward), terminated
        flags.append(info["bad_episode"])
        observations.append(obs)
    return {"steps": steps, "return": total, "flags": flags, "obs": np.array(observations)}


@pytest.mark.parametrize("size", [2, 6, 10])
def test_the_optimal_path_returns_0_99_and_is_never_bad(size: int) -> None:
    env = _env(size)
    for _ in range(2):  # the same lock in the next episode
        ep = _episode(env)
        assert ep["steps"] == size
        assert ep["return"] == pytest.approx(0.99)
        assert not any(ep["flags"])
    env.close()


@pytest.mark.parametrize("size", [4, 8])
def test_a_wrong_first_move_is_a_bad_episode_that_still_lasts_n_steps(size: int) -> None:
    env = _env(size)
    obs, _ = env.reset()
    wrong = 1 - _right(env, obs)
    ep = _episode(env, first=wrong)
    assert ep["steps"] == size  # a wrong move does not end the episode
    assert ep["flags"][0] is False and all(ep["flags"][1:])  # bad from the wrong move, final too
    assert ep["return"] < 0  # never reaches the reward: only the move costs
    assert env.unwrapped._env.bsuite_info()["total_bad_episodes"] == 1  # type: ignore[attr-defined]
    env.close()


def _trajectories(env: gym.Env, seed: int, episodes: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """Observations and returns of ``episodes`` right-moving episodes after reset(seed=seed)."""
    obs, rets = [], []
    for i in range(episodes):
        ep = _episode(env, seed=seed if i == 0 else None)
        obs.append(ep["obs"])
        rets.append(ep["return"])
    return np.array(obs), np.array(rets)


def test_the_stochastic_version_is_seeded_by_reset() -> None:
    env = _env(10, stochastic=True)
    obs_a, ret_a = _trajectories(env, seed=3)
    obs_b, ret_b = _trajectories(env, seed=3)
    np.testing.assert_array_equal(obs_a, obs_b)
    np.testing.assert_array_equal(ret_a, ret_b)
    others = [_trajectories(env, seed=s) for s in (4, 5, 6)]
    assert any(
        not np.array_equal(o, obs_a) or not np.array_equal(r, ret_a) for o, r in others
    )  # another seed: other right moves fail, other corner noise
    # and the deterministic version moves right every time: the same whatever the seed
    det = _env(10)
    assert np.array_equal(_trajectories(det, seed=3)[0], _trajectories(det, seed=4)[0])
    env.close()
    det.close()


@pytest.mark.parametrize("stochastic", [False, True])
def test_the_dynamics_are_bsuites_deep_sea_side_by_side(stochastic: bool) -> None:
    from bsuite.environments.deep_sea import DeepSea

    size, seed = 7, 11
    env = _env(size, stochastic)
    ref = DeepSea(size, deterministic=not stochastic, seed=seed, mapping_seed=BSUITE_MAPPING_SEED)
    rng = np.random.default_rng(0)
    bad_flags, rewards = [], []
    for episode in range(40):
        obs, _ = env.reset(seed=seed if episode == 0 else None)
        step = ref.reset()
        np.testing.assert_array_equal(obs, np.asarray(step.observation).ravel())
        bad_before = ref.bsuite_info()["total_bad_episodes"]
        done = False
        while not done:
            # mostly right moves (so the reward and the noisy corners are reached), some wrong
            action = _right(env, obs) if rng.random() < 0.8 else int(rng.integers(2))
            obs, reward, terminated, _, info = env.step(action)
            step = ref.step(action)
            np.testing.assert_array_equal(obs, np.asarray(step.observation).ravel())
            assert reward == float(step.reward)
            assert terminated == step.last()
            rewards.append(reward)
            done = terminated
        bad = ref.bsuite_info()["total_bad_episodes"] > bad_before
        assert info["bad_episode"] == bad
        bad_flags.append(bad)
    assert any(bad_flags) and not all(bad_flags)  # both kinds of episode were compared
    assert max(rewards) > 0.5  # the reward was reached
    env.close()
