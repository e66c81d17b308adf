"""Toy bridge maze of paper section 5.1 (Figure 1a), SPEC section 3.

A grid split into a left and a right part by a wall; a one-cell-high bridge is the only passage.
The agent (the paper's "car") starts in the bottom-left corner, the apple is in the top-right
corner. Actions: 0 up, 1 down, 2 left, 3 right; a move into a wall or the border leaves the agent
in place. Reward +100 on reaching the apple (the episode terminates) and -1 on every other step.

With the intended discount gamma = 1 (undiscounted) the optimal value of a cell at shortest-path
distance ``d`` from the apple is ``100 - (d - 1) = 101 - d``. The default layout (15 x 13, a wall
band three columns thick with the bridge in the middle row) puts the start 26 steps from the
apple, so ``V*(start) = 75``, the paper's ``Q_g = 75`` (section 5.1)::

    ......###.....G
    ......###......
    ......###......
    ......###......
    ......###......
    ......###......
    ......===......
    ......###......
    ......###......
    ......###......
    ......###......
    ......###......
    S.....###......

(``=`` marks the bridge). 159 free cells, 78 on each side plus the 3 bridge cells.

The small variant ``farsighter/BridgeMazeSmall-v0`` (7 x 5, one wall column, 31 free cells) puts
the start 10 steps from the apple, so its ``V*(start) = 91``.

Q* table convention (:meth:`BridgeMazeEnv.q_star`): shape ``(height, width, 4)`` indexed
``[row, col, action]``; wall cells are ``NaN``; the apple cell is terminal, so its entries are 0;
a free cell cut off from the apple (possible only in custom layouts) has ``-inf`` for gamma = 1
and ``-1 / (1 - gamma)`` otherwise.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from typing import Any, SupportsFloat

import gymnasium
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

__all__ = [
    "ACTION_NAMES",
    "DEFAULT_LAYOUT",
    "DEFAULT_START_VALUE",
    "ENV_ID",
    "GOAL_REWARD",
    "MOVES",
    "SMALL_ENV_ID",
    "SMALL_LAYOUT",
    "SMALL_START_VALUE",
    "STEP_REWARD",
    "BridgeMazeEnv",
    "bfs_distances",
    "build_layout",
    "parse_layout",
    "q_from_v",
    "register_bridge_maze",
    "value_iteration",
]

Cell = tuple[int, int]

ENV_ID = "farsighter/BridgeMaze-v0"
SMALL_ENV_ID = "farsighter/BridgeMazeSmall-v0"
ENTRY_POINT = "farsighter.envs.maze:BridgeMazeEnv"

# Rewards of section 5.1: +100 for the apple, -1 for every other step.
GOAL_REWARD = 100.0
STEP_REWARD = -1.0

# Action index -> (d_row, d_col); row 0 is the top row.
MOVES: tuple[Cell, ...] = ((-1, 0), (1, 0), (0, -1), (0, 1))
ACTION_NAMES: tuple[str, ...] = ("up", "down", "left", "right")

DEFAULT_WIDTH = 15
DEFAULT_HEIGHT = 13
DEFAULT_MAX_EPISODE_STEPS = 200
OBS_TYPES = ("onehot", "coords")

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


DEFAULT_LAYOUT = build_layout()
SMALL_LAYOUT = build_layout(width=7, height=5)
DEFAULT_START_VALUE = 75.0  # paper section 5.1: Q_g = 75 at the bottom-left start
SMALL_START_VALUE = 91.0  # 10 steps: 9 x (-1) + 100


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


class BridgeMazeEnv(gymnasium.Env[NDArray[np.float32], np.int64]):
    """Toy bridge maze of paper section 5.1 with its exact Q* table.

    Args:
        width, height: grid size of the parametric layout (default 15 x 13).
        wall_cols: contiguous columns of the wall band (default: 3 centred columns, 1 if
            ``width < 9``).
        bridge_row: row (0 = top) of the one-cell-high bridge through the band (default
            ``height // 2``).
        layout: ASCII alternative to the four options above (``#`` wall, ``.`` free, ``S``
            start, ``G`` apple, ``=`` optional bridge marker); cannot be combined with them.
        max_episode_steps: steps after which the episode is truncated (``truncated=True``);
            ``None`` disables the env's own limit (the registered ids use Gymnasium's
            ``TimeLimit`` with 200 instead).
        obs_type: ``"onehot"`` (float32 vector of length ``n_states``, the number of free cells,
            with a 1 at :meth:`state_index` of the agent) or ``"coords"`` (float32
            ``(row / (height - 1), col / (width - 1))`` in [0, 1]).
        render_mode: ``None``, ``"ansi"`` or ``"rgb_array"``.
        cell_px: pixels per cell of the ``rgb_array`` image.

    ``info`` holds ``position`` (row, col), ``state_index`` and, after a step, ``is_success``.
    """

    metadata: dict[str, Any] = {"render_modes": ["ansi", "rgb_array"], "render_fps": 8}

    def __init__(
        self,
        width: int | None = None,
        height: int | None = None,
        wall_cols: Sequence[int] | None = None,
        bridge_row: int | None = None,
        layout: str | None = None,
        max_episode_steps: int | None = DEFAULT_MAX_EPISODE_STEPS,
        obs_type: str = "onehot",
        render_mode: str | None = None,
        cell_px: int = 8,
    ) -> None:
        super().__init__()
        if layout is not None:
            given = {
                "width": width,
                "height": height,
                "wall_cols": wall_cols,
                "bridge_row": bridge_row,
            }
            clash = [k for k, val in given.items() if val is not None]
            if clash:
                raise ValueError(f"pass either layout or {clash}, not both")
        else:
            layout = build_layout(
                DEFAULT_WIDTH if width is None else width,
                DEFAULT_HEIGHT if height is None else height,
                wall_cols,
                bridge_row,
            )
        free, start, goal, marked = parse_layout(layout)
        if start == goal:
            raise ValueError("start and goal must differ")
        if not _connected(free, start, goal):
            raise ValueError(
                "goal unreachable: the layout must connect 'S' to 'G' through free cells "
                "(the bridge is the only passage between the two sides)"
            )
        if obs_type not in OBS_TYPES:
            raise ValueError(f"obs_type must be one of {OBS_TYPES}, got {obs_type!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be None or one of {self.metadata['render_modes']}, "
                f"got {render_mode!r}"
            )
        if max_episode_steps is not None and (
            not isinstance(max_episode_steps, int | np.integer) or max_episode_steps < 1
        ):
            raise ValueError(
                f"max_episode_steps must be a positive integer or None, got {max_episode_steps!r}"
            )
        if not isinstance(cell_px, int | np.integer) or cell_px < 1:
            raise ValueError(f"cell_px must be a positive integer, got {cell_px!r}")

        self.height, self.width = (int(x) for x in free.shape)
        self._free = free
        self._free.setflags(write=False)
        self.start: Cell = start
        self.goal: Cell = goal
        self.bridge_cells: list[Cell] = marked or _detect_bridge(free, start, goal)
        self.free_cells: list[Cell] = _cells(free)
        self._index = {cell: i for i, cell in enumerate(self.free_cells)}
        self.n_states = len(self.free_cells)
        self.max_episode_steps = None if max_episode_steps is None else int(max_episode_steps)
        self.obs_type = obs_type
        self.render_mode = render_mode
        self.cell_px = int(cell_px)
        self._layout = "\n".join(
            "".join(self._cell_char((r, c)) for c in range(self.width)) for r in range(self.height)
        )

        self.action_space = spaces.Discrete(len(MOVES))
        shape = (self.n_states,) if obs_type == "onehot" else (2,)
        self.observation_space = spaces.Box(0.0, 1.0, shape=shape, dtype=np.float32)

        self._pos: Cell = start
        self._steps = 0
        self._needs_reset = True
        self._q_cache: dict[float, NDArray[np.float64]] = {}

    # ----------------------------------------------------------------- layout helpers
    @property
    def free_mask(self) -> NDArray[np.bool_]:
        """Boolean ``(height, width)`` mask of walkable cells (a copy)."""
        return self._free.copy()

    @property
    def wall_mask(self) -> NDArray[np.bool_]:
        """Boolean ``(height, width)`` mask of wall cells."""
        return ~self._free

    @property
    def layout(self) -> str:
        """The layout as an ASCII string accepted by ``layout=``."""
        return self._layout

    @property
    def position(self) -> Cell:
        """Current (row, col) of the agent."""
        return self._pos

    def _cell_char(self, cell: Cell) -> str:
        if not self._free[cell]:
            return WALL
        if cell == self.start:
            return START
        if cell == self.goal:
            return GOAL
        return BRIDGE if cell in self.bridge_cells else FREE

    def state_index(self, row: int, col: int) -> int:
        """Index of a free cell in row-major order over free cells (the one-hot position)."""
        try:
            return self._index[(int(row), int(col))]
        except KeyError:
            raise ValueError(f"({row}, {col}) is not a free cell of the maze") from None

    def cell_of(self, index: int) -> Cell:
        """Inverse of :meth:`state_index`."""
        return self.free_cells[index]

    def obs_for(self, row: int, col: int) -> NDArray[np.float32]:
        """Observation the env returns when the agent is at (row, col)."""
        idx = self.state_index(row, col)
        if self.obs_type == "onehot":
            obs = np.zeros(self.n_states, dtype=np.float32)
            obs[idx] = 1.0
            return obs
        return np.array(
            [row / max(self.height - 1, 1), col / max(self.width - 1, 1)], dtype=np.float32
        )

    def all_observations(self) -> NDArray[np.float32]:
        """``(n_states, obs_dim)`` observations of every free cell, in :meth:`state_index` order."""
        return np.stack([self.obs_for(r, c) for r, c in self.free_cells])

    def next_position(self, row: int, col: int, action: int) -> Cell:
        """Deterministic transition (no reward); walls and the border leave the agent in place."""
        return _next_cell(self._free, (int(row), int(col)), int(action))

    # ----------------------------------------------------------------- exact values
    def shortest_distances(self) -> NDArray[np.int64]:
        """BFS step counts to the apple, ``(height, width)``; -1 for walls and cut-off cells."""
        return bfs_distances(self._free, self.goal)

    def value_iteration(
        self, gamma: float = 1.0, tol: float = 0.0, max_iter: int = 100_000
    ) -> NDArray[np.float64]:
        """Q* by value iteration (see module :func:`value_iteration`); independent of BFS."""
        return value_iteration(self._free, self.goal, gamma, tol, max_iter)

    def q_star(self, gamma: float = 1.0) -> NDArray[np.float64]:
        """Exact optimal Q*, ``(height, width, 4)`` indexed ``[row, col, action]``.

        Built from BFS distances (``V* = 101 - d`` for gamma = 1, the same recursion in general);
        NaN on walls, 0 on the terminal apple cell. Returns a copy.
        """
        gamma = _check_gamma(gamma)
        if gamma not in self._q_cache:
            dist = self.shortest_distances()
            v = np.full((self.height, self.width), _unreachable_value(gamma))
            v[~self._free] = np.nan
            # v_by_d[d]: value at distance d, same float recursion as value iteration.
            v_by_d = [0.0, GOAL_REWARD]
            for _ in range(2, int(dist.max()) + 1):
                v_by_d.append(STEP_REWARD + gamma * v_by_d[-1])
            reach = dist >= 0
            v[reach] = np.asarray(v_by_d)[dist[reach]]
            self._q_cache[gamma] = q_from_v(self._free, self.goal, v, gamma)
        return self._q_cache[gamma].copy()

    def v_star(self, gamma: float = 1.0) -> NDArray[np.float64]:
        """Optimal values ``max_a Q*``, ``(height, width)``; NaN on walls, 0 at the apple."""
        q = self.q_star(gamma)
        v = np.full((self.height, self.width), np.nan)
        v[self._free] = q[self._free].max(axis=-1)
        return v

    def start_value(self, gamma: float = 1.0) -> float:
        """``V*(start)``; 75.0 for the default layout with gamma = 1 (section 5.1)."""
        return float(self.v_star(gamma)[self.start])

    def optimal_action(self, row: int, col: int, gamma: float = 1.0) -> int:
        """Greedy action of Q* at (row, col) (lowest index among ties)."""
        self.state_index(row, col)  # validates the cell
        return int(np.argmax(self.q_star(gamma)[row, col]))

    # ----------------------------------------------------------------- Gymnasium API
    def _obs(self) -> NDArray[np.float32]:
        return self.obs_for(*self._pos)

    def _info(self) -> dict[str, Any]:
        return {"position": self._pos, "state_index": self._index[self._pos]}

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        """Put the agent on the start cell; the dynamics are deterministic, so ``seed`` only
        seeds ``self.np_random`` (via ``super().reset``)."""
        super().reset(seed=seed)
        self._pos = self.start
        self._steps = 0
        self._needs_reset = False
        return self._obs(), self._info()

    def step(
        self, action: np.int64 | int
    ) -> tuple[NDArray[np.float32], SupportsFloat, bool, bool, dict[str, Any]]:
        if self._needs_reset:
            raise RuntimeError("call reset() before step() (also after an episode ends)")
        if not self.action_space.contains(action):
            raise ValueError(f"action must be an integer in 0..{len(MOVES) - 1}, got {action!r}")
        self._pos = _next_cell(self._free, self._pos, int(action))
        self._steps += 1
        terminated = self._pos == self.goal
        reward = GOAL_REWARD if terminated else STEP_REWARD
        truncated = (
            not terminated
            and self.max_episode_steps is not None
            and self._steps >= self.max_episode_steps
        )
        self._needs_reset = terminated or truncated
        info = self._info()
        info["is_success"] = terminated
        return self._obs(), reward, terminated, truncated, info

    def render(self) -> str | NDArray[np.uint8] | None:  # type: ignore[override]
        """``"ansi"``: the layout with ``A`` for the agent; ``"rgb_array"``: a small uint8 image
        (white free, black wall, brown bridge, blue start, red apple, green agent)."""
        if self.render_mode == "ansi":
            rows = [list(line) for line in self._layout.splitlines()]
            rows[self._pos[0]][self._pos[1]] = "A"
            return "\n".join("".join(r) for r in rows) + "\n"
        if self.render_mode == "rgb_array":
            colours = {
                WALL: (0, 0, 0),
                FREE: (255, 255, 255),
                BRIDGE: (150, 100, 50),
                START: (120, 160, 255),
                GOAL: (220, 30, 30),
            }
            img = np.zeros((self.height, self.width, 3), dtype=np.uint8)
            for r, line in enumerate(self._layout.splitlines()):
                for c, ch in enumerate(line):
                    img[r, c] = colours[ch]
            img[self._pos] = (30, 180, 30)
            return np.repeat(np.repeat(img, self.cell_px, axis=0), self.cell_px, axis=1)
        return None


def register_bridge_maze() -> None:
    """Register ``farsighter/BridgeMaze-v0`` (default layout, V*(start) = 75) and
    ``farsighter/BridgeMazeSmall-v0`` (7 x 5, V*(start) = 91); idempotent.

    Both use Gymnasium's ``TimeLimit`` with 200 steps (the env's own limit is switched off), so
    ``gymnasium.make(id, max_episode_steps=n)`` overrides it as usual.
    """
    specs: dict[str, dict[str, Any]] = {
        ENV_ID: {"max_episode_steps": None},
        SMALL_ENV_ID: {"max_episode_steps": None, "width": 7, "height": 5},
    }
    for env_id, kwargs in specs.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(
                id=env_id,
                entry_point=ENTRY_POINT,
                max_episode_steps=DEFAULT_MAX_EPISODE_STEPS,
                kwargs=kwargs,
            )


register_bridge_maze()
