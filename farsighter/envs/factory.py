"""One environment factory for every agent: any Gymnasium id, Atari preprocessing for ALE ids,
MinAtar's planes and other (H, W, C) images channels-first, goal-conditioned (dict-observation)
robotics tasks flattened to vectors, and any other observation space Gymnasium can flatten
(Discrete as a one-hot vector, MultiDiscrete, MultiBinary, Tuple, Dict, Box grids) made a float32
vector."""

from __future__ import annotations

import contextlib
import importlib
import io
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import Any

import gymnasium as gym
import numpy as np

from farsighter import algorithms
from farsighter.config import Config, is_atari_id
from farsighter.config.fields import env_kwargs_dict
from farsighter.envs.bsuite_env import register_bsuite
from farsighter.envs.chain import register_chain
from farsighter.envs.deep_sea import register_deep_sea
from farsighter.envs.minatar import MinAtarChannelsFirst, is_minatar_id, register_minatar
from farsighter.envs.vector import LeanSyncVectorEnv
from farsighter.errors import EnvError

# Ids registered by gymnasium-robotics (imported lazily: it is an optional extra).
ROBOTICS_PREFIXES = (
    "Fetch",
    "HandManipulate",
    "HandReach",
    "AdroitHand",
    "AntMaze",
    "PointMaze",
    "FrankaKitchen",
)
MUJOCO_EXTRA = "install the MuJoCo extra: pip install 'farsighter[mujoco]'"


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


MINIGRID_PREFIXES = ("MiniGrid-", "BabyAI-")
MINIGRID_EXTRA = "install the exploration extra: pip install 'farsighter[explore]'"
BOX2D_EXTRA = "install the Box2D extra: pip install 'farsighter[box2d]'"


def _register_builtin(env_id: str) -> None:
    # Importing registers ``farsighter/BridgeMaze-v0`` and friends (idempotent); a chain id
    # ``farsighter/Chain<L>-v0``, a deep sea id or a bsuite id is registered when first named.
    importlib.import_module("farsighter.envs.maze")
    importlib.import_module("farsighter.envs.tabular")
    register_chain(env_id)
    register_deep_sea(env_id)
    register_bsuite(env_id)


def is_minigrid_id(env_id: str) -> bool:
    """MiniGrid and BabyAI ids (the ``minigrid`` package registers them on import)."""
    return env_id.split(":")[-1].startswith(MINIGRID_PREFIXES)


def _register_minigrid(env_id: str) -> None:
    if ":" in env_id or not is_minigrid_id(env_id) or env_id in gym.registry:
        return
    try:
        import minigrid  # noqa: F401  (importing registers its ids)
    except ImportError:
        raise EnvError(f"'{env_id}' is a MiniGrid task; {MINIGRID_EXTRA}") from None


def _register_robotics(env_id: str) -> None:
    """Register gymnasium-robotics' ids on first use of one of them."""
    name = env_id.split(":")[-1]
    if ":" in env_id or name in gym.registry or not name.startswith(ROBOTICS_PREFIXES):
        return
    try:
        # Its import prints a notice about Adroit reward versions to stderr; not ours to show.
        with contextlib.redirect_stderr(io.StringIO()):
            import gymnasium_robotics
    except ImportError:
        raise EnvError(f"'{env_id}' is a gymnasium-robotics task; {MUJOCO_EXTRA}") from None
    gym.register_envs(gymnasium_robotics)


def _cwd_importable(env_id: str) -> None:
    """For ``module:EnvId``: the current directory on ``sys.path`` (at its end, so it shadows
    nothing installed), as ``python -m farsighter`` has it, so that the ``farsighter`` console
    script finds a module beside the command too."""
    if ":" not in env_id:
        return
    cwd = os.getcwd()
    if cwd not in sys.path and "" not in sys.path:
        sys.path.append(cwd)


