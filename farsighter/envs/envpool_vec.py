"""Vectorised Atari through envpool (optional extra ``farsighter[envpool]``), with the preprocessing
and the vector-step contract of the Gymnasium path (:func:`farsighter.envs.atari.wrap_atari` under
``SyncVectorEnv(autoreset_mode=SAME_STEP)``), so the training loop cannot tell them apart.

envpool (1.2.5) runs the emulator, frame skip with max-pooling over the last two frames, no-op
starts, grey conversion and the 84x84 ``INTER_AREA`` resize in C++. Everything whose envpool
version differs from ours is done here instead:

* frame stacking: envpool fills a new game's stack with copies of its first frame and does not
  restart the stack after a life loss; we ask it for single frames (``stack_num=1``) and stack
  them here with zeros before every episode start, as ``FrameStackObservation(padding_type="zero")``
  and the replay's stack rebuilding do;
* life-loss terminals: envpool's ``episodic_life`` restarts a life with 1..noop_max single no-op
  frames at its next ``step``; :class:`~farsighter.envs.atari.EpisodicLife` takes one no-op agent
  step (frame skip, max-pool), and so do we, at once, on that environment alone;
* reward clipping: done here, so that episode statistics keep the unclipped rewards;
* autoreset: envpool answers the first ``step`` after an episode end with the reset observation
  and ignores that step's action (envpool issues 33, 194, 257). We reset every environment whose
  game ended within the same call (``reset(env_id)`` on just those), so the next ``step`` never
  meets envpool's autoreset and no transition crosses an episode boundary: the step that ends an
  episode returns the new episode's first observation, and the ended one's last in
  ``info["final_obs"]`` (Gymnasium's SAME_STEP contract).

What cannot be made identical is listed in :class:`EnvpoolAtariVector`'s docstring.
"""

from __future__ import annotations

import importlib.util
import time
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

import gymnasium as gym
import numpy as np

from farsighter.envs.atari import ale_name
from farsighter.errors import EnvError

ENVPOOL_EXTRA = "install the envpool extra: pip install 'farsighter[envpool]'"
# ALE v5 and NoFrameskip-v4 ids truncate a game at 108,000 emulator frames (30 minutes at 60 Hz).
MAX_FRAMES_PER_EPISODE = 108_000


def envpool_available() -> bool:
    """envpool is installed (it is imported only when an environment is made)."""
    return importlib.util.find_spec("envpool") is not None


def _atari_tasks() -> dict[str, str]:
    """envpool's Atari task ids keyed by their lower-case name (``breakout-v5`` -> ``Breakout-v5``)."""
    from envpool.registration import registry

    return {
        task.lower(): task
        for task, (import_path, _, _) in registry.specs.items()
        if import_path == "envpool.atari"
    }


def envpool_task_id(env_id: str) -> str:
    """The envpool task of an ALE id: ``ALE/Breakout-v5`` and ``BreakoutNoFrameskip-v4`` ->
    ``Breakout-v5``. Raises a one-line :class:`EnvError` for a game envpool lacks."""
    game = ale_name(env_id)
    if game is None:  # RAM observations (Breakout-ram-v5) are not ALE image ids either
        raise EnvError(
            f"'{env_id}' is not an ALE id (accepted: ALE/<Game>-v5 or <Game>NoFrameskip-v4)"
        )
    if not envpool_available():
        raise EnvError(f"the envpool Atari backend needs envpool; {ENVPOOL_EXTRA}")
    tasks = _atari_tasks()
    task = tasks.get(f"{game}-v5".lower())
    if task is None:
        raise EnvError(
            f"envpool has no Atari game '{game}' (from '{env_id}'; it has {len(tasks)} Atari "
            "games, e.g. Breakout-v5, Pong-v5); use the Gymnasium backend for this id"
        )
    return task


def envpool_supports(env_id: str, noop_max: int) -> bool:
    """envpool is installed, has this ALE id's game, and can start games as configured (it
    always takes at least one no-op, so ``noop_max`` must be >= 1): what an ``auto`` backend
    choice asks before using envpool."""
    if noop_max < 1 or not envpool_available():
        return False
    try:
        envpool_task_id(env_id)
    except EnvError:
        return False
    return True


def _check_settings(
    num_envs: int, noop_max: int, frame_skip: int, frame_stack: int, screen_size: int
) -> None:
    """One EnvError line for settings the envpool backend cannot serve."""
    if num_envs < 1:
        raise EnvError(f"num_envs must be >= 1 (got {num_envs})")
    if noop_max < 1:
        raise EnvError(
            f"the envpool Atari backend needs noop_max >= 1 (got {noop_max}): envpool always "
            "takes at least one no-op frame at a game start; use the Gymnasium backend"
        )
    if frame_skip < 1 or frame_stack < 1 or screen_size < 1:
        raise EnvError(
            f"frame_skip, frame_stack and screen_size must be >= 1 (got {frame_skip}, "
            f"{frame_stack}, {screen_size})"
        )


