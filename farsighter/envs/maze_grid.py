"""The bridge maze's grid (:mod:`farsighter.envs.maze`, which re-exports these), as functions of
plain arrays: its moves and rewards, its layout (built from a few numbers, or parsed from ASCII),
and its exact values (BFS distances to the apple, Q* from V*, value iteration) that
:class:`~farsighter.envs.maze.BridgeMazeEnv` builds on."""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

Cell = tuple[int, int]


# Rewards of section 5.1: +100 for the apple, -1 for every other step.
GOAL_REWARD = 100.0
STEP_REWARD = -1.0

# Action index -> (d_row, d_col); row 0 is the top row.
MOVES: tuple[Cell, ...] = ((-1, 0), (1, 0), (0, -1), (0, 1))
ACTION_NAMES: tuple[str, ...] = ("up", "down", "left", "right")

DEFAULT_WIDTH = 15
DEFAULT_HEIGHT = 13

WALL, FREE, START, GOAL, BRIDGE = "#", ".", "S", "G", "="
LAYOUT_CHARS = (WALL, FREE, START, GOAL, BRIDGE)


def build_layout(
    width: int = DEFAULT_WIDTH,
    height: int = DEFAULT_HEIGHT,
    wall_cols: Sequence[int] | None = None,
    bridge_row: int | None = None,
) -> str:
    """ASCII layout of a parametric bridge maze (start bottom-left, apple top-right).

    ``wall_cols`` are the (contiguous) columns of the wall band; by default a band three columns
    thick (one column when ``width < 9``) centred in the grid. ``bridge_row`` (row 0 is the top)
    is the row of the one-cell-high passage through the band; by default ``height // 2``.
    """
    if not isinstance(width, int | np.integer) or width < 3:
        raise ValueError(f"width must be an integer >= 3, got {width!r}")
    if not isinstance(height, int | np.integer) or height < 1:
        raise ValueError(f"height must be an integer >= 1, got {height!r}")
    if wall_cols is None:
        thickness = 3 if width >= 9 else 1
        first = (width - thickness) // 2
        cols = list(range(first, first + thickness))
    else:
        cols = sorted({int(c) for c in wall_cols})
        if not cols:
            raise ValueError("wall_cols must name at least one column")
        if cols[0] < 1 or cols[-1] > width - 2:
            raise ValueError(
                f"wall_cols must lie in 1..{width - 2} (columns 0 and width-1 hold the start and "
                f"the apple), got {list(wall_cols)}"
            )
        if cols != list(range(cols[0], cols[-1] + 1)):
            raise ValueError(f"wall_cols must be contiguous, got {list(wall_cols)}")
    row = height // 2 if bridge_row is None else bridge_row
    if not isinstance(row, int | np.integer) or not 0 <= row < height:
        raise ValueError(f"bridge_row must be an integer in 0..{height - 1}, got {bridge_row!r}")
    grid = [[FREE] * width for _ in range(height)]
    for r in range(height):
        for c in cols:
            grid[r][c] = BRIDGE if r == row else WALL
    grid[height - 1][0] = START
    grid[0][width - 1] = GOAL
    return "\n".join("".join(line) for line in grid)


def parse_layout(layout: str) -> tuple[NDArray[np.bool_], Cell, Cell, list[Cell]]:
    """Parse an ASCII layout into ``(free_mask, start, goal, marked_bridge_cells)``.

    Characters: ``#`` wall, ``.`` free, ``S`` start (exactly one), ``G`` goal/apple (exactly one),
    ``=`` free cell marked as part of the bridge (optional, informational). Leading/trailing
    whitespace of each line and blank lines are ignored, so indented triple-quoted strings work.
    """
    if not isinstance(layout, str):
        raise ValueError(f"layout must be a string, got {type(layout).__name__}")
    rows = [line.strip() for line in layout.strip().splitlines() if line.strip()]
    if not rows:
        raise ValueError("layout is empty")
    width = len(rows[0])
    if any(len(r) != width for r in rows):
        raise ValueError(f"layout rows must all have the same length, got {[len(r) for r in rows]}")
    bad = sorted({ch for r in rows for ch in r if ch not in LAYOUT_CHARS})
    if bad:
        raise ValueError(f"layout characters must be among {LAYOUT_CHARS!r}, got {bad!r}")
    starts = [(i, j) for i, r in enumerate(rows) for j, ch in enumerate(r) if ch == START]
    goals = [(i, j) for i, r in enumerate(rows) for j, ch in enumerate(r) if ch == GOAL]
    if len(starts) != 1 or len(goals) != 1:
        raise ValueError(
            f"layout must contain exactly one '{START}' and one '{GOAL}', got "
            f"{len(starts)} and {len(goals)}"
        )
    free = np.array([[ch != WALL for ch in r] for r in rows], dtype=bool)
    bridge = [(i, j) for i, r in enumerate(rows) for j, ch in enumerate(r) if ch == BRIDGE]
    return free, starts[0], goals[0], bridge


def _cells(mask: NDArray[np.bool_]) -> list[Cell]:
    """(row, col) of the True entries of ``mask`` in row-major order."""
    return [(int(r), int(c)) for r, c in np.argwhere(mask)]


def _next_cell(free: NDArray[np.bool_], cell: Cell, action: int) -> Cell:
    """Deterministic move; into a wall or the border the agent stays put."""
    dr, dc = MOVES[action]
    r, c = cell[0] + dr, cell[1] + dc
    if 0 <= r < free.shape[0] and 0 <= c < free.shape[1] and free[r, c]:
        return r, c
    return cell


