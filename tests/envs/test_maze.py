"""Tests of the toy bridge maze (paper section 5.1, SPEC section 3)."""

from __future__ import annotations

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import farsighter.envs.maze as maze
from farsighter.envs.maze import (
    DEFAULT_LAYOUT,
    ENV_ID,
    SMALL_ENV_ID,
    BridgeMazeEnv,
    bfs_distances,
    register_bridge_maze,
    value_iteration,
)

UP, DOWN, LEFT, RIGHT = range(4)


def _expected_q_from_bfs(env: BridgeMazeEnv) -> np.ndarray:
    """Q* for gamma = 1 written directly from BFS distances: 100 into the apple, else 100 - d'."""
    dist = bfs_distances(env.free_mask, env.goal)
    q = np.full((env.height, env.width, 4), np.nan)
    for r, c in env.free_cells:
        for a in range(4):
            if (r, c) == env.goal:
                q[r, c, a] = 0.0
                continue
            nr, nc = env.next_position(r, c, a)
            q[r, c, a] = 100.0 if (nr, nc) == env.goal else -1.0 + (101.0 - dist[nr, nc])
    return q


def test_default_start_value_is_75_and_dp_agrees_with_bfs() -> None:
    env = BridgeMazeEnv()
    assert env.start == (env.height - 1, 0) and env.goal == (0, env.width - 1)
    q_vi = env.value_iteration(gamma=1.0, tol=0.0)
    q_bfs = env.q_star()
    assert np.array_equal(q_vi, q_bfs, equal_nan=True)
    assert np.array_equal(q_vi, _expected_q_from_bfs(env), equal_nan=True)
    assert env.start_value() == 75.0 == maze.DEFAULT_START_VALUE
    assert env.v_star()[env.start] == 75.0
    assert env.shortest_distances()[env.start] == 26
    # Walls are NaN, the terminal apple cell is 0.
    assert np.isnan(q_bfs[env.wall_mask]).all()
    assert not np.isnan(q_bfs[env.free_mask]).any()
    assert (q_bfs[env.goal] == 0.0).all()


def test_q_star_at_start() -> None:
    env = BridgeMazeEnv()
    q = env.q_star()[env.start]
    assert q.max() == 75.0
    best = set(np.flatnonzero(q == 75.0).tolist())
    # From the bottom-left corner both up and right start a shortest path (ties are genuine);
    # down and left bump into the border and lose one step.
    assert best == {UP, RIGHT}
    assert q[DOWN] == q[LEFT] == 74.0
    assert all(q[a] < 75.0 for a in range(4) if a not in best)


def test_discounted_dp_agrees_with_bfs_recursion() -> None:
    env = BridgeMazeEnv()
    for gamma in (0.5, 0.9, 0.99):
        assert np.array_equal(env.value_iteration(gamma), env.q_star(gamma), equal_nan=True)
        d = 26
        closed = 100.0 * gamma ** (d - 1) - sum(gamma**i for i in range(d - 1))
        assert env.start_value(gamma) == pytest.approx(closed, rel=1e-12)


def test_make_and_check_env() -> None:
    register_bridge_maze()  # idempotent: already called at import
    register_bridge_maze()
    assert ENV_ID in gymnasium.registry and SMALL_ENV_ID in gymnasium.registry
    env = gymnasium.make(ENV_ID)
    assert isinstance(env.unwrapped, BridgeMazeEnv)
    assert env.unwrapped.start_value() == 75.0
    assert env.spec is not None and env.spec.max_episode_steps == 200
    check_env(env.unwrapped)
    env.close()
    check_env(gymnasium.make(ENV_ID, obs_type="coords").unwrapped)
    for mode in ("ansi", "rgb_array"):
        check_env(gymnasium.make(ENV_ID, render_mode=mode).unwrapped)
    small = gymnasium.make(SMALL_ENV_ID).unwrapped
    assert isinstance(small, BridgeMazeEnv)
    assert small.start_value() == maze.SMALL_START_VALUE == 91.0
    check_env(small)


