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

The grid's moves, rewards, layouts and exact values, as functions of plain arrays, live in
:mod:`farsighter.envs.maze_grid` and are re-exported here; the environment class stays here
(checkpoints pickle it by this module's path, and the registered ids name it).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, SupportsFloat

import gymnasium
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from farsighter.envs.maze_grid import (  # noqa: F401  (re-exported)
    ACTION_NAMES,
    BRIDGE,
    DEFAULT_HEIGHT,
    DEFAULT_WIDTH,
    FREE,
    GOAL,
    GOAL_REWARD,
    LAYOUT_CHARS,
    MOVES,
    START,
    STEP_REWARD,
    WALL,
    Cell,
    _cells,
    _check_gamma,
    _connected,
    _detect_bridge,
    _next_cell,
    _unreachable_value,
    bfs_distances,
    build_layout,
    parse_layout,
    q_from_v,
    value_iteration,
)

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

ENV_ID = "farsighter/BridgeMaze-v0"
SMALL_ENV_ID = "farsighter/BridgeMazeSmall-v0"
ENTRY_POINT = "farsighter.envs.maze:BridgeMazeEnv"

DEFAULT_MAX_EPISODE_STEPS = 200
OBS_TYPES = ("onehot", "coords")

DEFAULT_LAYOUT = build_layout()
SMALL_LAYOUT = build_layout(width=7, height=5)
DEFAULT_START_VALUE = 75.0  # paper section 5.1: Q_g = 75 at the bottom-left start
SMALL_START_VALUE = 91.0  # 10 steps: 9 x (-1) + 100


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
