"""Farsighter: uncertainty-driven multi-step exploration for deep RL.

>>> import farsighter
>>> cfg = farsighter.make_config("farsighter", "CartPole-v1", preset="cartpole", total_steps=50_000)
>>> summary = farsighter.train(cfg)              # doctest: +SKIP
>>> policy = farsighter.load_agent(summary["run_dir"])  # doctest: +SKIP

or, in the shape of Stable-Baselines3 (:mod:`farsighter.model`):

>>> model = farsighter.Farsighter("CartPole-v1", preset="cartpole")
>>> model.learn(50_000).save("cartpole-model")   # doctest: +SKIP
>>> action = model.predict(obs)                  # doctest: +SKIP
"""

from farsighter.config import PRESETS, Config, make_config
from farsighter.errors import FarsighterError
from farsighter.model import (
    BDQN,
    BNAF,
    DDQN,
    KDDQN,
    KNAF,
    KRND,
    NAF,
    OB2I,
    RND,
    Farsighter,
    FarsighterNAF,
    Model,
    make,
)
from farsighter.session import BaseCallback, Callback
from farsighter.train import load_agent, train

__all__ = [
    "BDQN",
    "BNAF",
    "BaseCallback",
    "Callback",
    "DDQN",
    "KDDQN",
    "KNAF",
    "KRND",
    "NAF",
    "OB2I",
    "PRESETS",
    "RND",
    "Config",
    "Farsighter",
    "FarsighterError",
    "FarsighterNAF",
    "Model",
    "load_agent",
    "make",
    "make_config",
    "train",
]
__version__ = "0.1.0"
