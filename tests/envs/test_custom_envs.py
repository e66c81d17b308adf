"""Environments of the user's own: images in height-width-channel layout, a ``module:EnvId``
beside the command, and an environment that returns NaN (issue #64)."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import farsighter
from farsighter.cli import main
from farsighter.envs import make_env
from tests.conftest import tiny


class RgbEnv(gym.Env[np.ndarray, int]):
    """A (64, 64, 3) uint8 image whose brightness says which action pays; 20 steps."""

    observation_space = gym.spaces.Box(0, 255, (64, 64, 3), np.uint8)
    action_space = gym.spaces.Discrete(2)

    def _image(self) -> np.ndarray:
        self.good = int(self.np_random.integers(2))
        return np.full((64, 64, 3), 200 * self.good, dtype=np.uint8)

    def reset(self, *, seed: int | None = None, options: Any = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self.t = 0
        return self._image(), {}

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict]:
        reward = float(action == self.good)
        self.t += 1
        return self._image(), reward, self.t >= 20, False, {}


class NanEnv(gym.Env[np.ndarray, int]):
    """Returns a NaN reward (``what="reward"``) or observation at its 50th step."""

    observation_space = gym.spaces.Box(-1.0, 1.0, (4,), np.float32)
    action_space = gym.spaces.Discrete(2)

    def __init__(self, what: str = "reward") -> None:
        self.what, self.steps = what, 0

    def reset(self, *, seed: int | None = None, options: Any = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        return np.zeros(4, np.float32), {}

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict]:
        self.steps += 1
        bad = self.steps == 50
        obs = np.full(4, np.nan if bad and self.what == "observation" else 0.0, np.float32)
        return obs, np.nan if bad and self.what == "reward" else 1.0, False, False, {}


gym.register("farsighter-test/Rgb-v0", entry_point=RgbEnv, max_episode_steps=100)
gym.register("farsighter-test/NanReward-v0", entry_point=NanEnv, kwargs={"what": "reward"})
gym.register(
    "farsighter-test/NanObservation-v0", entry_point=NanEnv, kwargs={"what": "observation"}
)


def test_channels_last_images_train_channels_first(tmp_path: Path) -> None:
    short = {"total_steps": 300, "learning_starts": 100, "eval_every": 0, "checkpoint_every": 0}
    cfg = tiny("ddqn", tmp_path / "run", env="farsighter-test/Rgb-v0", **short)
    env = make_env(cfg, seed=0)
    assert env.observation_space.shape == (3, 64, 64)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (3, 64, 64) and obs.dtype == np.uint8
    env.close()
    summary = farsighter.train(cfg)
    assert summary["global_step"] == 300 and summary["episodes"] == 15


MODULE = """
import gymnasium as gym
import numpy as np


class CwdEnv(gym.Env):
    observation_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
    action_space = gym.spaces.Discrete(2)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return np.zeros(2, np.float32), {}

    def step(self, action):
        self.t += 1
        return np.full(2, action, np.float32), float(action), self.t >= 10, False, {}


gym.register("CwdEnv-v0", entry_point="fs_cwd_envs:CwdEnv")
"""


def test_the_console_script_finds_a_module_in_the_current_directory(tmp_path: Path) -> None:
    script = Path(sys.executable).with_name("farsighter")
    if not script.exists():
        pytest.skip("the farsighter console script is not installed beside this interpreter")
    (tmp_path / "fs_cwd_envs.py").write_text(textwrap.dedent(MODULE))
    res = subprocess.run(
        [str(script), "train", "--algo", "ddqn", "--env", "fs_cwd_envs:CwdEnv-v0"]
        + ["--preset", "control", "--total-steps", "300", "--learning-starts", "100"]
        + ["--eval-every", "0", "--eval-episodes", "1", "--hidden-sizes", "16", "16"]
        + ["--no-progress", "--run-dir", "run"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "run" / "summary.json").exists()


@pytest.mark.parametrize(
    ("env", "what"),
    [("NanReward-v0", "a reward of nan"), ("NanObservation-v0", "an observation holding nan")],
)
def test_a_nan_from_the_environment_is_its_fault_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], env: str, what: str
) -> None:
    env_id = f"farsighter-test/{env}"
    args = ["train", "--algo", "ddqn", "--env", env_id, "--preset", "control"]
    args += ["--total-steps", "300", "--learning-starts", "20", "--hidden-sizes", "16", "16"]
    assert main([*args, "--no-progress", "--run-dir", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f"farsighter: error: the environment {env_id} returned {what} at step 50 (environment "
        "0); a NaN or infinite reward or observation is the environment's to fix"
    ]
