"""Several seeds of one config in one process, as one batched computation.

``farsighter train --seeds 1 2 ... S`` trains S independent runs. Where the agent has a
seed-batched form (:data:`BATCHED`: DDQN and k-DDQN, Farsighter and BDQN, RND and k-RND) they
train together: one forward pass acts for every seed, one backward pass updates them all, and
the loop below steps each seed's own environments, replay and run log in turn. Elsewhere the
seeds train one after another through :func:`farsighter.train.train`. Either way each seed is
an ordinary run:

* its own run directory (``runs/<env>__<algo>__s<seed>``, or ``RUN_DIR/s<seed>`` under a given
  ``--run-dir``), with the files, checkpoints and summary a run alone writes;
* on CPU the same numbers as the run alone, bit for bit (``tests/test_seeds.py``);
* resumable alone or in a batch: a checkpoint has the layout of the run alone, and a batch
  resumes its seeds in groups that stopped at the same step (a kill between two seeds' saves
  leaves them at different steps; each group then continues from its own).

This module is the loop of :func:`farsighter.train.train` with a seed axis; what it does per step
and per seed (logging, evaluation, checkpoints) is :mod:`farsighter.session`'s, unchanged.
"""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from tqdm import tqdm

from farsighter.agents import ddqn_seeds, farsighter_seeds, rnd_seeds
from farsighter.config import Config, validate
from farsighter.envs import check_spaces, make_vector_env
from farsighter.errors import ConfigError
from farsighter.interrupt import interrupted, requested
from farsighter.replay import VectorStep
from farsighter.rundir import check_same_run, load_checkpoint, prepare_run_dir
from farsighter.runtime import prepare_process
from farsighter.session import (
    Callback,
    LoopState,
    RunLog,
    check_transition,
    final_observations,
    restore_run,
)
from farsighter.train import check_extras, resolve_device, train

__all__ = ["BATCHED", "batchable", "seed_configs", "train_seeds"]

BATCHED = {
    **{algo: ddqn_seeds for algo in ddqn_seeds.ALGOS},
    **{algo: farsighter_seeds for algo in farsighter_seeds.ALGOS},
    **{algo: rnd_seeds for algo in rnd_seeds.ALGOS},
}
"""The algorithms with a seed-batched form -> its module (``supports``, the batch class)."""


def seed_configs(cfg: Config, seeds: Sequence[int]) -> list[Config]:
    """``cfg`` once per seed, each with its own run directory: the default one of its seed, or
    ``cfg.run_dir/s<seed>`` when ``cfg.run_dir`` is given."""
    if not seeds:
        raise ConfigError("--seeds needs at least one seed")
    if len(set(seeds)) != len(seeds):
        raise ConfigError(f"--seeds lists a seed twice: {list(seeds)}; give each seed once")
    return [
        dataclasses.replace(
            cfg, seed=int(s), run_dir=str(Path(cfg.run_dir) / f"s{s}") if cfg.run_dir else ""
        )
        for s in seeds
    ]


def train_seeds(
    cfgs: Sequence[Config],
    callbacks: Sequence[Sequence[Callback]] | None = None,
    batched: bool = True,
) -> list[dict[str, Any]]:
    """Train each config (one per seed; :func:`seed_configs`) and return their summaries, in
    order. Seeds whose configs agree outside seed and run directory, that resume from the same
    point and whose agent allows it, train as one batch; the others (and all of them with
    ``batched=False``) train alone, one after another. ``callbacks[i]``: the callbacks of run
    ``i``, which see its steps and its agent as they would alone."""
    for cfg in cfgs:
        check_same_run(cfg)
        validate(cfg)
        check_extras(cfg)
    if len({cfg.seed for cfg in cfgs}) != len(cfgs):
        raise ConfigError("train_seeds takes each seed once")
    hooks = {cfg.seed: list(callbacks[i]) if callbacks else [] for i, cfg in enumerate(cfgs)}
    summaries: dict[int, dict[str, Any]] = {}
    for group in _groups(cfgs) if batched else [[c] for c in cfgs]:
        reason = (
            _batch_refusal(group[0], resolve_device(group[0].runtime.device))
            if len(group) > 1
            else ""
        )
        if reason:
            print(f"farsighter: {reason}; these {len(group)} seeds train in turn", file=sys.stderr)
        if reason or len(group) == 1:
            for cfg in group:
                summaries[cfg.seed] = train(cfg, callbacks=hooks[cfg.seed])
            continue
        device = resolve_device(group[0].runtime.device)
        for summary in _train_batch(group, [hooks[c.seed] for c in group], device):
            summaries[summary["seed"]] = summary
    return [summaries[cfg.seed] for cfg in cfgs]


def batchable(cfg: Config) -> bool:
    """Whether seeds of ``cfg`` train as one batch here (its agent has a seed-batched form for
    its spaces and settings)."""
    return not _batch_refusal(cfg, resolve_device(cfg.runtime.device))


