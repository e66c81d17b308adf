"""blr.revisit_action: a uniformly random action where the episode is back at an observation it
visited (the loops a held or narrow draw walks), the draw's action everywhere else."""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from farsighter.agents import build_agent
from tests.conftest import parts, tiny

ACTIONS = 5


def make_agent(
    tmp_path: Path, revisit_action: str, redraw: str = "k", prior_std: float = 1e-6
) -> Any:
    """An agent over 5 actions whose draws sit on the posterior mean (a prior this narrow gives
    every draw the mean's argmax) unless ``prior_std`` widens them."""
    cfg = tiny(
        "farsighter",
        tmp_path,
        learning_starts=0,
        blr__prior_std=prior_std,
        blr__redraw=redraw,
        blr__revisit_action=revisit_action,
    )
    space = gym.spaces.Box(-1.0, 1.0, (4,), np.float32)
    return build_agent(
        cfg, space, gym.spaces.Discrete(ACTIONS), frame_stack=1, device=torch.device("cpu")
    )


def end_episode(agent: Any) -> None:
    parts(agent).exploration.observe(np.array([True]))


def test_a_revisited_observation_gets_a_uniform_action_and_a_new_one_the_draws(
    tmp_path: Path,
) -> None:
    obs = np.full((1, 4), 0.3, np.float32)
    greedy = int(agent_greedy(make_agent(tmp_path / "g", "draw"), obs))
    drawn = make_agent(tmp_path / "d", "draw")
    assert {int(drawn.act(obs, 10)[0]) for _ in range(200)} == {greedy}  # the loop, as it was

    agent = make_agent(tmp_path / "u", "uniform")
    assert int(agent.act(obs, 10)[0]) == greedy  # the first visit: the draw's action
    again = Counter(int(agent.act(obs, 10)[0]) for _ in range(1_000))
    assert set(again) == set(range(ACTIONS))  # every return: uniform over the actions
    assert all(150 <= c <= 250 for c in again.values()), again
    end_episode(agent)  # a new episode has visited nothing yet
    assert int(agent.act(obs, 10)[0]) == greedy


def agent_greedy(agent: Any, obs: np.ndarray) -> int:
    return int(agent.act(obs, 10, explore=False)[0])


def test_without_revisits_the_run_is_the_same_bit_for_bit(tmp_path: Path) -> None:
    """Observations that never repeat in an episode (continuous states, deep sea, the chain):
    the same actions and the same generator stream as without the option."""
    rng = np.random.default_rng(0)
    obs = [rng.normal(size=(1, 4)).astype(np.float32) for _ in range(60)]
    runs = []
    for mode in ("draw", "uniform"):
        agent = make_agent(tmp_path / mode, mode, redraw="step", prior_std=10.0)
        acts = [int(agent.act(o, 10)[0]) for o in obs]
        runs.append((acts, parts(agent).gen.get_state()))
    assert runs[0][0] == runs[1][0]
    assert len(set(runs[0][0])) > 1
    assert torch.equal(runs[0][1], runs[1][1])


def test_the_visits_resume_from_a_checkpoint(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    obs = [rng.normal(size=(1, 4)).astype(np.float32) for _ in range(6)]
    agent = make_agent(tmp_path / "a", "uniform")
    for t in range(10):
        agent.act(obs[t % 4], 10)  # the first four observations are visited
    saved = agent.state_dict(include_replay=False)
    later = [int(agent.act(obs[t % 6], 10)[0]) for t in range(24)]
    twin = make_agent(tmp_path / "b", "uniform")
    twin.load_state_dict(saved)
    assert [int(twin.act(obs[t % 6], 10)[0]) for t in range(24)] == later
    fresh = make_agent(tmp_path / "c", "uniform")  # without the visits: other actions
    fresh.load_state_dict({**saved, "exploration": {**saved["exploration"], "loops": None}})
    assert [int(fresh.act(obs[t % 6], 10)[0]) for t in range(24)] != later


def test_unpaid_breaks_loops_in_episodes_after_one_that_paid_nothing(tmp_path: Path) -> None:
    """uniform-unpaid: uniform at a revisit in an episode whose previous episode paid no
    positive reward (and in the first), the draw's action in one after a paid episode."""
    obs = np.full((1, 4), 0.3, np.float32)
    agent = make_agent(tmp_path, "uniform-unpaid")
    greedy = agent_greedy(agent, obs)

    def episode(reward: float) -> set[int]:
        actions = {int(agent.act(obs, 10)[0]) for _ in range(200)}
        parts(agent).exploration.observe(np.array([False]), np.array([reward]))
        parts(agent).exploration.observe(np.array([True]), np.array([0.0]))
        return actions

    assert len(episode(0.0)) == ACTIONS  # the first episode: uniform at the revisits
    assert len(episode(1.0)) == ACTIONS  # after an unpaid one; this one pays (mid-episode)
    twin = make_agent(tmp_path / "twin", "uniform-unpaid")
    twin.load_state_dict(agent.state_dict(include_replay=False))  # the flags resume with it
    assert episode(-1.0) == {greedy}  # after a paid one: the draw's action; pays nothing
    assert len(episode(0.0)) == ACTIONS  # after an unpaid one again
    assert {int(twin.act(obs, 10)[0]) for _ in range(200)} == {greedy}  # resumed: paid before


def test_timeout_breaks_loops_in_episodes_after_one_that_ran_to_its_time_limit(
    tmp_path: Path,
) -> None:
    """uniform-timeout: uniform at a revisit in an episode after one that ran to its time limit
    (truncated), the draw's action after one that ended on its own and in the first episode (a
    task without a time limit, CliffWalking-v1, may never end it)."""
    obs = np.full((1, 4), 0.3, np.float32)
    agent = make_agent(tmp_path, "uniform-timeout")
    greedy = agent_greedy(agent, obs)

    def episode(truncated: bool) -> set[int]:
        actions = {int(agent.act(obs, 10)[0]) for _ in range(200)}
        parts(agent).exploration.observe(np.array([True]), np.array([1.0]), np.array([truncated]))
        return actions

    assert episode(truncated=True) == {greedy}  # the first episode: the draw's action
    assert len(episode(truncated=False)) == ACTIONS  # after a time limit (paid or not)
    assert episode(truncated=False) == {greedy}  # after one that ended on its own