def _make_base(env_id: str, cfg: Config, render_mode: str | None) -> gym.Env:
    _cwd_importable(env_id)
    _register_builtin(env_id)
    _register_robotics(env_id)
    _register_minigrid(env_id)
    register_minatar(env_id)
    kwargs: dict[str, Any] = env_kwargs_dict(cfg.env_kwargs)
    if render_mode is not None:
        kwargs["render_mode"] = render_mode
    if is_atari_id(env_id):
        try:
            import ale_py

            gym.register_envs(ale_py)
        except ImportError:
            raise EnvError(
                f"'{env_id}' is an Atari id; install the Atari extra: pip install 'farsighter[atari]'"
            ) from None
        # The preprocessing wrapper skips frames itself, so the emulator must not.
        kwargs["frameskip"] = 1
        kwargs["repeat_action_probability"] = cfg.atari.repeat_action_probability
        kwargs["max_num_frames_per_episode"] = cfg.atari.max_frames_per_episode
    elif cfg.max_episode_steps:
        kwargs["max_episode_steps"] = cfg.max_episode_steps
    try:
        return gym.make(env_id, **kwargs)
    except gym.error.DependencyNotInstalled as exc:
        if "mujoco" in str(exc).lower():
            raise EnvError(f"'{env_id}' needs MuJoCo; {MUJOCO_EXTRA}") from None
        if "box2d" in str(exc).lower():  # Gymnasium's own advice builds box2d-py with swig
            raise EnvError(f"'{env_id}' needs Box2D; {BOX2D_EXTRA}") from None
        raise EnvError(f"cannot make environment '{env_id}': {_first_line(exc)}") from None
    except (gym.error.Error, ImportError, AttributeError) as exc:
        raise EnvError(
            f"cannot make environment '{env_id}': {_first_line(exc)} (accepted: any registered "
            "Gymnasium id such as CartPole-v1, ALE/Breakout-v5, MinAtar/Breakout-v1, "
            "farsighter/BridgeMaze-v0, or module:EnvId)"
        ) from None
    except Exception as exc:  # an environment constructor failing is a user-facing problem too
        given = f" with {' '.join(cfg.env_kwargs)}" if cfg.env_kwargs else ""
        why = _first_line(exc)
        if isinstance(exc, KeyError):  # str(KeyError('9x9')) is only "'9x9'"
            why = f"no entry {why}"
        raise EnvError(f"cannot make environment '{env_id}'{given}: {why}") from None


def make_env(
    cfg: Config, *, seed: int, training: bool = True, render_mode: str | None = None
) -> gym.Env:
    """A single environment with the preprocessing its id calls for."""
    env = _make_base(cfg.env, cfg, render_mode)
    if is_atari_id(cfg.env):
        env = _wrap_atari(env, cfg, training)
    else:
        if is_minigrid_id(cfg.env):
            env = MiniGridImage(env)
        if is_minatar_id(cfg.env):  # no Atari preprocessing, no frame stack (frame_stack_of: 1)
            env = MinAtarChannelsFirst(env)
        if is_goal_space(env.observation_space):
            env = FlattenGoalObservation(env, include_achieved=cfg.naf.her)
        elif flattenable(env.observation_space):
            env = FlatObservation(env)
        elif is_channels_last(env.observation_space):
            env = ChannelsFirst(env)
        env = gym.wrappers.RecordEpisodeStatistics(env)
    env.action_space.seed(seed)
    env.observation_space.seed(seed)
    return env


def make_eval_envs(
    cfg: Config, count: int, *, seed: int, render_mode: str | None = None
) -> list[gym.Env]:
    """``count`` evaluation environments, stepped as a batch by
    :func:`farsighter.session.evaluate_episodes`: each is ``make_env(training=False)`` (for ALE
    ids no life-loss terminals and unclipped rewards, always the Gymnasium wrappers), environment
    ``i`` with its spaces seeded ``seed + i``. Each episode reseeds its environment on reset.
    ``render_mode``: the first environment's (the one a video records)."""
    envs: list[gym.Env] = []
    try:
        for i in range(count):
            mode = render_mode if i == 0 else None
            envs.append(make_env(cfg, seed=seed + i, training=False, render_mode=mode))
    except BaseException:
        for env in envs:
            env.close()
        raise
    return envs