def _groups(cfgs: Sequence[Config]) -> list[list[Config]]:
    """Seeds that can share a batch: the same config but for seed and run directory, starting
    from the same step with the same counters (a fresh start, or equal checkpoints)."""
    groups: dict[Any, list[Config]] = {}
    for cfg in cfgs:
        key = (dataclasses.replace(cfg, seed=0, run_dir=""), _start_point(cfg))
        groups.setdefault(key, []).append(cfg)
    return list(groups.values())


def _start_point(cfg: Config) -> Any:
    if not cfg.resume:
        return None
    checkpoint = load_checkpoint(cfg.resolved_run_dir)
    counters = checkpoint["agent"].get("counters", {})
    return checkpoint["loop"]["global_step"], tuple(sorted(counters.items()))


def _batch_refusal(cfg: Config, device: torch.device) -> str:
    if cfg.algo not in BATCHED:  # said without building an environment
        return f"{cfg.algo} trains its seeds one at a time (batched: {', '.join(BATCHED)})"
    probe = make_vector_env(cfg, seed=cfg.seed)
    try:
        check_spaces(cfg.algo, probe.single_observation_space, probe.single_action_space)
        return BATCHED[cfg.algo].supports(cfg, probe.single_observation_space, device)
    finally:
        probe.close()


@dataclasses.dataclass
class _Seed:
    """One seed's part of the loop: what ``train`` holds for a run alone."""

    cfg: Config
    path: Path
    envs: Any
    obs: Any
    state: LoopState
    log: RunLog
    callbacks: Sequence[Callback]


def _train_batch(
    cfgs: Sequence[Config], callbacks: Sequence[Sequence[Callback]], device: torch.device
) -> list[dict[str, Any]]:
    cfg = cfgs[0]
    envs = [make_vector_env(c, seed=c.seed) for c in cfgs]
    obs_space, act_space = envs[0].single_observation_space, envs[0].single_action_space
    assert isinstance(obs_space, gym.spaces.Box) and isinstance(act_space, gym.spaces.Discrete)
    paths = [prepare_run_dir(c) for c in cfgs]
    prepare_process(cfg.runtime.torch_threads)
    batch = BATCHED[cfg.algo].SeedBatch(cfgs, obs_space, act_space, device=device)
    members = [batch.member(s) for s in range(len(cfgs))]
    runs: list[_Seed] = []
    try:
        for c, path, env, member, hooks in zip(cfgs, paths, envs, members, callbacks, strict=True):
            if c.resume:
                state, env, obs = restore_run(path, c, member, env)
            else:
                state, (obs, _) = LoopState(), env.reset(seed=c.seed)
            quiet = dataclasses.replace(c, progress=False)  # one bar for the batch, below
            log = RunLog(path, quiet, state, resumed=c.resume, callbacks=hooks)
            runs.append(_Seed(c, path, env, obs, state, log, hooks))
    except BaseException:  # the logs opened so far (their W&B runs) closed as failed
        for run in runs:
            run.log.close()
        raise
    step = runs[0].state.global_step
    bar = tqdm(
        total=cfg.total_steps * len(runs),
        initial=step * len(runs),
        unit="step",
        disable=not cfg.progress,
        dynamic_ncols=True,
        mininterval=1.0,
        desc=f"{cfg.algo} {cfg.env} {len(runs)} seeds",
    )
    try:
        while step < cfg.total_steps:
            actions_SE = batch.act(np.stack([run.obs for run in runs]), step)
            prev, step = step, step + cfg.num_envs
            infos, vector_steps = [], []
            for run, actions in zip(runs, actions_SE, strict=True):
                next_obs, rewards, terminated, truncated, info = run.envs.step(actions)
                final = final_observations(info, cfg.num_envs)
                check_transition(run.cfg.env, step, rewards, next_obs, final)
                vector_steps.append(
                    VectorStep(run.obs, actions, rewards, terminated, truncated, final)
                )
                run.obs = next_obs
                infos.append(info)
            batch.observe(vector_steps)
            metrics = batch.learn(step)
            for run, member, info, mine in zip(runs, members, infos, metrics, strict=True):
                run.state.global_step = step
                run.log.after_step(
                    run.state, prev, info, mine, member, run.envs, run.obs, run.callbacks
                )
            bar.update(cfg.num_envs * len(runs))
            if requested() and step < cfg.total_steps:  # SIGINT / SIGTERM: every seed saved
                for run, member in zip(runs, members, strict=True):
                    run.log.checkpoint(run.state, member, run.envs, run.obs)
                raise interrupted(step, ", ".join(str(run.path) for run in runs))
        for run, member in zip(runs, members, strict=True):
            run.log.finish(run.state, member, run.envs, run.obs, run.callbacks)
        return [run.log.summary(run.state) for run in runs]
    finally:
        bar.close()
        for run in runs:
            run.log.close()
            run.envs.close()