def test_greedy_policy_reaches_apple_in_26_steps() -> None:
    env = BridgeMazeEnv()
    q = env.q_star()
    _, info = env.reset(seed=0)
    total, steps, terminated, truncated = 0.0, 0, False, False
    while not (terminated or truncated):
        r, c = info["position"]
        _, reward, terminated, truncated, info = env.step(int(np.argmax(q[r, c])))
        total += float(reward)
        steps += 1
    assert terminated and not truncated and info["is_success"]
    assert info["position"] == env.goal
    assert steps == 26 and total == 75.0
    with pytest.raises(RuntimeError):
        env.step(0)


def test_walls_block_and_bridge_is_only_passage() -> None:
    env = BridgeMazeEnv()
    assert env.bridge_cells == [(6, 6), (6, 7), (6, 8)]
    assert all(env.free_mask[cell] for cell in env.bridge_cells)
    # Every wall column is blocked except at the bridge row.
    for c in {col for _, col in env.bridge_cells}:
        assert env.wall_mask[:, c].sum() == env.height - 1
    # Moving right from the cell left of the wall band (off the bridge row) stays put.
    assert env.next_position(3, 5, RIGHT) == (3, 5)
    assert env.next_position(6, 5, RIGHT) == (6, 6)
    assert env.next_position(6, 7, UP) == (6, 7)  # walls above and below the bridge
    assert env.next_position(0, 0, UP) == (0, 0)  # border
    assert env.next_position(12, 0, LEFT) == (12, 0)
    # Walking straight right from the start hits the wall band and stays in place.
    _, info = env.reset()
    for _ in range(10):
        _, reward, *_rest, info = env.step(RIGHT)
        assert reward == -1.0
    assert info["position"] == (12, 5)
    # Removing any bridge cell cuts the maze in two.
    rows = DEFAULT_LAYOUT.splitlines()
    for _, c in env.bridge_cells:
        blocked = rows.copy()
        blocked[6] = blocked[6][:c] + "#" + blocked[6][c + 1 :]
        with pytest.raises(ValueError, match="goal unreachable"):
            BridgeMazeEnv(layout="\n".join(blocked))


def test_observations() -> None:
    env = BridgeMazeEnv()
    obs, info = env.reset(seed=1)
    assert obs.dtype == np.float32 and obs.shape == (env.n_states,) == (159,)
    assert obs.sum() == 1.0 and obs[env.state_index(*env.start)] == 1.0
    assert info["position"] == env.start
    assert np.array_equal(obs, env.obs_for(*env.start))
    for action in (UP, UP, RIGHT, DOWN, RIGHT):
        obs, _, _, _, info = env.step(action)
        r, c = info["position"]
        assert obs.sum() == 1.0 and np.flatnonzero(obs).tolist() == [env.state_index(r, c)]
        assert np.array_equal(obs, env.obs_for(r, c))
        assert info["state_index"] == env.state_index(r, c)
    assert env.cell_of(env.state_index(3, 4)) == (3, 4)
    with pytest.raises(ValueError):
        env.state_index(0, 6)  # a wall cell
    all_obs = env.all_observations()
    assert np.array_equal(all_obs, np.eye(env.n_states, dtype=np.float32))

    cenv = BridgeMazeEnv(obs_type="coords")
    obs, _ = cenv.reset()
    assert obs.shape == (2,) and obs.dtype == np.float32
    assert np.array_equal(obs, np.array([1.0, 0.0], dtype=np.float32))
    coords = cenv.all_observations()
    assert coords.min() >= 0.0 and coords.max() <= 1.0
    assert np.array_equal(cenv.obs_for(*cenv.goal), np.array([0.0, 1.0], dtype=np.float32))
    for action in (UP, RIGHT, RIGHT):
        obs, _, _, _, info = cenv.step(action)
        assert np.array_equal(obs, cenv.obs_for(*info["position"]))
        assert cenv.observation_space.contains(obs)


