"""Gymnasium's Box2D tasks (the ``box2d`` extra, installed by scripts/setup.sh): LunarLander trains
with the discrete agents and BipedalWalker with a continuous one, each run's saved policy acts;
without Box2D the environment is refused in one line naming the extra."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from farsighter import load_agent, train
from farsighter.envs import make_env
from farsighter.errors import EnvError
from tests.conftest import tiny


@pytest.mark.parametrize("algo", ["ddqn", "farsighter"])
def test_lunar_lander_trains_and_its_saved_policy_acts(tmp_path: Path, algo: str) -> None:
    cfg = tiny(algo, tmp_path / "run", env="LunarLander-v3", total_steps=600, eval_every=0)
    summary = train(cfg)
    assert summary["global_step"] == 600 and np.isfinite(summary["final_eval_return"])
    env = make_env(cfg, seed=0)
    assert env.observation_space.shape == (8,) and env.action_space.n == 4  # type: ignore[attr-defined]
    obs, _ = env.reset(seed=0)
    action = int(load_agent(tmp_path / "run").act(obs[None])[0])
    assert env.action_space.contains(action)
    env.close()


def test_bipedal_walker_trains_with_a_continuous_agent(tmp_path: Path) -> None:
    cfg = tiny(
        "farsighter-naf",
        tmp_path / "run",
        env="BipedalWalker-v3",
        preset="continuous",
        total_steps=400,
        eval_every=0,
        eval_max_steps=100,
    )
    summary = train(cfg)
    assert summary["global_step"] == 400 and np.isfinite(summary["final_eval_return"])


def test_missing_box2d_is_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    for name in [m for m in sys.modules if m.startswith("gymnasium.envs.box2d")]:
        monkeypatch.delitem(sys.modules, name)  # imported again by the entry point
    monkeypatch.setitem(sys.modules, "Box2D", None)  # import Box2D raises ImportError
    with pytest.raises(EnvError, match=r"^'LunarLander-v3' needs Box2D; .*farsighter\[box2d\]"):
        make_env(tiny("ddqn", tmp_path, env="LunarLander-v3"), seed=0)