def _preprocessing(cfg: Config, training: bool) -> dict[str, Any]:
    """The Atari preprocessing settings both backends take (Gymnasium wrappers and envpool)."""
    a = cfg.atari
    return {
        "frame_skip": a.frame_skip,
        "noop_max": a.noop_max,
        "screen_size": a.screen_size,
        "frame_stack": a.frame_stack,
        "training": training,
        "terminal_on_life_loss": a.terminal_on_life_loss,
        "clip_rewards": a.clip_rewards,
    }


def _wrap_atari(env: gym.Env, cfg: Config, training: bool) -> gym.Env:
    from farsighter.envs.atari import wrap_atari

    return wrap_atari(env, **_preprocessing(cfg, training))


def make_vector_env(cfg: Config, *, seed: int) -> gym.vector.VectorEnv:
    """Training environments, stepped together; an ended episode resets in the same step and its
    last observation is in ``info["final_obs"]`` (needed to bootstrap after truncation). ALE
    games go through envpool when ``atari.backend`` says so (:mod:`farsighter.envs.envpool_vec`:
    the same preprocessing and step contract), everything else through Gymnasium's
    synchronous vector env."""

    # Build one first so that a bad id fails with our one-line error, not inside the vector env.
    make_env(cfg, seed=seed, training=True).close()
    if is_atari_id(cfg.env) and _use_envpool(cfg):
        from farsighter.envs.envpool_vec import make_envpool_atari

        a = cfg.atari
        return make_envpool_atari(
            cfg.env,
            cfg.num_envs,
            seed,
            **_preprocessing(cfg, training=True),
            repeat_action_probability=a.repeat_action_probability,
            max_episode_steps=a.max_frames_per_episode // a.frame_skip or 2**31 - 1,
            num_threads=a.envpool_threads,
        )
    return LeanSyncVectorEnv(
        # partials (not lambdas) keep the vector env picklable, so checkpoints can hold it.
        [partial(make_env, cfg, seed=seed + i, training=True) for i in range(cfg.num_envs)],
        autoreset_mode=gym.vector.AutoresetMode.SAME_STEP,
    )


def _use_envpool(cfg: Config) -> bool:
    """auto: envpool when installed, the game is there and noop_max >= 1; an explicit envpool
    that cannot serve the game fails with one line in :func:`make_envpool_atari`."""
    if cfg.atari.backend == "auto":
        if cfg.env_kwargs:  # constructor arguments are gymnasium.make's
            return False
        from farsighter.envs.envpool_vec import envpool_supports

        return envpool_supports(cfg.env, cfg.atari.noop_max)
    return cfg.atari.backend == "envpool"


# Spaces that are neither a flat vector nor an image but that the MLP torso can take flattened.
FLATTENED = (
    gym.spaces.Discrete,
    gym.spaces.MultiDiscrete,
    gym.spaces.MultiBinary,
    gym.spaces.Tuple,
    gym.spaces.Dict,
)


def flattenable(space: gym.Space) -> bool:
    """An observation space the torso takes once flattened by :class:`FlatObservation`: a
    discrete space (FrozenLake, Taxi, CliffWalking: the state index), a tuple or dict of spaces
    (Blackjack), or a Box that is neither a flat vector (D,) nor an image (C, H, W)."""
    if isinstance(space, gym.spaces.Box):
        return space.shape is not None and len(space.shape) not in (1, 3)
    if not isinstance(space, FLATTENED):
        return False
    try:  # a Sequence or Graph part has no fixed-size vector: flattened, it is no Box
        return isinstance(gym.spaces.flatten_space(space), gym.spaces.Box)
    except (NotImplementedError, TypeError, ValueError):
        return False