def test_time_limit_truncates() -> None:
    env = BridgeMazeEnv(max_episode_steps=7)
    env.reset()
    for t in range(1, 8):
        _, _, terminated, truncated, _ = env.step(LEFT)
        assert not terminated
        assert truncated == (t == 7)
    wrapped = gymnasium.make(ENV_ID, max_episode_steps=5)
    wrapped.reset(seed=0)
    outs = [wrapped.step(DOWN) for _ in range(5)]
    assert [o[3] for o in outs] == [False] * 4 + [True]
    assert not any(o[2] for o in outs)
    default = BridgeMazeEnv()
    default.reset()
    flags = [default.step(LEFT)[2:4] for _ in range(200)]
    assert flags[-1] == (False, True) and all(f == (False, False) for f in flags[:-1])


def test_custom_layout_matches_bfs() -> None:
    layout = """
        ....#..G
        .##.#.#.
        .#..=...
        .#.##.#.
        S...#...
    """
    env = BridgeMazeEnv(layout=layout, obs_type="coords")
    assert (env.height, env.width) == (5, 8)
    assert env.start == (4, 0) and env.goal == (0, 7)
    assert env.bridge_cells == [(2, 4)]
    q = env.q_star()
    assert np.array_equal(q, _expected_q_from_bfs(env), equal_nan=True)
    assert np.array_equal(q, value_iteration(env.free_mask, env.goal), equal_nan=True)
    dist = env.shortest_distances()
    assert env.start_value() == 101.0 - dist[env.start]
    check_env(env, skip_render_check=True)
    # Unmarked corridors are detected as the bridge; parametric layouts round-trip.
    plain = BridgeMazeEnv(layout=DEFAULT_LAYOUT.replace("=", "."))
    assert plain.bridge_cells == [(6, 6), (6, 7), (6, 8)] and plain.layout == DEFAULT_LAYOUT
    assert BridgeMazeEnv(layout=DEFAULT_LAYOUT).layout == BridgeMazeEnv().layout


def test_parametric_options() -> None:
    env = BridgeMazeEnv(width=11, height=9, wall_cols=[4, 5], bridge_row=2)
    assert env.bridge_cells == [(2, 4), (2, 5)]
    assert env.start_value() == 101.0 - (10 + 8)
    assert np.array_equal(env.value_iteration(), env.q_star(), equal_nan=True)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"obs_type": "pixels"}, "obs_type must be one of"),
        ({"render_mode": "human"}, "render_mode must be"),
        ({"wall_cols": [0, 1]}, "wall_cols must lie in"),
        ({"wall_cols": [5, 7]}, "contiguous"),
        ({"bridge_row": 13}, "bridge_row must be"),
        ({"width": 2}, "width must be"),
        ({"max_episode_steps": 0}, "max_episode_steps must be"),
        ({"layout": "S.#G"}, "goal unreachable"),
        ({"layout": "S..\n..."}, "exactly one"),
        ({"layout": "S.x\n..G"}, "layout characters"),
        ({"layout": "S..\n.G"}, "same length"),
        ({"layout": "S.G", "width": 3}, "either layout"),
    ],
)
def test_validation(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        BridgeMazeEnv(**kwargs)


def test_render_modes() -> None:
    env = BridgeMazeEnv(render_mode="ansi")
    env.reset()
    text = env.render()
    assert isinstance(text, str)
    lines = text.splitlines()
    assert lines[12][0] == "A" and lines[0][-1] == "G" and lines[6] == "......===......"
    img_env = BridgeMazeEnv(render_mode="rgb_array", cell_px=4)
    img_env.reset()
    img = img_env.render()
    assert isinstance(img, np.ndarray)
    assert img.shape == (13 * 4, 15 * 4, 3) and img.dtype == np.uint8
    assert BridgeMazeEnv().render() is None
