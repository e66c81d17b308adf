"""Any bsuite experiment by id (:mod:`farsighter.envs.bsuite_env`): stepped side by side with
bsuite's own environment, seeded by ``reset``, its setting's task kept, constructor arguments,
the end of an episode, and the ids refused in one line."""

from __future__ import annotations

from typing import Any

import dm_env
import numpy as np
import pytest

from farsighter.config import make_config
from farsighter.envs import make_env

pytest.importorskip("bsuite")

from bsuite import bsuite as bsuite_module  # noqa: E402
from bsuite import sweep  # noqa: E402


def _episode(env: Any, seed: int | None, actions: np.ndarray) -> tuple[np.ndarray, list[float]]:
    """Observations and rewards of one episode of the adapter, acting ``actions`` in turn."""
    obs, _ = env.reset(seed=seed)
    observations, rewards = [obs], []
    for action in actions:
        obs, reward, terminated, truncated, _ = env.step(int(action))
        observations.append(obs)
        rewards.append(reward)
        if terminated or truncated:
            break
    return np.array(observations), rewards


@pytest.mark.parametrize("bsuite_id", ["catch/0", "umbrella_length/3", "cartpole_swingup/2"])
def test_steps_as_bsuites_own_environment_with_the_runs_seed(bsuite_id: str) -> None:
    name, index = bsuite_id.split("/")
    env = make_env(make_config("ddqn", f"bsuite/{name}-{index}"), seed=0)
    actions = np.random.default_rng(0).integers(0, env.action_space.n, size=2_000)
    observations, rewards = _episode(env, 7, actions)
    own = bsuite_module.load(name, {**sweep.SETTINGS[bsuite_id], "seed": 7})
    step = own.reset()
    assert np.array_equal(observations[0], np.asarray(step.observation, np.float32).ravel())
    for t, action in enumerate(actions[: len(rewards)]):
        step = own.step(int(action))
        assert np.array_equal(observations[t + 1], np.asarray(step.observation, np.float32).ravel())
        assert rewards[t] == step.reward
    assert step.last()  # the adapter's episode ended where bsuite's did
    assert env.observation_space.contains(observations[-1])


def test_reset_seeds_the_episodes_and_the_setting_keeps_the_task() -> None:
    catch = make_env(make_config("ddqn", "bsuite/catch-0"), seed=0)
    actions = np.ones(20, dtype=np.int64)
    first, again = (_episode(catch, 3, actions)[0] for _ in range(2))
    assert np.array_equal(first, again)
    starts = {_episode(catch, seed, actions[:1])[0][0].tobytes() for seed in range(10)}
    assert len(starts) > 2  # the ball starts in other columns under other seeds
    # bandit: the paying arm is the setting's mapping_seed, whatever the run's seed
    paid = {}
    for index in (0, 1):
        env = make_env(make_config("ddqn", f"bsuite/bandit-{index}"), seed=0)
        paid[index] = [
            [_episode(env, seed, np.array([arm]))[1][0] for arm in range(11)] for seed in (0, 5)
        ]
        assert paid[index][0] == paid[index][1]
    assert paid[0][0] != paid[1][0]
    # the stochastic deep sea, whose constructor takes no seed: its noise follows reset's seed
    sea = make_env(make_config("ddqn", "bsuite/deep_sea_stochastic-0"), seed=0)
    actions = np.random.default_rng(0).integers(0, 2, size=10)

    def episodes(seed: int) -> bytes:  # five episodes after a reset with ``seed``
        first = _episode(sea, seed, actions)
        rest = [_episode(sea, None, actions) for _ in range(4)]
        return b"".join(o.tobytes() + np.array(r).tobytes() for o, r in [first, *rest])

    runs = [episodes(seed) for seed in (1, 1, 2, 3)]
    assert runs[0] == runs[1]
    assert len(set(runs[1:])) > 1


def test_constructor_arguments_replace_the_settings() -> None:
    def length(values: tuple[str, ...]) -> int:
        env = make_env(make_config("ddqn", "bsuite/umbrella_length-3", env_kwargs=values), seed=0)
        return len(_episode(env, 0, np.zeros(500, dtype=np.int64))[1])

    assert length(()) == sweep.SETTINGS["umbrella_length/3"]["chain_length"]
    assert length(("chain_length=9",)) == 9


def test_an_episode_ends_terminated_at_discount_zero_else_truncated(monkeypatch) -> None:
    class Ends(dm_env.Environment):
        """Two steps; the last with ``discount``."""

        def __init__(self, discount: float, seed: int | None = None) -> None:
            self.discount, self.t = discount, 0

        def reset(self) -> dm_env.TimeStep:
            self.t = 0
            return dm_env.restart(np.zeros(2, np.float32))

        def step(self, action: int) -> dm_env.TimeStep:
            self.t += 1
            obs = np.full(2, self.t, np.float32)
            if self.t < 2:
                return dm_env.transition(1.0, obs)
            return dm_env.truncation(1.0, obs, self.discount)

        def observation_spec(self) -> Any:
            return dm_env.specs.Array((2,), np.float32)

        def action_spec(self) -> Any:
            return dm_env.specs.DiscreteArray(2)

    from farsighter.envs.bsuite_env import BsuiteEnv

    monkeypatch.setitem(bsuite_module.EXPERIMENT_NAME_TO_ENVIRONMENT, "catch", Ends)
    monkeypatch.setattr(sweep, "SETTINGS", {**sweep.SETTINGS, "catch/0": {"discount": 0.0}})
    ends = []
    for discount in (0.0, 1.0):
        env = BsuiteEnv("catch", 0, discount=discount)
        env.reset(seed=0)
        assert env.step(0)[2:4] == (False, False)
        ends.append(env.step(0)[2:4])
    assert ends == [(True, False), (False, True)]


@pytest.mark.parametrize(
    ("env_id", "expected"),
    [
        ("bsuite/catchh-0", "bsuite has no experiment 'catchh' (it has bandit,"),
        ("bsuite/catch-20", "bsuite's catch has settings 0 to 19 (got 20)"),
        ("bsuite/mnist-0", "bsuite's mnist downloads MNIST when made; not supported"),
    ],
)
def test_ids_bsuite_cannot_make_are_one_line(env_id: str, expected: str) -> None:
    from farsighter.errors import EnvError

    with pytest.raises(EnvError) as info:
        make_env(make_config("ddqn", env_id), seed=0)
    assert expected in str(info.value)
    assert "\n" not in str(info.value)
