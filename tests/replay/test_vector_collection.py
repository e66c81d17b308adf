"""Vectorised collection equals single-environment collection: E environments stepped together
(environment i seeded seed + i) store, per stream, exactly the transitions that E separate
single-environment runs with those seeds store, episode ends included, for the same actions."""

from __future__ import annotations

import dataclasses
import importlib.util

import numpy as np
import pytest

from farsighter.agents.common import make_replay
from farsighter.config import Config, make_config
from farsighter.envs import frame_stack_of, make_vector_env
from farsighter.replay import ReplayBuffer, VectorStep
from farsighter.session import final_observations

E, STEPS, SEED, K = 3, 400, 11, 3

CASES = [pytest.param("CartPole-v1", {}, id="cartpole")]
if importlib.util.find_spec("minatar"):
    CASES.append(pytest.param("MinAtar/Breakout-v1", {}, id="minatar"))
if importlib.util.find_spec("ale_py"):
    CASES.append(pytest.param("ALE/Pong-v5", {"atari.backend": "gymnasium"}, id="ale-gymnasium"))
if importlib.util.find_spec("envpool"):
    CASES.append(pytest.param("ALE/Pong-v5", {"atari.backend": "envpool"}, id="ale-envpool"))


def _collect(cfg: Config, seed: int, actions_TE: np.ndarray) -> tuple[ReplayBuffer, int]:
    """Step ``cfg.num_envs`` environments with the given actions into a replay buffer."""
    envs = make_vector_env(cfg, seed=seed)
    replay = make_replay(cfg, envs.single_observation_space, frame_stack_of(cfg), seed=0)
    obs, _ = envs.reset(seed=seed)
    ends = 0
    for a_E in actions_TE:
        next_obs, rew, term, trunc, info = envs.step(a_E)
        final = final_observations(info, cfg.num_envs)
        replay.add_step(VectorStep(obs, a_E, rew, term, trunc, final))
        ends += int(np.logical_or(term, trunc).sum())
        obs = next_obs
    envs.close()
    return replay, ends


@pytest.mark.parametrize(("env", "extra"), CASES)
def test_vectorised_and_single_environment_collection_store_the_same_transitions(
    env: str, extra: dict[str, object]
) -> None:
    base = make_config("ddqn", env, buffer_size=E * 2 * STEPS, **extra)  # type: ignore[arg-type]
    n_actions = {"CartPole-v1": 2}.get(env, 3)
    actions_TE = np.random.default_rng(0).integers(0, n_actions, size=(STEPS, E))
    vec, ends = _collect(dataclasses.replace(base, num_envs=E), SEED, actions_TE)
    if env == "CartPole-v1":
        assert ends > 10  # episode boundaries are inside the comparison
    for e in range(E):
        one, _ = _collect(dataclasses.replace(base, num_envs=1), SEED + e, actions_TE[:, e : e + 1])
        n = int(one.count[0])
        assert int(vec.count[e]) == n
        for name in ("frames", "actions", "rewards", "flags", "t_ep"):
            np.testing.assert_array_equal(getattr(vec, name)[e, :n], getattr(one, name)[0, :n])
        # k-step windows (returns, bootstraps, stacked observations) at every valid start
        starts = np.arange(n, dtype=np.int64)
        ours = vec.sample_indices(np.full(n, e, dtype=np.int64), starts, K, 0.99)
        theirs = one.sample_indices(np.zeros(n, dtype=np.int64), starts, K, 0.99)
        assert len(ours.actions) == len(theirs.actions) > 0
        for name in ("obs", "actions", "returns", "bootstrap", "next_obs", "steps", "index"):
            np.testing.assert_array_equal(getattr(ours, name), getattr(theirs, name))
