"""One environment factory for every agent: any Gymnasium id, Atari preprocessing for ALE ids."""

from __future__ import annotations

import importlib
from functools import partial
from typing import Any

import gymnasium as gym

from farsighter.config import Config, is_atari_id
from farsighter.errors import EnvError


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def _register_builtin() -> None:
    # Importing registers ``farsighter/BridgeMaze-v0`` and friends (idempotent).
    importlib.import_module("farsighter.envs.maze")


def _make_base(env_id: str, cfg: Config, render_mode: str | None) -> gym.Env:
    _register_builtin()
    kwargs: dict[str, Any] = {}
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
    try:
        return gym.make(env_id, **kwargs)
    except (gym.error.Error, ImportError, AttributeError) as exc:
        raise EnvError(
            f"cannot make environment '{env_id}': {_first_line(exc)} (accepted: any registered "
            "Gymnasium id such as CartPole-v1, ALE/Breakout-v5, farsighter/BridgeMaze-v0, or "
            "module:EnvId)"
        ) from None
    except Exception as exc:  # an environment constructor failing is a user-facing problem too
        raise EnvError(f"cannot make environment '{env_id}': {_first_line(exc)}") from None


def make_env(
    cfg: Config, *, seed: int, training: bool = True, render_mode: str | None = None
) -> gym.Env:
    """A single environment with the preprocessing its id calls for."""
    env = _make_base(cfg.env, cfg, render_mode)
    if is_atari_id(cfg.env):
        env = _wrap_atari(env, cfg, training)
    else:
        env = gym.wrappers.RecordEpisodeStatistics(env)
    env.action_space.seed(seed)
    env.observation_space.seed(seed)
    return env


def _wrap_atari(env: gym.Env, cfg: Config, training: bool) -> gym.Env:
    from farsighter.envs.atari import wrap_atari

    a = cfg.atari
    return wrap_atari(
        env,
        frame_skip=a.frame_skip,
        noop_max=a.noop_max,
        screen_size=a.screen_size,
        frame_stack=a.frame_stack,
        training=training,
        terminal_on_life_loss=a.terminal_on_life_loss,
        clip_rewards=a.clip_rewards,
    )


def make_vector_env(cfg: Config, *, seed: int) -> gym.vector.SyncVectorEnv:
    """Training environments, stepped together; an ended episode resets in the same step and its
    last observation is in ``info["final_obs"]`` (needed to bootstrap after truncation)."""

    # Build one first so that a bad id fails with our one-line error, not inside the vector env.
    make_env(cfg, seed=seed, training=True).close()
    return gym.vector.SyncVectorEnv(
        # partials (not lambdas) keep the vector env picklable, so checkpoints can hold it.
        [partial(make_env, cfg, seed=seed + i, training=True) for i in range(cfg.num_envs)],
        autoreset_mode=gym.vector.AutoresetMode.SAME_STEP,
    )


def frame_stack_of(cfg: Config) -> int:
    """Frames per observation that the replay should rebuild (1: store observations whole)."""
    return cfg.atari.frame_stack if is_atari_id(cfg.env) else 1


def check_spaces(algo: str, obs_space: gym.Space, act_space: gym.Space) -> None:
    """Raise a one-line EnvError when an algorithm cannot handle the spaces."""
    discrete_algos = {"ddqn", "kddqn", "bdqn", "farsighter", "ob2i", "rnd", "krnd"}
    if algo in discrete_algos and not isinstance(act_space, gym.spaces.Discrete):
        raise EnvError(
            f"algorithm '{algo}' needs a discrete action space; this environment has {act_space} "
            "(continuous agents naf, knaf, bnaf, farsighter-naf are planned)"
        )
    if not isinstance(obs_space, gym.spaces.Box):
        raise EnvError(
            f"observation space {obs_space} is not supported; accepted: Box observations (flat "
            "vectors or images)"
        )
    if obs_space.shape is None or len(obs_space.shape) not in (1, 3):
        raise EnvError(
            f"observation shape {obs_space.shape} is not supported; accepted: flat vectors (D,) "
            "or stacked images (C, H, W)"
        )
