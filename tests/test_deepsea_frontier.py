"""The deep sea frontier read back from a run's replayed observations
(benchmarks/deepsea_frontier.py)."""

import numpy as np

from benchmarks.deepsea_frontier import frontier, parse_value


def one_hot(n: int, cells: list[tuple[int, int]]) -> np.ndarray:
    frames = np.zeros((len(cells), n * n), dtype=np.float32)
    for i, (row, col) in enumerate(cells):
        if row >= 0:
            frames[i, row * n + col] = 1.0
    return frames


def test_frontier_counts_episodes_from_row_zero_and_skips_blank_rows() -> None:
    n = 3
    # episode 1 drifts left then right once; a blank row (past the episode's end); episode 2
    # goes right twice; episode 3 stays left
    cells = [(0, 0), (1, 0), (2, 1), (-1, -1), (0, 0), (1, 1), (2, 2), (0, 0), (1, 0), (2, 0)]
    out = frontier(one_hot(n, cells), n)
    assert out["rightmost_column"] == 2
    assert out["first_episode_of_column"] == {0: 1, 1: 1, 2: 2}
    assert out["reachable_cells"] == 6
    assert out["reachable_cells_visited"] == 6
    out = frontier(one_hot(n, cells[:7]), n)
    assert out["reachable_cells_visited"] == 5  # (2, 0) first visited in episode 3


def test_set_values_are_literals_where_they_parse() -> None:
    assert parse_value("512") == 512
    assert parse_value("True") is True
    assert parse_value("episode") == "episode"
