"""Shared fixtures: tiny configs that run in seconds on 2 cores."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import torch

from farsighter.config import Config, make_config

torch.set_num_threads(1)


class GrabAgent:
    """Training callback that keeps the trained agent (``on_finish``) for inspection."""

    agent: Any = None

    def on_step(self, global_step: int, info: dict[str, Any], agent: Any) -> None:
        pass

    def on_finish(self, run_dir: Path, agent: Any) -> None:
        self.agent = agent


def inner(agent: Any) -> Any:
    """The object that holds an agent's parts: the agent itself, or for an agent written over
    the seed axis (one seed alone, a ``Sole``; one seed of a batch, a member) the seed-axis
    agent (its replay, networks, loss and counters)."""
    return getattr(agent, "agents", None) or getattr(agent, "batch", None) or agent


def parts(agent: Any, s: int = 0) -> Any:
    """Seed ``s``'s own parts of a Farsighter or BDQN agent (alone: a ``Sole``; or the agent
    written over the seed axis itself, or a member: its own seed): its posterior ``head``,
    ``target_mean_AD``, ``counters``, ``exploration``, generators, ``calibrated``, ``blr``,
    ``k_target``, ``draws``."""
    own = getattr(agent, "parts", None)
    return own if own is not None and not isinstance(own, list) else inner(agent).parts[s]


def eq8(agent: Any, t: Any, draws: Any = None, cached: Any = None) -> Any:
    """Seed 0's y of Eq. 8 on the rows ``t`` (a TensorBatch) of a Farsighter agent of one seed,
    with its ``draws`` (``SeedParts.draws``'s names) and the cached target features of s'."""
    loss = inner(agent).loss
    inputs = {**t.tensors(), **{f"{k}@0": v for k, v in (draws or {}).items()}}
    if cached is not None:
        inputs["phi_next_target_BD"] = cached
    return loss.targets(t, inputs)[0]


def tiny(algo: str, run_dir: Path, env: str = "CartPole-v1", **kw: Any) -> Config:
    values: dict[str, Any] = dict(
        total_steps=1_500,
        learning_starts=200,
        buffer_size=5_000,
        batch_size=16,
        train_every=2,
        target_update_every=250,
        eps_decay_steps=1_000,
        eval_every=500,
        eval_episodes=2,
        eval_max_steps=200,
        checkpoint_every=500,
        log_every=250,
        hidden_sizes=(32, 32),
        progress=False,
        run_dir=str(run_dir),
        blr__posterior_every=400,
        blr__posterior_samples=500,
    )
    values.update(kw)
    preset = values.pop("preset", "control")
    return make_config(algo, env, preset=preset, **values)


@pytest.fixture
def tiny_config() -> Any:
    return tiny
