"""Whole-episode access to the replay (OB2I's episodic backward update): which episodes are
complete and live, what an episode holds, and frame stacks gathered per chunk."""

import numpy as np
import pytest

from farsighter.replay import ReplayBuffer
from tests.replay.test_replay import fill


def bounds(buf: ReplayBuffer) -> list[tuple[int, int, int]]:
    e, s, n = buf.episode_bounds()
    return [(int(a), int(b), int(c)) for a, b, c in zip(e, s, n, strict=True)]


def test_complete_episodes_only() -> None:
    buf = ReplayBuffer(100, (1,), np.float32)
    n = fill(buf, [(3, "term"), (5, "trunc")])
    for t in range(4):  # an episode still running is not complete
        buf.add(
            np.array([[n + t]], np.float32),
            np.array([0]),
            np.array([1.0]),
            np.array([False]),
            np.array([False]),
        )
    # rows 0..2 + final row 3; rows 4..8 + final row 9; rows 10..13 still running
    assert bounds(buf) == [(0, 0, 3), (0, 4, 5)]


def test_episode_contents_and_final_observation() -> None:
    buf = ReplayBuffer(100, (1,), np.float32, seed=0)
    fill(buf, [(5, "trunc")])
    ep = buf.sample_episode()
    assert (ep.env, ep.start, ep.length, ep.terminated) == (0, 0, 5, False)
    assert list(ep.actions) == [0, 1, 2, 0, 1] and list(ep.rewards) == [1.0] * 5
    rows = ep.start + np.arange(ep.length + 1)
    states = buf.stacked_obs(np.zeros(len(rows), np.int64), rows)[:, 0]
    assert list(states) == [0, 1, 2, 3, 4, 4.5]  # s_0..s_4 and the final observation s_5
    fill(buf, [(2, "term")], start=10)
    assert buf.sample_episode(np.random.default_rng(0)).length in (5, 2)
    terminal = [buf.sample_episode() for _ in range(20)]
    assert {e.terminated for e in terminal if e.length == 2} == {True}


def test_wraparound_partly_overwritten_episode_is_excluded() -> None:
    buf = ReplayBuffer(10, (1,), np.float32)
    fill(buf, [(4, "term"), (3, "term"), (2, "term")])
    # 5 + 4 + 3 = 12 rows into 10 slots: rows 0, 1 overwritten, so the first episode is gone
    assert bounds(buf) == [(0, 5, 3), (0, 9, 2)]
    assert not buf.is_live(0, 1) and buf.is_live(0, 5)
    fill(buf, [(3, "trunc")], start=20)  # rows 12..14 + final 15: now rows < 6 are overwritten
    assert bounds(buf) == [(0, 9, 2), (0, 12, 3)]


def test_clear_and_streams() -> None:
    buf = ReplayBuffer(200, (1,), np.float32, num_envs=2)
    for t in range(6):  # stream 0: episodes of 2 steps; stream 1: one episode of 6 steps
        end0, end1 = t % 2 == 1, t == 5
        buf.add(
            np.array([[t], [10 + t]], np.float32),
            np.array([0, 1]),
            np.array([1.0, 2.0]),
            np.array([end0, end1]),
            np.array([False, False]),
            [np.array([0.5], np.float32) if end0 else None, np.array([9.5], np.float32)]
            if end0 or end1
            else None,
        )
    assert bounds(buf) == [(0, 0, 2), (0, 3, 2), (0, 6, 2), (1, 0, 6)]
    buf.clear()
    assert bounds(buf) == []
    with pytest.raises(ValueError, match="no complete episode"):
        buf.sample_episode()


def test_frame_stacks_of_an_episode_are_zero_padded_at_its_start() -> None:
    buf = ReplayBuffer(100, (3, 2), np.uint8, frame_stack=3)
    frames = []
    for t in range(7):  # episodes of 3 and 4 steps; newest frame of obs t is t + 1
        obs = np.full((1, 3, 2), t + 1, np.uint8)
        end = t in (2, 6)
        final = [np.full((3, 2), 50 + t, np.uint8)] if end else None
        buf.add(obs, np.array([0]), np.array([0.0]), np.array([end]), np.array([False]), final)
        frames.append(t + 1)
    e_N, s_N, n_N = buf.episode_bounds()
    assert list(s_N) == [0, 4] and list(n_N) == [3, 4]
    rows = 4 + np.arange(5)  # the second episode: s_0..s_3 and its final observation
    stacks = buf.stacked_obs(np.zeros(5, np.int64), rows)[:, :, 0]
    assert stacks.tolist() == [[0, 0, 4], [0, 4, 5], [4, 5, 6], [5, 6, 7], [6, 7, 56]]
