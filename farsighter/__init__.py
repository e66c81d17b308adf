"""Farsighter: uncertainty-driven multi-step exploration for deep RL.

>>> import farsighter
>>> cfg = farsighter.make_config("farsighter", "CartPole-v1", preset="cartpole", total_steps=50_000)
>>> summary = farsighter.train(cfg)              # doctest: +SKIP
>>> policy = farsighter.load_agent(summary["run_dir"])  # doctest: +SKIP
"""

from farsighter.config import PRESETS, Config, make_config
from farsighter.errors import FarsighterError
from farsighter.train import load_agent, train

__all__ = ["PRESETS", "Config", "FarsighterError", "load_agent", "make_config", "train"]
__version__ = "0.1.0"
