"""The one training loop: any agent, any environment, one seed or several in one process,
resumable from its run directories (:func:`run_seeds`; :func:`train` for a run alone,
:func:`farsighter.seeds.train_seeds` for seeds)."""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from tqdm import tqdm

from farsighter.agents import Agent, SeedAgents, build_agent, build_seed_agents
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
    checkpoints, checkpoint = [checkpoint], None  # run_seeds lets go of it once loaded
    return run_seeds([cfg], [callbacks], device, checkpoints)[0]


@dataclass
class _Seed:
    """One seed's part of the loop: its environments, observation, counters and run log."""

    cfg: Config
    path: Path
    envs: Any
    obs: Any
    state: LoopState
    log: RunLog
    callbacks: Sequence[Callback]
    agent: Agent
    """The seed as an agent (the seed-axis agents' member): what its log and callbacks see."""


def run_seeds(
    cfgs: Sequence[Config],
    callbacks: Sequence[Sequence[Callback]],
    device: torch.device,
    checkpoints: list[dict[str, Any] | None] | None = None,
) -> list[dict[str, Any]]:
    """The one training loop: S seeds of one config (``cfgs``, checked; S = 1 for a run alone)
    step their own environments, and their agents (:func:`build_seed_agents`) act, record and
    learn together; each seed keeps its own run directory, log, checkpoints and summary.
    ``checkpoints[i]``: seed i's checkpoint when a resume has read it already (emptied once it
    is loaded, so that its replay is not held twice)."""
    cfg, S = cfgs[0], len(cfgs)
    agents, runs, overlap = _start(cfgs, callbacks, device, checkpoints)
    step = runs[0].state.global_step
    bar = tqdm(
        total=cfg.total_steps * S,
        initial=step * S,
        unit="step",
        disable=not cfg.progress or S == 1,
        dynamic_ncols=True,
        mininterval=1.0,
        desc=f"{cfg.algo} {cfg.env} {S} seeds",
    )
    try:
        while step < cfg.total_steps:
            actions_S = agents.act([run.obs for run in runs], step)
            prev, step = step, step + cfg.num_envs
            if overlap:  # the games step on their threads while the updates owed are made
                for run, actions in zip(runs, actions_S, strict=True):
                    run.envs.step_async(actions)
                metrics = agents.learn(step)
                results = [run.envs.step_wait() for run in runs]
            else:
                results = [run.envs.step(a) for run, a in zip(runs, actions_S, strict=True)]
            infos, steps = [], []
            for run, actions, result in zip(runs, actions_S, results, strict=True):
                next_obs, rewards, terminated, truncated, info = result
                final = final_observations(info, cfg.num_envs)
                check_transition(run.cfg.env, step, rewards, next_obs, final)
                steps.append(VectorStep(run.obs, actions, rewards, terminated, truncated, final))
                run.obs = next_obs
                infos.append(info)
            agents.observe(steps)
            if not overlap:
                metrics = agents.learn(step)
            for run, info, mine in zip(runs, infos, metrics, strict=True):
                run.state.global_step = step
                run.log.after_step(
                    run.state, prev, info, mine, run.agent, run.envs, run.obs, run.callbacks
                )
            bar.update(cfg.num_envs * S)
            if requested() and step < cfg.total_steps:  # SIGINT / SIGTERM: every seed saved
                for run in runs:
                    run.log.checkpoint(run.state, run.agent, run.envs, run.obs)
                raise interrupted(step, ", ".join(str(run.path) for run in runs))
        for run in runs:
            run.log.finish(run.state, run.agent, run.envs, run.obs, run.callbacks)
        return [run.log.summary(run.state) for run in runs]
    finally:
        bar.close()
        for run in runs:
            run.log.close()
            run.envs.close()


def _start(
    cfgs: Sequence[Config],
    callbacks: Sequence[Sequence[Callback]],
    device: torch.device,
    checkpoints: list[dict[str, Any] | None] | None,
) -> tuple[SeedAgents, list[_Seed], bool]:
    """:func:`run_seeds`' start: the seeds' environments (checked before a run directory is
    touched), run directories, agents, restored checkpoints and run logs; whether the loop
    steps the environments while it learns (:func:`overlap_enabled`)."""
    cfg, S = cfgs[0], len(cfgs)
    envs: list[gym.vector.VectorEnv] = []
    runs: list[_Seed] = []
    try:
        for c in cfgs:  # a bad id fails before a run directory is touched
            envs.append(make_vector_env(c, seed=c.seed))
            check_spaces(c.algo, envs[-1].single_observation_space, envs[-1].single_action_space)
        obs_space, act_space = envs[0].single_observation_space, envs[0].single_action_space
        obs_shape = tuple(obs_space.shape or ())
        note = random_features_note(
            cfg.blr.random_feature_width(int(np.prod(obs_shape))), obs_shape, cfg.env
        )
        if note:
            print(note, file=sys.stderr)
        overlap = overlap_enabled(cfg.runtime.overlap_env, envs[0], device)
        stop_before_start()  # Ctrl-C while the environments were made: run directories untouched
        paths = [prepare_run_dir(c) for c in cfgs]
        prepare_process(cfg.runtime.torch_threads)
        agents = build_seed_agents(
            cfgs, obs_space, act_space, frame_stack=frame_stack_of(cfg), device=device
        )
        for s, (c, path, hooks) in enumerate(zip(cfgs, paths, callbacks, strict=True)):
            member = agents.member(s)
            if c.resume:
                saved = checkpoints[s] if checkpoints else None
                if checkpoints:
                    checkpoints[s] = None
                state, envs[s], obs = restore_run(path, c, member, envs[s], saved)
                saved = None
            else:
                state, (obs, _) = LoopState(), envs[s].reset(seed=c.seed)
            # one progress bar: the run's own, or the batch's below
            log = RunLog(path, c if S == 1 else replace(c, progress=False), state, c.resume, hooks)
            runs.append(_Seed(c, path, envs[s], obs, state, log, hooks, member))
    except BaseException:  # what was opened so far (the logs' W&B runs end as failed)
        for run in runs:
            run.log.close()
        for env in envs:
            env.close()
        raise
    return agents, runs, overlap


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