class FlatObservation(gym.ObservationWrapper):
    """Observations as float32 vectors through Gymnasium's own flattening
    (``gymnasium.spaces.flatten``): a Discrete(n) state i becomes the one-hot vector e_i of
    length n (so a tabular task gets a tabular network input), a MultiDiscrete one one-hot block
    per part, tuples and dicts their parts' vectors concatenated, a Box grid its cells in order.
    (Gymnasium's FlattenObservation does the same but holds a lambda, and a checkpoint pickles
    the environments.)"""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.original_space = env.observation_space
        flat = gym.spaces.flatten_space(env.observation_space)
        assert isinstance(flat, gym.spaces.Box)  # flattenable() checked it
        self.observation_space = gym.spaces.Box(
            flat.low.astype(np.float32), flat.high.astype(np.float32), dtype=np.float32
        )

    def observation(self, observation: Any) -> np.ndarray:
        flat = gym.spaces.flatten(self.original_space, observation)
        return np.asarray(flat, dtype=np.float32)


IMAGE_CHANNELS = (1, 3, 4)
"""Channel counts of an image: grey, RGB, RGBA (or four stacked grey frames)."""


def is_channels_last(space: gym.Space) -> bool:
    """A Box image in height-width-channel layout, (H, W, C) with C in :data:`IMAGE_CHANNELS`
    and H not (a (C, H, W) image the torsos take as it is would have its channels first)."""
    if not isinstance(space, gym.spaces.Box) or space.shape is None or len(space.shape) != 3:
        return False
    return space.shape[2] in IMAGE_CHANNELS and space.shape[0] not in IMAGE_CHANNELS