def bfs_distances(free: NDArray[np.bool_], goal: Cell) -> NDArray[np.int64]:
    """Shortest-path step counts from every cell to ``goal``; -1 for walls and cut-off cells.

    Moves are reversible, so the distance from ``goal`` equals the distance to it.
    """
    dist = np.full(free.shape, -1, dtype=np.int64)
    dist[goal] = 0
    queue: deque[Cell] = deque([goal])
    while queue:
        cell = queue.popleft()
        for a in range(len(MOVES)):
            nxt = _next_cell(free, cell, a)
            if dist[nxt] < 0:
                dist[nxt] = dist[cell] + 1
                queue.append(nxt)
    return dist


def _unreachable_value(gamma: float) -> float:
    """Value of a cell that cannot reach the apple: -1 forever."""
    return -np.inf if gamma == 1.0 else STEP_REWARD / (1.0 - gamma)


def _check_gamma(gamma: float) -> float:
    gamma = float(gamma)
    if not 0.0 < gamma <= 1.0:
        raise ValueError(f"gamma must be in (0, 1], got {gamma}")
    return gamma


def q_from_v(
    free: NDArray[np.bool_], goal: Cell, v: NDArray[np.float64], gamma: float = 1.0
) -> NDArray[np.float64]:
    """One Bellman backup ``Q(s, a) = r(s, a) + gamma * V(s')`` (no bootstrap into the apple).

    Returns an ``(H, W, 4)`` table: NaN on walls, 0 on the (terminal) apple cell.
    """
    gamma = _check_gamma(gamma)
    h, w = free.shape
    q = np.full((h, w, len(MOVES)), np.nan, dtype=np.float64)
    for r in range(h):
        for c in range(w):
            if not free[r, c]:
                continue
            if (r, c) == goal:
                q[r, c] = 0.0
                continue
            for a in range(len(MOVES)):
                nxt = _next_cell(free, (r, c), a)
                q[r, c, a] = GOAL_REWARD if nxt == goal else STEP_REWARD + gamma * v[nxt]
    return q


def value_iteration(
    free: NDArray[np.bool_],
    goal: Cell,
    gamma: float = 1.0,
    tol: float = 0.0,
    max_iter: int = 100_000,
) -> NDArray[np.float64]:
    """Exact optimal Q* of the maze by synchronous value iteration (section 5.1's ``Q_g``).

    Iterates ``V <- max_a r(s, a) + gamma * V(s')`` from ``V = 0`` on the cells connected to the
    apple until the largest change is ``<= tol``. From ``V = 0`` each cell's value is exact (to the
    last bit) once the iteration count reaches its distance to the apple, so ``tol = 0`` terminates
    after ``max distance + 1`` sweeps for any gamma in (0, 1]. Cells cut off from the apple take
    their closed-form value (``-inf`` for gamma = 1, ``-1 / (1 - gamma)`` otherwise) instead of
    diverging. Returns the ``(H, W, 4)`` table of :func:`q_from_v`.
    """
    gamma = _check_gamma(gamma)
    cells = _cells(bfs_distances(free, goal) >= 0)
    index = {cell: i for i, cell in enumerate(cells)}
    n, n_act = len(cells), len(MOVES)
    nxt = np.zeros((n, n_act), dtype=np.int64)
    reward = np.full((n, n_act), STEP_REWARD)
    cont = np.ones((n, n_act))  # 0 where the transition ends the episode (reaching the apple)
    for i, cell in enumerate(cells):
        for a in range(n_act):
            nc = _next_cell(free, cell, a)
            nxt[i, a] = index[nc]
            if nc == goal:
                reward[i, a], cont[i, a] = GOAL_REWARD, 0.0
    is_goal = np.array([cell == goal for cell in cells])
    v = np.zeros(n)
    for _ in range(max_iter):
        v_new = (reward + gamma * cont * v[nxt]).max(axis=1)
        v_new[is_goal] = 0.0  # terminal
        delta = float(np.max(np.abs(v_new - v)))
        v = v_new
        if delta <= tol:
            break
    else:
        raise RuntimeError(f"value iteration did not reach tol={tol} in {max_iter} sweeps")
    v_grid = np.full(free.shape, _unreachable_value(gamma))
    v_grid[~free] = np.nan
    for i, cell in enumerate(cells):
        v_grid[cell] = v[i]
    return q_from_v(free, goal, v_grid, gamma)


def _connected(free: NDArray[np.bool_], a: Cell, b: Cell) -> bool:
    return bool(bfs_distances(free, b)[a] >= 0)


def _detect_bridge(free: NDArray[np.bool_], start: Cell, goal: Cell) -> list[Cell]:
    """Bridge cells of a layout without ``=`` marks: corridor cells on every start-apple path.

    A free cell qualifies when removing it disconnects the start from the apple and it is walled
    (or bordered) on two opposite sides, i.e. it lies inside a one-cell-wide passage.
    """
    h, w = free.shape

    def blocked(r: int, c: int) -> bool:
        return not (0 <= r < h and 0 <= c < w and free[r, c])

    out: list[Cell] = []
    for cell in _cells(free):
        r, c = cell
        if cell in (start, goal):
            continue
        if not (
            (blocked(r - 1, c) and blocked(r + 1, c)) or (blocked(r, c - 1) and blocked(r, c + 1))
        ):
            continue
        trial = free.copy()
        trial[cell] = False
        if not _connected(trial, start, goal):
            out.append(cell)
    return out
