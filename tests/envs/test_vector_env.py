"""The training loop's vector env steps exactly as Gymnasium's SyncVectorEnv (same-step autoreset)
does: the same observations, rewards, flags and infos, episode ends and their final
observations included."""

from __future__ import annotations

import pickle
from functools import partial
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from farsighter.config import make_config
from farsighter.envs import make_env, make_vector_env
from farsighter.envs.deep_sea import deep_sea_id
from farsighter.envs.vector import LeanSyncVectorEnv


def assert_same(a: Any, b: Any, where: str = "") -> None:
    if isinstance(a, tuple | list):
        assert type(a) is type(b) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same(x, y, f"{where}[{i}]")
    elif isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), where
        for key in a:
            if not where.endswith(".episode") or key != "t":  # t: wall-clock seconds
                assert_same(a[key], b[key], f"{where}.{key}")
    elif isinstance(a, np.ndarray) and a.dtype == object:
        assert b.dtype == object and a.shape == b.shape, where
        for x, y in zip(a, b, strict=True):
            assert_same(x, y, where)
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.dtype == b.dtype, where
        np.testing.assert_array_equal(a, b, err_msg=where)
    else:
        assert type(a) is type(b) and a == b, where


@pytest.mark.parametrize(
    ("env_id", "num_envs", "lean"),
    [
        ("CartPole-v1", 3, True),  # terminations, episode statistics
        ("Pendulum-v1", 2, True),  # continuous actions, truncation at 200 steps
        (deep_sea_id(6), 2, True),  # bsuite infos: bad_episode, is_success at the end
        ("FrozenLake-v1", 2, True),  # Discrete observations, made one-hot vectors
        ("FrozenLake-v1", 2, False),  # the same unwrapped (Discrete): Gymnasium's own step
    ],
)
def test_steps_are_gymnasiums(env_id: str, num_envs: int, lean: bool) -> None:
    cfg = make_config("naf" if env_id == "Pendulum-v1" else "ddqn", env_id, num_envs=num_envs)
    if lean:  # the factory's environments
        ours = make_vector_env(cfg, seed=4)
        fns = [lambda i=i: make_env(cfg, seed=4 + i, training=True) for i in range(num_envs)]
    else:  # a space the factory would flatten, given to the vector env as it is
        fns = [partial(gym.make, env_id) for _ in range(num_envs)]
        ours = LeanSyncVectorEnv(fns)
    assert isinstance(ours, LeanSyncVectorEnv) and ours._lean == lean
    theirs = gym.vector.SyncVectorEnv(fns, autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
    assert_same(ours.reset(seed=4), theirs.reset(seed=4), "reset")
    ours.action_space.seed(0)
    ends = 0
    for step in range(700):
        actions = ours.action_space.sample()
        out, ref = ours.step(actions), theirs.step(actions)
        assert_same(out, ref, f"step {step}")
        ends += int(np.sum(out[2] | out[3]))
    assert ends >= 2  # episodes ended (and reset) within the steps compared
    # the returned batch is the caller's: a later step does not write into it
    held = out[0].copy()
    ours.step(ours.action_space.sample())
    np.testing.assert_array_equal(out[0], held)
    # a checkpoint pickles it, and the copy steps on as the original does
    copy = pickle.loads(pickle.dumps(ours))
    actions = ours.action_space.sample()
    assert_same(copy.step(actions), ours.step(actions), "after unpickling")
    ours.close()
    theirs.close()
