"""bsuite's deep sea behind the Gymnasium adapter (:mod:`farsighter.envs.deep_sea`): the optimal
path, a wrong first move, the seeding of the stochastic version, bsuite's own DeepSea stepped
side by side with the adapter, and ``info["is_success"]`` (the treasure taken, noise-free) as the
training loop and the evaluation read it."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from farsighter.config import make_config
from farsighter.envs import make_env, make_eval_envs, make_vector_env
from farsighter.envs.deep_sea import BSUITE_MAPPING_SEED, deep_sea_id
from farsighter.session import evaluate_episodes, finished_episodes

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


def _episode(
    env: gym.Env, first: int | None = None, seed: int | None = None, left: bool = False
) -> dict[str, Any]:
    """One episode moving right at every step (``first``: the first action instead; ``left``:
    moving left at every step)."""
    obs, info = env.reset(seed=seed)
    assert "is_success" not in info  # a step's flag, as in the maze
    steps, total, flags, observations, successes = 0, 0.0, [info["bad_episode"]], [obs], []
    done = False
    while not done:
        action = first if steps == 0 and first is not None else _right(env, obs)
        action = 1 - _right(env, obs) if left else action
        obs, reward, terminated, truncated, info = env.step(action)
        assert not truncated
        steps, total, done = steps + 1, total + float(reward), terminated
        flags.append(info["bad_episode"])
        successes.append(info["is_success"])
        observations.append(obs)
    return {
        "steps": steps,
        "return": total,
        "reward": float(reward),  # the last step's, where the corner noise falls
        "flags": flags,
        "successes": successes,
        "obs": np.array(observations),
    }


@pytest.mark.parametrize("size", [2, 6, 10])
def test_the_optimal_path_returns_0_99_is_never_bad_and_succeeds(size: int) -> None:
    env = _env(size)
    for _ in range(2):  # the same lock in the next episode
        ep = _episode(env)
        assert ep["steps"] == size
        assert ep["return"] == pytest.approx(0.99)
        assert not any(ep["flags"])
        # the treasure is paid at the last step only: a success from there
        assert ep["successes"] == [False] * (size - 1) + [True]
        assert all(type(s) is bool for s in ep["successes"])
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
    assert not any(ep["successes"])
    assert _episode(env)["successes"][-1]  # the next episode takes the treasure again
    env.close()


def _last_column(ep: dict[str, Any], size: int) -> int:
    """The column of the last row's cell, where the episode took its last action."""
    return int(np.argmax(ep["obs"][-2])) % size


def test_stochastic_success_is_the_treasure_whatever_the_noise() -> None:
    size = 6
    env = _env(size, stochastic=True)
    right = [_episode(env, seed=1 if i == 0 else None) for i in range(200)]
    # moving right at every step takes the treasure exactly when the N - 1 moves before the last
    # all succeeded (the last row's right action pays even when its move fails)
    for ep in right:
        assert ep["successes"][-1] == (_last_column(ep, size) == size - 1)
        assert not any(ep["successes"][:-1])
    took = [ep for ep in right if ep["successes"][-1]]
    assert 0 < len(took) < len(right)  # some right move failed in some episode
    assert len(took) / len(right) == pytest.approx((1 - 1 / size) ** (size - 1), abs=0.1)
    # the bottom-right corner's noise pulled some successes' returns below 0: still successes
    assert any(ep["return"] < 0 for ep in took)
    # moving left at every step ends bottom left: never a success, whatever the noisy reward
    left = [_episode(env, left=True) for _ in range(50)]
    assert all(_last_column(ep, size) == 0 and not any(ep["successes"]) for ep in left)
    assert max(ep["reward"] for ep in left) > 1.0  # a large positive noise, still no success
    env.close()


def test_the_loop_reads_the_success_in_training_and_in_evaluation() -> None:
    size, num_envs = 4, 2
    cfg = make_config("ddqn", deep_sea_id(size, stochastic=False), num_envs=num_envs)
    envs = make_vector_env(cfg, seed=0)  # the loop's vector env, SAME_STEP autoreset
    mapping = envs.envs[0].unwrapped._env._action_mapping  # type: ignore[attr-defined]
    obs, _ = envs.reset(seed=0)
    ended = []
    for _ in range(2 * size):  # two episodes in each environment
        cells = [divmod(int(np.argmax(o)), size) for o in obs]
        right = [int(mapping[r, c]) for r, c in cells]
        # environment 0 always moves right; environment 1 moves wrong at the first step
        actions = np.array([right[0], right[1] if cells[1] != (0, 0) else 1 - right[1]])
        obs, _, _, _, info = envs.step(actions)
        ended += [(ret > 0.5, success) for ret, _, success in finished_episodes(info)]
    envs.close()
    assert ended == [(True, 1.0), (False, 0.0)] * 2

    class Right:  # a greedy agent that knows the lock
        def __init__(self, env: gym.Env) -> None:
            self.env = env

        def act(self, obs: np.ndarray, step: int, explore: bool) -> np.ndarray:
            return np.array([_right(self.env, o) for o in obs])  # one row per running episode

    for stochastic in (False, True):
        cfg = make_config("ddqn", deep_sea_id(size, stochastic))
        evals = make_eval_envs(cfg, 4, seed=0)  # 30 episodes through 4 environments
        result = evaluate_episodes(Right(evals[0]), cfg, evals, 30, seed=2, global_step=0)  # type: ignore[arg-type]
        assert len(result.successes) == len(result.returns) == 30
        if stochastic:  # some right moves failed, and the returns are noisy
            assert 0 < sum(result.successes) < 30
        else:
            assert result.successes == [1.0] * 30
        for env in evals:
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
    bad_flags, rewards, successes = [], [], []
    for episode in range(40):
        obs, _ = env.reset(seed=seed if episode == 0 else None)
        step = ref.reset()
        np.testing.assert_array_equal(obs, np.asarray(step.observation).ravel())
        bad_before = ref.bsuite_info()["total_bad_episodes"]
        done = False
        while not done:
            # mostly right moves (so the reward and the noisy corners are reached), some wrong
            action = _right(env, obs) if rng.random() < 0.8 else int(rng.integers(2))
            last_cell = divmod(int(np.argmax(obs)), size)
            took = last_cell[1] == size - 1 and action == _right(env, obs)  # the treasure's rule
            obs, reward, terminated, _, info = env.step(action)
            step = ref.step(action)
            assert info["is_success"] == (terminated and took)
            np.testing.assert_array_equal(obs, np.asarray(step.observation).ravel())
            assert reward == float(step.reward)
            assert terminated == step.last()
            rewards.append(reward)
            done = terminated
        bad = ref.bsuite_info()["total_bad_episodes"] > bad_before
        assert info["bad_episode"] == bad
        bad_flags.append(bad)
        successes.append(info["is_success"])
    assert any(bad_flags) and not all(bad_flags)  # both kinds of episode were compared
    assert max(rewards) > 0.5  # the reward was reached
    assert any(successes) and not all(successes)
    env.close()
