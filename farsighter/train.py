"""The one training loop: any agent, any environment, resumable from its run directory."""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from farsighter.agents import Agent, build_agent
from farsighter.agents.cuda_graph import check_compiler, graphs_enabled
from farsighter.config import Config, load_config, validate
from farsighter.envs import check_spaces, frame_stack_of, make_env, make_vector_env
from farsighter.envs.video import check_video
from farsighter.errors import ConfigError, RunDirError
from farsighter.interrupt import interrupted, requested, stop_before_start
from farsighter.policy_file import load_policy_state
from farsighter.replay import VectorStep
from farsighter.rundir import (
    CONFIG_FILE,
    check_resume,
    check_same_run,
    load_checkpoint,
    prepare_run_dir,
)
from farsighter.runtime import prepare_process
from farsighter.session import (
    POLICY_FILE,
    BaseCallback,
    Callback,
    EvalResult,
    LoopState,
    RunLog,
    check_transition,
    evaluate_episodes,
    final_observations,
    nothing_to_resume,
    restore_run,
)
from farsighter.tracking import check_tracking

__all__ = [
    "BaseCallback",
    "Callback",
    "EvalResult",
    "Policy",
    "evaluate_episodes",
    "load_agent",
    "new_policy",
    "train",
]


def resolve_device(name: str) -> torch.device:
    """auto: CUDA when present, CPU otherwise."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name.startswith("cuda") and not torch.cuda.is_available():
        raise ConfigError(f"device '{name}' requested but CUDA is not available; use --device cpu")
    return torch.device(name)


def overlap_enabled(setting: str, envs: gym.vector.VectorEnv, device: torch.device) -> bool:
    """Whether the loop steps ``envs`` while it updates (``RuntimeConfig.overlap_env``): ``on`` when the
    environments can (``step_async`` / ``step_wait``; refused with ConfigError where they
    cannot), ``auto`` when they can and the device is CUDA, ``off`` never."""
    can = callable(getattr(envs, "step_async", None)) and callable(getattr(envs, "step_wait", None))
    if setting == "on" and not can:
        raise ConfigError(
            "overlap_env on needs environments that step asynchronously (the envpool Atari "
            f"backend); {type(envs).__name__} steps in the loop's thread; use auto or off"
        )
    return setting == "on" or (setting == "auto" and can and device.type == "cuda")


def random_features_note(width: int, obs_shape: tuple[int, ...], env: str) -> str | None:
    """What a run with ``width`` random features (``blr.random_features``) on observations of
    ``obs_shape`` should know, or None: images keep the learned features alone; a flat
    observation wider than the random layer can hold more distinct states (one-hot cells)
    than the layer has directions, and past that many visited states a new one no longer looks
    new to the posterior (docs/design.md, "Why a fixed random layer runs out at depth")."""
    if not width:
        return None
    if len(obs_shape) != 1:
        return (
            f"farsighter: blr.random_features applies to flat observations; {env}'s images "
            f"{obs_shape} keep the learned features alone"
        )
    if obs_shape[0] > width:
        return (
            f"farsighter: note: {env}'s observation has {obs_shape[0]} entries, more than the "
            f"{width} random features (blr.random_features, widened up to "
            "blr.random_features_max); once a run has visited about "
            f"{width} distinct states, new ones stop looking new to the posterior. A wider "
            "layer keeps them apart, at O(width^2) a step"
        )
    return None


def check_extras(cfg: Config) -> None:
    """The optional packages a run's flags need, refused in one line before the run directory is
    touched: moviepy for --capture-video, wandb for --track."""
    if cfg.runtime.capture_video:
        check_video("--capture-video")
    check_tracking(cfg)


def train(cfg: Config, callbacks: Sequence[Callback] = ()) -> dict[str, Any]:
    """Train ``cfg.algo`` on ``cfg.env``; returns the run's summary (also in summary.json).

    ``callbacks`` (:class:`Callback`) see every vector step's ``info`` and the agent, read-only
    by contract, and with an ``on_scalar`` hook every scalar written to TensorBoard. A
    resume to no more steps than were done changes nothing (:func:`nothing_to_resume`). Inside
    :func:`farsighter.interrupt.stop_on_signal`, SIGINT or SIGTERM ends the step, saves a
    checkpoint and raises :class:`~farsighter.errors.Interrupted`."""
    check_same_run(cfg)  # a resume as another algorithm or env: said so before validate
    validate(cfg)
    device = resolve_device(cfg.runtime.device)
    graphs_enabled(cfg.runtime.cuda_graph, device)  # cuda_graph on with no GPU: refused
    check_compiler(cfg.runtime.compile, device)  # compile on a CPU without a C++ compiler: refused
    check_extras(cfg)
    checkpoint = None
    if cfg.resume:
        check_resume(cfg)  # a flag a resume may not change: refused before the checkpoint is read
        checkpoint = load_checkpoint(cfg.resolved_run_dir)
        done = nothing_to_resume(cfg, checkpoint)
        if done is not None:
            return done
    envs: gym.vector.VectorEnv = make_vector_env(
        cfg, seed=cfg.seed
    )  # a bad id fails before the run dir is touched
    obs_space, act_space = envs.single_observation_space, envs.single_action_space
    check_spaces(cfg.algo, obs_space, act_space)
    obs_shape = tuple(obs_space.shape or ())
    width = cfg.blr.random_feature_width(int(np.prod(obs_shape)))
    note = random_features_note(width, obs_shape, cfg.env)
    if note:
        print(note, file=sys.stderr)
    overlap = overlap_enabled(cfg.runtime.overlap_env, envs, device)
    stop_before_start()  # Ctrl-C while the environments were made: the run directory untouched
    path = prepare_run_dir(cfg)
    prepare_process(cfg.runtime.torch_threads)
    agent = build_agent(cfg, obs_space, act_space, frame_stack=frame_stack_of(cfg), device=device)
    if checkpoint is not None:
        state, envs, obs = restore_run(path, cfg, agent, envs, checkpoint)
        checkpoint = None  # its replay is in the agent now: not held twice
    else:
        state, (obs, _) = LoopState(), envs.reset(seed=cfg.seed)
    async_envs: Any = envs  # with overlap: step_async / step_wait (overlap_enabled checked them)
    log = RunLog(path, cfg, state, resumed=cfg.resume, callbacks=callbacks)
    try:
        while state.global_step < cfg.total_steps:
            actions = agent.act(obs, state.global_step)
            prev_step, state.global_step = state.global_step, state.global_step + cfg.num_envs
            if overlap:  # the games step on their threads while the updates owed are made
                async_envs.step_async(actions)
                metrics = agent.learn(state.global_step)
                next_obs, rewards, terminated, truncated, info = async_envs.step_wait()
            else:
                next_obs, rewards, terminated, truncated, info = envs.step(actions)
            final_obs = final_observations(info, cfg.num_envs)
            check_transition(cfg.env, state.global_step, rewards, next_obs, final_obs)
            agent.observe(VectorStep(obs, actions, rewards, terminated, truncated, final_obs))
            obs = next_obs
            if not overlap:
                metrics = agent.learn(state.global_step)
            log.after_step(state, prev_step, info, metrics, agent, envs, obs, callbacks)
            if requested() and state.global_step < cfg.total_steps:  # SIGINT / SIGTERM
                log.checkpoint(state, agent, envs, obs)
                raise interrupted(state.global_step, str(path))
        log.finish(state, agent, envs, obs, callbacks)
    finally:
        log.close()
        envs.close()
    return log.summary(state)


class Policy:
    """A trained agent loaded from its run directory, for acting. ``observation_space``: what
    its environments (:meth:`make_env`) observe, when known."""

    def __init__(
        self, agent: Agent, cfg: Config, observation_space: gym.Space | None = None
    ) -> None:
        self.agent, self.config = agent, cfg
        self.observation_space = observation_space

    def act(self, obs: np.ndarray, deterministic: bool = True) -> np.ndarray:
        """Actions for a batch of observations: greedy under the learned Q / posterior mean, or
        with ``deterministic=False`` the agent's exploration as at the end of training (a
        Thompson draw from the posterior for the Bayesian agents, epsilon-greedy for DQN)."""
        step = max(self.config.total_steps, self.config.learning_starts)
        return self.agent.act(np.asarray(obs), step, explore=not deterministic)

    def make_env(
        self, seed: int = 0, training: bool = False, render_mode: str | None = None
    ) -> gym.Env:
        """An environment with the same preprocessing as training (evaluation flavour);
        ``render_mode`` (``rgb_array``, ``human``) is passed to ``gymnasium.make``."""
        return make_env(self.config, seed=seed, training=training, render_mode=render_mode)


def new_policy(cfg: Config, device: str = "cpu") -> Policy:
    """An agent of ``cfg`` as built before training (untrained), for acting."""
    env = make_env(cfg, seed=0)
    try:
        agent = build_agent(
            cfg,
            env.observation_space,
            env.action_space,
            frame_stack=frame_stack_of(cfg),
            device=resolve_device(device),
        )
    finally:
        env.close()
    return Policy(agent, cfg, env.observation_space)


def load_agent(run_dir: str | Path, device: str = "cpu") -> Policy:
    """Load a trained agent from a run directory: ``policy.pt`` (what acting needs:
    :mod:`farsighter.policy_file`), else the last checkpoint."""
    path = Path(run_dir)
    if not (path / CONFIG_FILE).exists():
        raise RunDirError(f"{path} holds no run (no {CONFIG_FILE})")
    policy = new_policy(load_config(path / CONFIG_FILE), device)
    if (path / POLICY_FILE).exists():
        state = torch.load(path / POLICY_FILE, map_location="cpu", weights_only=False)
        load_policy_state(policy.agent, state)
    else:
        policy.agent.load_state_dict(load_checkpoint(path)["agent"])
    return policy
