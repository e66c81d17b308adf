"""Several seeds of one config in one process.

``farsighter train --seeds 1 2 ... S`` trains S independent runs in one loop
(:func:`farsighter.train.run_seeds`). Where the agent is written over a seed axis
(``Algorithm.seed_batch`` in :mod:`farsighter.algorithms`: DDQN and k-DDQN, Farsighter and BDQN,
RND and k-RND) and its settings stack, they are one computation: one forward pass acts for every
seed, one backward pass updates them all. Elsewhere (OB2I, NAF, bf16, compile, CUDA graphs,
adaptive k) the loop steps one agent per seed together (:class:`farsighter.agents.protocol.Each`);
seeds on image observations, whose replays are GBs, and such seeds resumed, train one after
another through :func:`farsighter.train.train`. Either way each seed is an ordinary run:

* its own run directory (``runs/<env>__<algo>__s<seed>``, or ``RUN_DIR/s<seed>`` under a given
  ``--run-dir``), with the files, checkpoints and summary a run alone writes;
* on CPU the same numbers as the run alone, bit for bit (``tests/training/test_seeds.py``);
* resumable alone or in a batch: a checkpoint has the layout of the run alone, and a batch
  resumes its seeds in groups that stopped at the same step (a kill between two seeds' saves
  leaves them at different steps; each group then continues from its own).

This module groups the seeds; what the loop does per step and per seed (logging, evaluation,
checkpoints) is :mod:`farsighter.session`'s.
"""

from __future__ import annotations

import dataclasses
import importlib
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import torch

from farsighter import algorithms
from farsighter.agents.cuda_graph import check_compiler, graphs_enabled
from farsighter.config import Config, validate
from farsighter.envs import check_spaces, make_vector_env
from farsighter.errors import ConfigError
from farsighter.rundir import check_same_run, load_checkpoint
from farsighter.session import Callback
from farsighter.train import check_extras, resolve_device, run_seeds, train

__all__ = ["batchable", "seed_configs", "train_seeds"]


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
        device = resolve_device(group[0].runtime.device)
        reason, images = _batch_refusal(group[0], device) if len(group) > 1 else ("", False)
        if len(group) == 1 or (reason and (images or group[0].resume)):
            if reason:  # an image replay is GBs: one in memory at a time
                why = "image replays" if images else "a resume"
                print(
                    f"farsighter: {reason}; these {len(group)} seeds train in turn ({why})",
                    file=sys.stderr,
                )
            for cfg in group:
                summaries[cfg.seed] = train(cfg, callbacks=hooks[cfg.seed])
            continue
        if reason:  # one agent per seed, stepped together by the one loop
            print(
                f"farsighter: {reason}; these {len(group)} seeds step together, each its own agent",
                file=sys.stderr,
            )
            graphs_enabled(group[0].runtime.cuda_graph, device)  # refused as train refuses
            check_compiler(group[0].runtime.compile, device)
        for summary in run_seeds(group, [hooks[c.seed] for c in group], device):
            summaries[summary["seed"]] = summary
    return [summaries[cfg.seed] for cfg in cfgs]


def batchable(cfg: Config) -> bool:
    """Whether seeds of ``cfg`` train as one batch here (its agent has a seed-batched form for
    its spaces and settings)."""
    return not _batch_refusal(cfg, resolve_device(cfg.runtime.device))[0]


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


def _batch_refusal(cfg: Config, device: torch.device) -> tuple[str, bool]:
    """Why seeds of ``cfg`` cannot share one computation here ('' when they can), and whether
    its observations are images."""
    probe = make_vector_env(cfg, seed=cfg.seed)
    try:
        space = probe.single_observation_space
        check_spaces(cfg.algo, space, probe.single_action_space)
        images = len(space.shape or ()) == 3
        module = algorithms.get(cfg.algo).seed_batch
        if not module:
            batched = ", ".join(algorithms.seed_batched())
            return f"{cfg.algo} has no seed-axis form (batched: {batched})", images
        batch = importlib.import_module(f"farsighter.agents.{module}")
        return str(batch.supports(cfg, space, device)), images
    finally:
        probe.close()
