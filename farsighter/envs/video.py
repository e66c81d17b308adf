"""Episodes recorded as .mp4 files through Gymnasium's ``RecordVideo`` (it writes them with
moviepy, the ``video`` extra): every episode of ``farsighter eval --video DIR``, and one episode of
each periodic evaluation with ``--capture-video`` (``RUN_DIR/videos/``)."""

from __future__ import annotations

import importlib.util
import warnings
from collections.abc import Callable
from pathlib import Path

import gymnasium as gym

from farsighter.errors import ConfigError, EnvError

VIDEO_EXTRA = "install the video extra: pip install 'farsighter[video]'"
VIDEO_DIR = "videos"
"""Where ``--capture-video`` puts a run's videos, inside its run directory."""


def moviepy_installed() -> bool:
    return importlib.util.find_spec("moviepy") is not None


def check_video(what: str = "--video") -> None:
    """Refuse (one line naming the extra) a recording when moviepy is not installed."""
    if not moviepy_installed():
        raise ConfigError(f"{what} writes .mp4 files with moviepy, which is missing; {VIDEO_EXTRA}")


def record_episodes(env: gym.Env, folder: str | Path, name_prefix: str = "eval") -> gym.Env:
    """``env`` (made with ``render_mode="rgb_array"``) recording every episode into ``folder`` as
    ``<name_prefix>-episode-<i>.mp4`` (the last one is written when the environment closes)."""
    check_video()

    def make() -> gym.Env:
        return gym.wrappers.RecordVideo(
            env, str(folder), episode_trigger=lambda _: True, name_prefix=name_prefix
        )

    return _wrap(make, env)


class EvalVideo(gym.wrappers.RecordVideo):
    """Records the first episode after each :meth:`arm` as ``<name>.mp4`` (one per periodic
    evaluation: ``eval-step-<global step>.mp4``)."""

    def __init__(self, env: gym.Env, folder: str | Path) -> None:
        super().__init__(env, str(folder), episode_trigger=self._due)
        self._next: str | None = None

    def arm(self, name: str) -> None:
        """Record the next episode that starts, as ``name``.mp4."""
        self._next = name

    def finish(self) -> None:
        """Write the episode being recorded (the evaluation that ran it is over)."""
        self._next = None
        if self.recording:
            self.stop_recording()

    def _due(self, episode_id: int) -> bool:
        return getattr(self, "_next", None) is not None

    def start_recording(self, video_name: str) -> None:
        name, self._next = self._next or video_name, None
        super().start_recording(name)


def eval_video(env: gym.Env, folder: str | Path) -> EvalVideo:
    """``env`` (made with ``render_mode="rgb_array"``) as an :class:`EvalVideo`."""
    check_video("--capture-video")
    with warnings.catch_warnings():  # "overwriting existing videos": a resume adds to its own
        warnings.simplefilter("ignore")
        wrapped = _wrap(lambda: EvalVideo(env, folder), env)
    assert isinstance(wrapped, EvalVideo)
    return wrapped


def _wrap(make: Callable[[], gym.Env], env: gym.Env) -> gym.Env:
    """``make()``, with an environment that renders no frames, or a folder that cannot be made,
    said in one line."""
    try:
        return make()
    except (gym.error.Error, ValueError, OSError) as exc:
        env.close()
        name = env.spec.id if env.spec is not None else type(env.unwrapped).__name__
        why = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise EnvError(f"cannot record {name}: {why}") from None
