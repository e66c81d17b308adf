"""The notebook API (issue #64 item 3): ``farsighter.make`` and the model classes over
make_config, train and load_agent; environment objects made from registered ids; the quickstart
notebook runs."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.envs.classic_control.cartpole import CartPoleEnv

import farsighter
from farsighter.config import make_config
from farsighter.envs import make_env

ROOT = Path(__file__).resolve().parents[2]
TINY: dict[str, Any] = {
    "preset": "control",
    "learning_starts": 100,
    "buffer_size": 2_000,
    "batch_size": 16,
    "eval_episodes": 1,
    "eval_max_steps": 50,
    "hidden_sizes": (32, 32),
    "blr__posterior_every": 100,
    "blr__posterior_samples": 200,
}


def test_make_config_takes_an_environment_made_from_a_registered_id() -> None:
    cfg = make_config("farsighter", gym.make("CartPole-v1"), preset="cartpole")
    assert cfg.env == "CartPole-v1" and cfg == make_config("farsighter", "CartPole-v1", "cartpole")


def test_an_environment_made_with_arguments_keeps_them_as_env_kwargs() -> None:
    """gymnasium.make's arguments travel with the config (env_kwargs): every environment of the
    run, training and evaluation, is the one given, here an 8x8 lake without slipping."""
    lake = gym.make("FrozenLake-v1", is_slippery=False, map_name="8x8")
    cfg = make_config("farsighter", lake)
    assert cfg.env == "FrozenLake-v1"
    assert sorted(cfg.env_kwargs) == ["is_slippery=False", "map_name='8x8'"]
    assert cfg == make_config("farsighter", "FrozenLake-v1", env_kwargs=cfg.env_kwargs)
    for training in (True, False):
        env = make_env(cfg, seed=0, training=training)
        assert env.observation_space.shape == (64,)  # one-hot over 8 x 8 cells
        env.reset(seed=0)
        # without slipping, "right" (2) moves one cell right, every time
        assert np.argmax(env.step(2)[0]) == 1 and np.argmax(env.step(2)[0]) == 2
    with pytest.raises(farsighter.FarsighterError, match="^env_kwargs given twice"):
        make_config("farsighter", lake, env_kwargs={"map_name": "4x4"})


@pytest.mark.parametrize(
    ("make_env", "needle"),
    [
        (CartPoleEnv, "this CartPoleEnv environment has no registered Gymnasium id; pass an id"),
        (lambda: gym.make("CartPole-v1").unwrapped, "without its id's time limit (500 steps)"),
        (lambda: gym.make("CartPole-v1", max_episode_steps=50), "max_episode_steps=50"),
        (lambda: gym.wrappers.TimeAwareObservation(gym.make("CartPole-v1")), "wrappers"),
        (lambda: 3, "env must be a Gymnasium environment id"),
    ],
)
def test_an_environment_object_no_id_remakes_is_one_line(make_env: Any, needle: str) -> None:
    env = make_env()
    with pytest.raises(farsighter.FarsighterError) as info:
        make_config("farsighter", env)
    message = str(info.value)
    assert needle in message and "\n" not in message, message


def test_learn_predict_save_load(tmp_path: Path) -> None:
    cartpole = gym.make("CartPole-v1")
    model = farsighter.make("farsighter", cartpole, run_dir=str(tmp_path / "r"), **TINY)
    assert type(model) is farsighter.Farsighter and model.num_steps == 0
    env = model.make_env(seed=0)
    obs, _ = env.reset(seed=0)
    batch = np.stack([obs, -obs, 2 * obs])
    assert model.learn(300, progress=False) is model
    assert model.num_steps == 300 and model.run_dir == tmp_path / "r"
    single = model.predict(obs)
    assert np.ndim(single) == 0 and int(single) in (0, 1)
    actions = model.predict(batch)
    assert actions.shape == (3,) and actions[0] == single
    assert model.predict(batch, deterministic=False).shape == (3,)
    with pytest.raises(farsighter.FarsighterError, match=r"one observation of shape \(4,\)"):
        model.predict(np.zeros(3))
    model.learn(200, progress=False)  # continues the run
    assert model.num_steps == 500 and model.summary is not None
    assert model.summary["global_step"] == 500
    actions = model.predict(batch)
    saved = model.save(tmp_path / "saved")
    assert sorted(p.name for p in saved.iterdir()) == ["config.json", "policy.pt", "summary.json"]
    for loaded in (farsighter.Model.load(saved), farsighter.Farsighter.load(model.run_dir)):
        assert type(loaded) is farsighter.Farsighter and loaded.num_steps == 500
        np.testing.assert_array_equal(loaded.predict(batch), actions)
    with pytest.raises(farsighter.FarsighterError, match="load it with farsighter.Model.load"):
        farsighter.DDQN.load(saved)
    with pytest.raises(farsighter.FarsighterError, match="without a checkpoint"):
        farsighter.Model.load(saved).learn(100, progress=False)
    resumed = farsighter.Model.load(model.run_dir).learn(100, progress=False)
    assert resumed.num_steps == 600


def test_each_algorithm_has_its_class_and_a_default_run_dir_is_never_reused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    model = farsighter.DDQN("CartPole-v1", **TINY)
    assert model.config.algo == "ddqn" and isinstance(model, farsighter.Model)
    assert farsighter.make("bdqn", "CartPole-v1").config.algo == "bdqn"
    assert farsighter.FarsighterNAF("Pendulum-v1").config.algo == "farsighter-naf"
    first = model.learn(200, progress=False).run_dir
    second = farsighter.DDQN("CartPole-v1", **TINY).learn(200, progress=False).run_dir
    assert first == Path("runs/CartPole-v1__ddqn__s1")
    assert second == Path("runs/CartPole-v1__ddqn__s1-2")
    with pytest.raises(farsighter.FarsighterError, match="unknown algorithm 'nope'"):
        farsighter.make("nope", "CartPole-v1")
    with pytest.raises(farsighter.FarsighterError, match="k must be"):
        farsighter.DDQN("CartPole-v1", k=0)


def test_the_quickstart_notebook_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """examples/quickstart.ipynb's code cells, in order, in one namespace (no Jupyter)."""
    notebook = json.loads((ROOT / "examples" / "quickstart.ipynb").read_text())
    cells = ["".join(c["source"]) for c in notebook["cells"] if c["cell_type"] == "code"]
    assert len(cells) >= 4
    monkeypatch.chdir(tmp_path)
    namespace: dict[str, Any] = {"__name__": "__main__"}
    start = time.perf_counter()
    for i, source in enumerate(cells):
        exec(compile(source, f"quickstart.ipynb cell {i}", "exec"), namespace)
    assert time.perf_counter() - start < 60
    assert namespace["model"].num_steps == 2_000
    assert (tmp_path / "cartpole-farsighter" / "policy.pt").is_file()
    assert isinstance(namespace["loaded"], farsighter.Farsighter)