class EnvpoolAtariVector(gym.vector.VectorEnv):
    """``num_envs`` Atari games stepped together by envpool, with :func:`wrap_atari`'s
    preprocessing and Gymnasium's SAME_STEP autoreset contract:

    * ``obs`` (E, stack, size, size) uint8, zeros before the first frame of every episode (a new
      game, or with life-loss terminals a new life);
    * at a step that ends an episode: ``obs[e]`` is the new episode's first stack,
      ``info["final_obs"][e]`` the ended one's last (object array, mask ``info["_final_obs"]``),
      ``info["final_info"]`` its info (``lives``, and ``episode`` when the whole game ended);
    * ``info["final_info"]["episode"]`` {"r", "l", "t"} (mask ``info["final_info"]["_episode"]``):
      a whole game's unclipped return and length in agent steps, counted like
      ``RecordEpisodeStatistics`` placed before the life-loss wrapper, so the no-op step that
      starts each new life counts too;
    * ``info["lives"]`` (mask ``info["_lives"]``): lives after the step (after a reset, of the
      new game).

    Not identical to the Gymnasium path (all minor; none changes a transition's meaning):

    * random streams: no-op counts come from envpool's per-environment generator (seed + e), not
      from Gymnasium's ``np_random``; the same seed gives other (equally distributed) starts;
    * ``noop_max=0`` is refused: envpool always takes 1..noop_max no-op frames at a game start
      (its ``noop_max=0`` crashes);
    * a game that ends inside a frame skip: Gymnasium's final observation max-pools the
      previous step's last two frames, envpool's is the frame at which the game ended (only
      ``final_obs`` of a terminal differs, and terminals are not bootstrapped from);
    * the 108,000-frame time limit counts agent steps (27,000 at frame skip 4) from the game's
      start, not emulator frames including the start's no-ops (at most noop_max frames later);
    * a game ending on the no-op step that starts a new life (a time limit reached there): its
      statistics are reported here; Gymnasium's wrappers drop them;
    * a game over on the very step the time limit is reached is ``terminated`` only here (ALE
      reports it both terminated and truncated);
    * sticky actions (``repeat_action_probability`` > 0) draw from envpool's ALE generator.

    Environment state cannot be pickled (envpool holds C++ handles): checkpoints of a run on this
    backend resume with fresh episodes.
    """

    metadata: dict[str, Any] = {
        "render_modes": [],
        "autoreset_mode": gym.vector.AutoresetMode.SAME_STEP,
    }

    def __init__(
        self,
        task_id: str,
        num_envs: int,
        seed: int,
        *,
        frame_skip: int = 4,
        noop_max: int = 30,
        screen_size: int = 84,
        frame_stack: int = 4,
        training: bool = True,
        terminal_on_life_loss: bool = True,
        clip_rewards: bool = True,
        repeat_action_probability: float = 0.0,
        max_episode_steps: int | None = None,
        num_threads: int = 1,
    ) -> None:
        _check_settings(num_envs, noop_max, frame_skip, frame_stack, screen_size)
        self.task_id = task_id
        self.num_envs = num_envs
        self.frame_stack = frame_stack
        self.life_terminals = training and terminal_on_life_loss
        self.clip_rewards = training and clip_rewards
        self.max_episode_steps = (
            max_episode_steps
            if max_episode_steps is not None
            else MAX_FRAMES_PER_EPISODE // frame_skip
        )
        self._options: dict[str, Any] = {
            "num_envs": num_envs,
            "batch_size": num_envs,  # synchronous: every step returns all requested envs
            "num_threads": num_threads,
            "stack_num": 1,  # stacked here, zero-padded
            "frame_skip": frame_skip,
            "noop_max": noop_max,
            "img_height": screen_size,
            "img_width": screen_size,
            "gray_scale": True,
            "use_inter_area_resize": True,  # cv2.INTER_AREA, as AtariPreprocessing
            "episodic_life": False,  # life-loss terminals are done here (EpisodicLife)
            "reward_clip": False,  # clipped here; statistics keep the raw rewards
            "use_fire_reset": False,  # AtariPreprocessing does not fire at reset
            "zero_discount_on_life_loss": False,
            "full_action_space": False,
            "repeat_action_probability": float(repeat_action_probability),
            "max_episode_steps": self.max_episode_steps,
        }
        self._seed = int(seed)
        self._pool: Any = None
        self._fresh = False  # the pool has not been stepped or reset since it was made
        n_actions = int(self._make_pool(self._seed).action_space.n)
        self.single_observation_space = gym.spaces.Box(
            0, 255, (frame_stack, screen_size, screen_size), dtype=np.uint8, seed=self._seed
        )
        self.single_action_space = gym.spaces.Discrete(n_actions, seed=self._seed)
        self.observation_space = gym.vector.utils.batch_space(
            self.single_observation_space, num_envs
        )
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, num_envs)
        self.action_space.seed(self._seed)
        e = num_envs
        self._stack = np.zeros((e, frame_stack, screen_size, screen_size), dtype=np.uint8)
        self._lives = np.zeros(e, dtype=np.int64)
        self._ep_return = np.zeros(e, dtype=np.float64)
        self._ep_length = np.zeros(e, dtype=np.int64)
        self._ep_start = np.zeros(e, dtype=np.float64)
        self._noop = np.zeros(e, dtype=np.int32)
        self._all = np.arange(e, dtype=np.int32)
        self._needs_reset = True
        self._pending: Future[Any] | None = None  # a step_async awaiting its step_wait
        self._worker: ThreadPoolExecutor | None = None  # made by the first step_async

    # ------------------------------------------------------------------ envpool
    def _make_pool(self, seed: int) -> Any:
        import envpool

        if self._pool is not None:
            self._pool.close()
        try:
            self._pool = envpool.make_gymnasium(self.task_id, seed=seed, **self._options)
        except Exception as exc:  # a bad option or task is a user-facing problem
            text = str(exc).strip().splitlines()
            raise EnvError(
                f"cannot make envpool task '{self.task_id}': "
                f"{text[0] if text else type(exc).__name__}"
            ) from None
        self._seed, self._fresh = seed, True
        return self._pool

    @staticmethod
    def _by_env(info: dict[str, Any], *arrays: np.ndarray) -> tuple[np.ndarray, ...]:
        """Arrays of an envpool result in the order of ``info["env_id"]`` sorted ascending."""
        order = np.argsort(info["env_id"], kind="stable")
        return tuple(np.asarray(a)[order] for a in arrays)

    def _restart(self, ids: np.ndarray) -> None:
        """New games on environments ``ids`` (sorted): zero-padded stacks, fresh statistics."""
        obs, info = self._pool.reset(ids)
        frames, lives = self._by_env(info, obs[:, -1], info["lives"])
        self._stack[ids] = 0
        self._stack[ids, -1] = frames
        self._lives[ids] = lives
        self._ep_return[ids] = 0.0
        self._ep_length[ids] = 0
        self._ep_start[ids] = time.perf_counter()

    # ------------------------------------------------------------------ VectorEnv
    def reset(
        self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """New games everywhere. envpool fixes seeds when it is made, so a seed (environment
        ``e`` gets ``seed + e``, as SyncVectorEnv) remakes the pool unless it is still fresh
        with that seed."""
        if self._pending is not None:  # finish the step in flight before a reset or remake
            self.step_wait()
        if seed is not None:
            base = int(seed[0]) if isinstance(seed, (list, tuple)) else int(seed)
            if not (self._fresh and base == self._seed):
                self._make_pool(base)
            self.single_action_space.seed(base)
            self.action_space.seed(base)
        self._fresh = False
        self._restart(self._all)
        self._needs_reset = False
        return self._stack.copy(), {
            "lives": self._lives.copy(),
            "_lives": np.ones_like(self._all, bool),
        }

    def step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        if self._pending is not None:
            raise RuntimeError("step called while a step_async awaits its step_wait")
        return self._step(self._actions(actions))

    def step_async(self, actions: Any) -> None:
        """Start a step on a worker thread and return: the games (and the no-op step of a new
        life, and the resets of ended games) run while the caller works, until
        :meth:`step_wait` collects the step (the training loop's ``overlap_env``). envpool's
        emulation runs without Python's lock; the bookkeeping here takes it briefly."""
        if self._pending is not None:
            raise RuntimeError("step_async called again before step_wait collected the last step")
        actions_E = self._actions(actions)
        if self._worker is None:
            self._worker = ThreadPoolExecutor(1, thread_name_prefix="envpool-step")
        self._pending = self._worker.submit(self._step, actions_E)

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """The step started by :meth:`step_async` (the contract of :meth:`step`)."""
        if self._pending is None:
            raise RuntimeError("step_wait called without a step_async before it")
        pending, self._pending = self._pending, None
        return pending.result()

    def _actions(self, actions: Any) -> np.ndarray:
        if self._needs_reset:
            raise gym.error.ResetNeeded("call reset() before step()")
        return np.asarray(actions, dtype=np.int32).reshape(self.num_envs)

    def _step(
        self, actions_E: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        self._fresh = False
        obs, _, _, trunc, info = self._pool.step(actions_E, self._all)
        frame, raw, game_over, trunc, lives = self._by_env(
            info, obs[:, -1], info["reward"], info["terminated"], trunc, info["lives"]
        )
        game_over = game_over.astype(bool)
        time_limit = trunc.astype(bool) & ~game_over
        raw = raw.astype(np.float64)  # envpool's info["reward"] is never clipped
        self._ep_return += raw
        self._ep_length += 1
        self._stack[:, :-1] = self._stack[:, 1:]
        self._stack[:, -1] = frame
        life_lost = (lives > 0) & (lives < self._lives)
        self._lives[:] = lives
        terminated = game_over | (life_lost if self.life_terminals else False)
        truncated = time_limit
        rewards = np.sign(raw) if self.clip_rewards else raw
        out: dict[str, Any] = {}
        ended = terminated | truncated
        if ended.any():
            out.update(self._end_episodes(np.flatnonzero(ended), game_over | time_limit))
        out["lives"], out["_lives"] = self._lives.copy(), np.ones(self.num_envs, bool)
        return self._stack.copy(), rewards, terminated, truncated, out

    def _end_episodes(self, ended: np.ndarray, game_ended: np.ndarray) -> dict[str, Any]:
        """Record the ended episodes' last observations and games' statistics, then start the
        next episode of each (a no-op step for a new life, else a new game) in this call."""
        e = self.num_envs
        final_obs = np.full(e, None, dtype=object)
        for i in ended:
            final_obs[i] = self._stack[i].copy()
        ended_mask = np.zeros(e, bool)
        ended_mask[ended] = True
        final_info: dict[str, Any] = {"lives": self._lives.copy(), "_lives": ended_mask.copy()}
        games = np.zeros(e, bool)
        games[ended] = game_ended[ended]
        lives_left = ended[~game_ended[ended]]
        if lives_left.size:  # EpisodicLife.reset: one no-op agent step, the game goes on
            obs, _, _, trunc, info = self._pool.step(self._noop[: lives_left.size], lives_left)
            frame, raw, over, trunc, lives = self._by_env(
                info, obs[:, -1], info["reward"], info["terminated"], trunc, info["lives"]
            )
            self._ep_return[lives_left] += raw
            self._ep_length[lives_left] += 1
            self._stack[lives_left] = 0
            self._stack[lives_left, -1] = frame
            self._lives[lives_left] = lives
            games[lives_left] = over.astype(bool) | trunc.astype(bool)
        if games.any():
            now = time.perf_counter()
            episode = {
                "r": np.where(games, self._ep_return, 0.0),
                "l": np.where(games, self._ep_length, 0),
                "t": np.where(games, np.round(now - self._ep_start, 6), 0.0),
            }
            for key in ("r", "l", "t"):
                episode[f"_{key}"] = games.copy()
            final_info["episode"], final_info["_episode"] = episode, games.copy()
            self._restart(np.flatnonzero(games).astype(np.int32))
        return {
            "final_obs": final_obs,
            "_final_obs": ended_mask,
            "final_info": final_info,
            "_final_info": ended_mask.copy(),
        }

    def close_extras(self, **kwargs: Any) -> None:
        if self._pending is not None:
            self.step_wait()
        if self._worker is not None:
            self._worker.shutdown()
            self._worker = None
        if self._pool is not None:
            self._pool.close()
            self._pool = None

    def __getstate__(self) -> dict[str, Any]:
        raise TypeError("envpool environments hold C++ state and cannot be pickled")


def make_envpool_atari(
    env_id: str,
    num_envs: int,
    seed: int,
    *,
    frame_skip: int,
    noop_max: int,
    screen_size: int,
    frame_stack: int,
    training: bool,
    terminal_on_life_loss: bool,
    clip_rewards: bool,
    repeat_action_probability: float,
    max_episode_steps: int | None = None,
    num_threads: int = 1,
) -> EnvpoolAtariVector:
    """Training (or evaluation, ``training=False``) Atari environments for an ALE id on envpool,
    with :func:`farsighter.envs.atari.wrap_atari`'s settings. ``num_threads`` is envpool's
    worker threads (1 steps the games one after another in one thread)."""
    if not envpool_available():
        raise EnvError(f"the envpool Atari backend needs envpool; {ENVPOOL_EXTRA}")
    return EnvpoolAtariVector(
        envpool_task_id(env_id),
        num_envs,
        seed,
        frame_skip=frame_skip,
        noop_max=noop_max,
        screen_size=screen_size,
        frame_stack=frame_stack,
        training=training,
        terminal_on_life_loss=terminal_on_life_loss,
        clip_rewards=clip_rewards,
        repeat_action_probability=repeat_action_probability,
        max_episode_steps=max_episode_steps,
        num_threads=num_threads,
    )