class ChannelsFirst(gym.ObservationWrapper):
    """An (H, W, C) image observation as (C, H, W), the layout of the image torsos (the Nature
    CNN, as for Atari frames)."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        space = env.observation_space
        assert isinstance(space, gym.spaces.Box)  # is_channels_last() checked it
        self.observation_space = gym.spaces.Box(
            np.transpose(space.low, (2, 0, 1)),
            np.transpose(space.high, (2, 0, 1)),
            dtype=space.dtype,
        )

    def observation(self, observation: Any) -> np.ndarray:
        return np.ascontiguousarray(np.transpose(observation, (2, 0, 1)))


class MiniGridImage(gym.ObservationWrapper):
    """A MiniGrid observation as its egocentric view only, flattened to float32 in [0, 1]: the
    (7, 7, 3) grid of object, colour and state indices, each divided by its largest value. The
    agent's direction is implicit in the view and the mission text is dropped (fixed per task
    in DoorKey, KeyCorridor and MultiRoom)."""

    # The largest object, colour and state indices of minigrid.core.constants.
    MAX_INDEX = np.array([10.0, 5.0, 2.0], dtype=np.float32)

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        image = env.observation_space["image"]  # type: ignore[index]
        self.observation_space = gym.spaces.Box(
            0.0, 1.0, (int(np.prod(image.shape)),), dtype=np.float32
        )

    def observation(self, observation: dict[str, Any]) -> np.ndarray:
        image = np.asarray(observation["image"], dtype=np.float32) / self.MAX_INDEX
        return image.ravel()


def is_goal_space(space: gym.Space) -> bool:
    """A goal-conditioned observation space (gymnasium-robotics' GoalEnv convention)."""
    return isinstance(space, gym.spaces.Dict) and {
        "observation",
        "achieved_goal",
        "desired_goal",
    } <= set(space.spaces)


class FlattenGoalObservation(gym.ObservationWrapper):
    """Dict observations of goal-conditioned tasks as one float32 vector (SPEC 2.2):
    ``[observation, desired_goal]``, or ``[observation, achieved_goal, desired_goal]`` with
    ``include_achieved`` (hindsight replay reads achieved goals back from stored rows)."""

    def __init__(self, env: gym.Env, include_achieved: bool = False) -> None:
        super().__init__(env)
        spaces = env.observation_space.spaces  # type: ignore[attr-defined]
        self.keys: tuple[str, ...] = (
            ("observation", "achieved_goal", "desired_goal")
            if include_achieved
            else ("observation", "desired_goal")
        )
        parts = [spaces[k] for k in self.keys]
        low = np.concatenate([np.broadcast_to(p.low, p.shape).ravel() for p in parts])
        high = np.concatenate([np.broadcast_to(p.high, p.shape).ravel() for p in parts])
        self.observation_space = gym.spaces.Box(
            low.astype(np.float32), high.astype(np.float32), dtype=np.float32
        )
        self.obs_dim = int(np.prod(spaces["observation"].shape))
        self.goal_dim = int(np.prod(spaces["desired_goal"].shape))

    def observation(self, observation: dict[str, Any]) -> np.ndarray:
        return np.concatenate(
            [np.asarray(observation[k], dtype=np.float32).ravel() for k in self.keys]
        )


@dataclass(frozen=True)
class GoalSpec:
    """Layout of a flattened goal observation ``[observation, achieved_goal, desired_goal]`` and
    the task's reward function, for hindsight relabelling."""

    obs_dim: int
    goal_dim: int
    compute_reward: Callable[[np.ndarray, np.ndarray, Any], np.ndarray]
    """``compute_reward(achieved_NG, desired_NG, None) -> reward_N`` of the unwrapped task."""

    @property
    def achieved(self) -> slice:
        return slice(self.obs_dim, self.obs_dim + self.goal_dim)

    @property
    def desired(self) -> slice:
        return slice(self.obs_dim + self.goal_dim, self.obs_dim + 2 * self.goal_dim)


def goal_spec(cfg: Config) -> GoalSpec:
    """The goal layout and reward function of ``cfg.env`` (which must be goal-conditioned)."""
    env = _make_base(cfg.env, cfg, None)
    if not is_goal_space(env.observation_space):
        env.close()
        raise EnvError(
            f"'{cfg.env}' has no goal-conditioned dict observations; naf.her needs one "
            "(accepted: gymnasium-robotics tasks such as FetchPickAndPlace-v4)"
        )
    spaces = env.observation_space.spaces  # type: ignore[attr-defined]
    # The bound method keeps this one environment alive for the agent's lifetime.
    return GoalSpec(
        obs_dim=int(np.prod(spaces["observation"].shape)),
        goal_dim=int(np.prod(spaces["desired_goal"].shape)),
        compute_reward=env.unwrapped.compute_reward,  # type: ignore[attr-defined]
    )


def frame_stack_of(cfg: Config) -> int:
    """Frames per observation that the replay should rebuild (1: store observations whole)."""
    return cfg.atari.frame_stack if is_atari_id(cfg.env) else 1


def check_spaces(algo: str, obs_space: gym.Space, act_space: gym.Space) -> None:
    """Raise a one-line EnvError when an algorithm cannot handle the spaces."""
    if algorithms.get(algo).actions == "continuous":
        if not isinstance(act_space, gym.spaces.Box) or len(act_space.shape) != 1:
            raise EnvError(
                f"algorithm '{algo}' needs a continuous (Box, 1-d) action space; this environment "
                f"has {act_space} (for discrete actions use "
                f"{algorithms.accepted(algorithms.names_for('discrete'))})"
            )
        if not (np.isfinite(act_space.low).all() and np.isfinite(act_space.high).all()):
            raise EnvError(
                f"algorithm '{algo}' needs finite action bounds (mu is tanh-scaled to them); "
                f"this environment has {act_space}"
            )
    elif not isinstance(act_space, gym.spaces.Discrete):
        raise EnvError(
            f"algorithm '{algo}' needs a discrete action space; this environment has {act_space} "
            f"(for continuous actions use {algorithms.accepted(algorithms.names_for('continuous'))})"
        )
    if not isinstance(obs_space, gym.spaces.Box):
        raise EnvError(
            f"observation space {obs_space} is not supported; accepted: Box observations (flat "
            "vectors or images) and spaces Gymnasium flattens to vectors (Discrete, MultiDiscrete, "
            "MultiBinary, and Tuple or Dict of them)"
        )
    if obs_space.shape is None or len(obs_space.shape) not in (1, 3):
        raise EnvError(
            f"observation shape {obs_space.shape} is not supported; accepted: flat vectors (D,) "
            "or stacked images (C, H, W)"
        )
