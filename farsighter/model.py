"""A model object in the shape of Stable-Baselines3's, over :func:`~farsighter.config.make_config`,
:func:`~farsighter.train.train` and :func:`~farsighter.train.load_agent` (no loop of its own):

>>> import farsighter
>>> model = farsighter.make("farsighter", "CartPole-v1", preset="cartpole")
>>> model.learn(20_000)                       # doctest: +SKIP
>>> action = model.predict(obs)               # doctest: +SKIP
>>> model.save("cartpole-model")              # doctest: +SKIP
>>> model = farsighter.Model.load("cartpole-model")  # doctest: +SKIP

``farsighter.Farsighter("CartPole-v1")`` is ``make("farsighter", "CartPole-v1")``, and so for every
algorithm (:data:`MODELS`). A model trains in a run directory like any run (``run_dir=`` to name
it; else the first free one of ``runs/<env>__<algo>__s<seed>``, ``-2``, ``-3``, ...), and a
second :meth:`Model.learn` continues it there (a resume). A saved model is the acting part of a
run directory: ``config.json`` and ``policy.pt`` (and ``summary.json``); a run directory loads
as a model too.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
import torch

from farsighter import algorithms
from farsighter.config import Config, load_config, make_config, save_config, validate
from farsighter.config.field_types import field_value
from farsighter.errors import ConfigError, EnvError, RunDirError
from farsighter.policy_file import policy_state
from farsighter.rundir import CHECKPOINT_FILE, CONFIG_FILE, SUMMARY_FILE
from farsighter.session import POLICY_FILE
from farsighter.train import Policy, load_agent, new_policy, train

__all__ = ["MODELS", "Model", "make"]


class Model:
    """An agent of ``algo`` for ``env`` (an id, or an environment made by ``gymnasium.make``):
    ``overrides`` are :func:`~farsighter.config.make_config`'s (``preset=``, ``seed=``,
    ``lr=``, ``blr__prior_std=``, ``device=``, ...)."""

    ALGO: ClassVar[str] = ""
    """The algorithm a subclass fixes ("" for any)."""

    def __init__(self, algo: str, env: str | gym.Env[Any, Any], **overrides: Any) -> None:
        if self.ALGO and algo != self.ALGO:
            raise ConfigError(f"{type(self).__name__} trains {self.ALGO}, not {algo}")
        cfg = make_config(algo, env, **overrides)
        validate(cfg)  # a bad value is said now, not at learn()
        self.config: Config = cfg
        self.run_dir: Path | None = None
        """Where the model trained (None before :meth:`learn`)."""
        self.num_steps = 0
        """Environment steps trained so far."""
        self.summary: dict[str, Any] | None = None
        """The latest run's summary (summary.json)."""
        self._policy: Policy | None = None

    def __repr__(self) -> str:
        where = f", run_dir={str(self.run_dir)!r}" if self.run_dir else ""
        return (
            f"{type(self).__name__}(algo={self.config.algo!r}, env={self.config.env!r}, "
            f"num_steps={self.num_steps}{where})"
        )

    # ------------------------------------------------------------------ training
    def learn(self, total_steps: int | float, progress: bool = True) -> Model:
        """Train for ``total_steps`` more environment steps (the first call from scratch, each
        later one resuming the run where it stopped); returns the model."""
        value, want = field_value("total_steps", total_steps)  # learn(1e5) is learn(100000)
        if want or value < 1:
            raise ConfigError(f"total_steps must be an integer >= 1 (got {total_steps!r})")
        steps: int = value
        if self.num_steps == 0:
            path = self._fresh_run_dir()
            cfg = dataclasses.replace(
                self.config, total_steps=steps, progress=progress, run_dir=str(path)
            )
        else:
            path = self._resumable_run_dir()
            cfg = dataclasses.replace(
                self.config,
                total_steps=self.num_steps + steps,
                progress=progress,
                run_dir=str(path),
                resume=True,
                overwrite=False,
            )
        self.summary = train(cfg)
        self.run_dir, self.num_steps = path, int(self.summary["global_step"])
        self.config = dataclasses.replace(load_config(path / CONFIG_FILE), resume=False)
        self._policy = load_agent(path)
        return self

    def _fresh_run_dir(self) -> Path:
        if self.config.run_dir:  # named by the caller: never replaced unless overwrite=True
            return Path(self.config.run_dir)
        base = self.config.default_run_dir()
        path, n = base, 1
        while path.exists():
            n += 1
            path = base.with_name(f"{base.name}-{n}")
        return path

    def _resumable_run_dir(self) -> Path:
        if self.run_dir is None or not (self.run_dir / CHECKPOINT_FILE).is_file():
            raise RunDirError(
                f"this model was loaded from {self.run_dir}, which holds its policy without a "
                f"checkpoint ({CHECKPOINT_FILE}); to train on, load the run directory it was "
                "trained in"
            )
        return self.run_dir

    # ------------------------------------------------------------------ acting
    @property
    def policy(self) -> Policy:
        """The agent that acts (before :meth:`learn`: as built, untrained)."""
        if self._policy is None:
            self._policy = new_policy(self.config)
        return self._policy

    def predict(self, obs: Any, deterministic: bool = True) -> Any:
        """The action for one observation, or an array of actions for a batch of them, as the
        environments of :meth:`make_env` give them. ``deterministic``: greedy under the learned
        Q / posterior mean; False: the agent's exploration (a Thompson draw from the posterior
        for the Bayesian agents). Unlike Stable-Baselines3 no recurrent state is returned."""
        policy = self.policy
        batch = np.asarray(obs)
        shape = None if policy.observation_space is None else policy.observation_space.shape
        if shape is None or batch.shape[1:] == shape:
            return policy.act(batch, deterministic)
        if batch.shape == shape:
            return policy.act(batch[None], deterministic)[0]
        raise EnvError(
            f"predict takes one observation of shape {shape} or a batch (N, "
            f"{', '.join(map(str, shape))}); got shape {batch.shape} (observations as "
            "model.make_env() gives them)"
        )

    def make_env(self, seed: int = 0, render_mode: str | None = None) -> gym.Env:
        """An environment with the preprocessing the model acts on (evaluation flavour);
        ``render_mode``: ``rgb_array`` or ``human``."""
        return self.policy.make_env(seed=seed, render_mode=render_mode)

    # ------------------------------------------------------------------ files
    def save(self, path: str | Path) -> Path:
        """Write the model to the directory ``path``: ``config.json`` and ``policy.pt`` (what
        acting needs: :mod:`farsighter.policy_file`), and ``summary.json`` once trained.
        Returns the directory."""
        out = Path(path)
        if self.run_dir is not None and out.resolve() == self.run_dir.resolve():
            return out  # the run directory holds them already
        if out.exists() and not out.is_dir():
            raise RunDirError(f"cannot save the model to {out}: a file of that name exists")
        if (out / CHECKPOINT_FILE).exists():
            raise RunDirError(
                f"cannot save the model to {out}: it holds another run ({CHECKPOINT_FILE}); "
                "choose a new directory"
            )
        try:
            out.mkdir(parents=True, exist_ok=True)
            save_config(self.config, out / CONFIG_FILE)
            torch.save(policy_state(self.policy.agent, self.config.algo), out / POLICY_FILE)
            if self.run_dir is not None and (self.run_dir / SUMMARY_FILE).is_file():
                shutil.copyfile(self.run_dir / SUMMARY_FILE, out / SUMMARY_FILE)
        except OSError as exc:
            raise RunDirError(f"cannot save the model to {out}: {exc.strerror or exc}") from None
        return out

    @classmethod
    def load(cls, path: str | Path, device: str = "cpu") -> Model:
        """A model saved by :meth:`save`, or the run directory of any run. One with a checkpoint
        (a run directory) trains on with :meth:`learn`."""
        policy = load_agent(path, device=device)
        algo = policy.config.algo
        if cls.ALGO and algo != cls.ALGO:
            raise ConfigError(
                f"{path} holds a {algo} model; load it with farsighter.Model.load or "
                f"farsighter.{MODELS[algo].__name__}.load"
            )
        kind = cls if cls.ALGO else MODELS[algo]
        model = kind.__new__(kind)
        model.config = policy.config
        model.run_dir, model._policy = Path(path), policy
        model.summary = _read_summary(Path(path))
        model.num_steps = int((model.summary or {}).get("global_step", 0))
        return model


