"""Evaluation of a run's agent: greedy episodes on the evaluation environments, run as a batch
(re-exported by :mod:`farsighter.session`, whose :class:`~farsighter.session.RunLog` logs them)."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from tqdm import tqdm

from farsighter.agents import Agent
from farsighter.config import Config


@dataclass
class EvalResult:
    """Returns of the evaluation episodes, and ``info["is_success"]`` at each episode's end
    (goal-conditioned tasks; empty when the environment does not report it)."""

    returns: list[float]
    successes: list[float]


EVAL_MAX_ENVS = 32
"""Most environments an evaluation steps at once; more episodes run in turn through them (the
returns do not depend on how many run at once)."""


@dataclass
class _Running:
    """An evaluation episode in progress in one environment of the batch."""

    episode: int
    obs: Any
    rng: np.random.Generator
    total: float = 0.0
    steps: int = 0


def eval_step_cap(cfg: Config) -> int:
    """Most steps of one evaluation episode: ``eval_max_steps`` (27,000 under the Atari protocol)
    for a run at least that long. A shorter run is no protocol run, and its evaluations play at
    most as many steps as it trains: each episode is capped at total_steps // eval_episodes
    (a barely trained Atari policy that never presses FIRE would otherwise play every episode
    to the protocol's cap, minutes for a run of seconds)."""
    if cfg.total_steps >= cfg.eval_max_steps:
        return cfg.eval_max_steps
    return max(1, cfg.total_steps // cfg.eval_episodes)


def evaluate_episodes(
    agent: Agent,
    cfg: Config,
    envs: Sequence[gym.Env],
    episodes: int,
    seed: int,
    global_step: int,
    progress: bool = False,
) -> EvalResult:
    """``episodes`` greedy episodes (eval_epsilon-greedy for discrete actions; the posterior mean
    / noiseless mu for continuous ones) on evaluation environments (unclipped rewards, no
    life-loss terminals: :func:`farsighter.envs.make_eval_envs`), run as a batch: up to
    ``len(envs)`` at once with one forward pass over the running ones per step, each environment
    taking the next episode when its own ends (terminated, truncated, or after
    :func:`eval_step_cap` steps).

    Episode ``i`` starts from ``reset(seed=seed + i)`` and draws its eval_epsilon coins (one per
    step, and the random action when it comes up) from its own ``default_rng(seed + i)``; so
    episode 0 is the one the earlier, sequential evaluation ran first, and no episode depends
    on the batch's width or on the other episodes: for a deterministic greedy policy each returns
    what it returns stepped alone. (The sequential evaluation let episodes 1, 2, ... continue its
    one environment's generators; environments side by side cannot share them, and seeding them
    alike would give every episode of a stochastic task the same noise.) The agent's generators
    are not touched (``act(explore=False)`` draws nothing). Returns (and ``info["is_success"]``
    at each end, where reported) are listed in episode order. ``progress``: a bar of the
    finished episodes, with the steps of the longest running one."""
    if not envs:
        raise ValueError("evaluate_episodes needs at least one environment")
    cap = eval_step_cap(cfg)
    space = envs[0].action_space
    n_actions = int(space.n) if isinstance(space, gym.spaces.Discrete) else 0
    returns = [0.0] * episodes
    success_of: list[float | None] = [None] * episodes
    running: dict[int, _Running] = {}  # environment index -> its episode
    queued = iter(range(episodes))

    def start(slot: int) -> None:
        i = next(queued, None)
        if i is not None:
            obs, _ = envs[slot].reset(seed=seed + i)
            running[slot] = _Running(i, obs, np.random.default_rng(seed + i))

    for slot in range(min(len(envs), episodes)):
        start(slot)
    bar = tqdm(
        total=episodes,
        unit="episode",
        desc=f"eval at step {global_step}",
        disable=not progress,
        leave=False,
        dynamic_ncols=True,
    )
    shown = time.perf_counter()
    try:
        while running:
            slots = sorted(running)
            obs_E = np.stack([np.asarray(running[slot].obs) for slot in slots])
            actions_E = agent.act(obs_E, global_step, explore=False)
            for slot, action in zip(slots, actions_E, strict=True):
                run = running[slot]
                if n_actions and run.rng.random() < cfg.eval_epsilon:
                    action = int(run.rng.integers(n_actions))
                run.obs, reward, terminated, truncated, info = envs[slot].step(action)
                run.total += float(reward)
                run.steps += 1
                if terminated or truncated or run.steps >= cap:
                    returns[run.episode] = run.total
                    if "is_success" in info:
                        success_of[run.episode] = float(info["is_success"])
                    del running[slot]
                    bar.update(1)
                    start(slot)
            if progress and running and time.perf_counter() - shown >= 1.0:
                longest = max(run.steps for run in running.values())
                bar.set_postfix_str(f"step {longest:,} of at most {cap:,}")
                shown = time.perf_counter()
    finally:
        bar.close()
    return EvalResult(returns, [s for s in success_of if s is not None])