def _read_summary(path: Path) -> dict[str, Any] | None:
    try:
        summary = json.loads((path / SUMMARY_FILE).read_text())
    except (OSError, ValueError):
        return None
    return summary if isinstance(summary, dict) else None


class _OneAlgorithm(Model):
    """A model of the algorithm the subclass names."""

    def __init__(self, env: str | gym.Env[Any, Any], **overrides: Any) -> None:
        super().__init__(self.ALGO, env, **overrides)


class DDQN(_OneAlgorithm):
    """Double DQN with epsilon-greedy exploration."""

    ALGO = "ddqn"


class KDDQN(_OneAlgorithm):
    """Double DQN with k-step returns."""

    ALGO = "kddqn"


class BDQN(_OneAlgorithm):
    """Thompson sampling on a Bayesian linear regression Q-head, 1-step."""

    ALGO = "bdqn"


class Farsighter(_OneAlgorithm):
    """Thompson draws over k-step returns from recent transitions (Algorithms 1-2)."""

    ALGO = "farsighter"


class OB2I(_OneAlgorithm):
    """Bootstrapped heads with a UCB bonus and episodic backward update."""

    ALGO = "ob2i"


class RND(_OneAlgorithm):
    """Double DQN with a random-network-distillation bonus."""

    ALGO = "rnd"


class KRND(_OneAlgorithm):
    """RND with k-step returns."""

    ALGO = "krnd"


class NAF(_OneAlgorithm):
    """Normalized advantage functions with action noise."""

    ALGO = "naf"


class KNAF(_OneAlgorithm):
    """NAF with k-step returns."""

    ALGO = "knaf"


class BNAF(_OneAlgorithm):
    """NAF with a Bayesian mu-layer sampled every step."""

    ALGO = "bnaf"


class FarsighterNAF(_OneAlgorithm):
    """Bayesian NAF with k-step returns."""

    ALGO = "farsighter-naf"


MODELS: dict[str, type[_OneAlgorithm]] = {
    cls.ALGO: cls
    for cls in (DDQN, KDDQN, BDQN, Farsighter, OB2I, RND, KRND, NAF, KNAF, BNAF, FarsighterNAF)
}
"""Each algorithm's model class (every row of :data:`farsighter.algorithms.TABLE`)."""
assert set(MODELS) == set(algorithms.NAMES), "a model class per algorithm"


def make(algo: str, env: str | gym.Env[Any, Any], **overrides: Any) -> Model:
    """A model of ``algo`` (its class in :data:`MODELS`) for ``env``, an id or an environment
    made by ``gymnasium.make``; ``overrides`` as :func:`~farsighter.config.make_config` takes
    them."""
    algorithms.get(algo)  # an unknown name: one line listing the accepted ones
    return MODELS[algo](env, **overrides)
