"""Trackers beside TensorBoard, fed by :class:`farsighter.rundir.RunLogger` with what it writes
there: Weights & Biases (``farsighter train --track``) and the ``on_scalar`` hook of training
callbacks (:class:`farsighter.session.BaseCallback`). Each sees every scalar with the tag and
step TensorBoard gets, when the logger writes them out (at least every
:data:`~farsighter.rundir.FLUSH_SECONDS`, before each checkpoint and at the end)."""

from __future__ import annotations

import secrets
import string
import sys
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType
from typing import Any, Protocol

from farsighter.config import Config
from farsighter.config.files import config_to_dict
from farsighter.errors import ConfigError

TRACK_EXTRA = "install the track extra: pip install 'farsighter[track]'"
WANDB_ID_FILE = "wandb-run-id.txt"
"""The W&B run id of a tracked run, in its run directory: a resume continues that W&B run."""
VIDEO_TAG = "videos/eval"
"""Where a tracker shows the evaluation videos of ``--capture-video``."""

Scalar = tuple[str, float, int]
"""(tag, value, step), as :meth:`farsighter.rundir.RunLogger.scalar` takes them."""


class Tracker(Protocol):
    """Receives what a run logs, beside TensorBoard."""

    def scalars(self, items: Sequence[Scalar]) -> None:
        """The scalars logged since the last call, in the order logged."""

    def video(self, tag: str, file: Path, step: int) -> None:
        """An .mp4 written at ``step`` (an evaluation's episode, with ``--capture-video``)."""

    def close(self, failed: bool) -> None:
        """The run is over: finished (``failed`` False), or stopped by an error or a signal."""


class ScalarCallback(Protocol):
    """A training callback that also takes the run's scalars (the optional hook)."""

    def on_scalar(self, tag: str, value: float, step: int) -> None: ...


def import_wandb() -> ModuleType:
    """The ``wandb`` module, or a one-line refusal naming the extra."""
    try:
        import wandb
    except ImportError:
        raise ConfigError(
            f"--track logs to Weights & Biases with wandb, which is missing; {TRACK_EXTRA}"
        ) from None
    return wandb


def check_tracking(cfg: Config) -> None:
    """Refuse ``--track`` without wandb (before anything of the run is made)."""
    if cfg.runtime.track:
        import_wandb()


def new_run_id() -> str:
    """Eight lower-case letters and digits, the form W&B gives its own run ids."""
    alphabet = string.ascii_lowercase + string.digits
    return "".join(secrets.choice(alphabet) for _ in range(8))


class WandbTracker:
    """One W&B run per run directory: ``wandb.init`` with the resolved config, named after the
    directory and writing into it (``RUN_DIR/wandb``); a resume continues the same W&B run (its
    id in :data:`WANDB_ID_FILE`). Scalars go against a ``global_step`` axis (``define_metric``),
    so points a resume logs again after its checkpoint are kept rather than refused as steps
    gone back; W&B's own ``_step`` counts the calls."""

    def __init__(self, cfg: Config, path: Path, resumed: bool) -> None:
        wandb = import_wandb()
        self.wandb = wandb
        id_file = path / WANDB_ID_FILE
        run_id = id_file.read_text().strip() if resumed and id_file.is_file() else ""
        if not run_id:
            run_id = new_run_id()
            id_file.write_text(run_id + "\n")
        runtime = cfg.runtime
        try:
            self.run: Any = wandb.init(
                project=runtime.wandb_project,
                entity=runtime.wandb_entity or None,
                config=config_to_dict(cfg),
                name=path.name,
                dir=str(path),
                id=run_id,
                resume="allow",
                reinit="create_new",  # each seed of a batch (--seeds) its own run
                sync_tensorboard=False,
            )
        except Exception as exc:  # wandb raises its own errors (no login, no network, ...)
            lines = str(exc).strip().splitlines()
            raise ConfigError(
                f"--track: Weights & Biases could not start a run "
                f"({lines[0] if lines else type(exc).__name__}); log in with `wandb login`, "
                "or set WANDB_MODE=offline to keep the run in RUN_DIR/wandb"
            ) from None
        self.run.define_metric("global_step")
        self.run.define_metric("*", step_metric="global_step")

    def scalars(self, items: Sequence[Scalar]) -> None:
        row: dict[str, Any] = {}
        for tag, value, step in items:  # one wandb.log per step (several tags each)
            if row and (row["global_step"] != step or tag in row):
                self.run.log(row)
                row = {}
            row.setdefault("global_step", step)
            row[tag] = value
        if row:
            self.run.log(row)

    def video(self, tag: str, file: Path, step: int) -> None:
        self.run.log({"global_step": step, tag: self.wandb.Video(str(file), format="mp4")})

    def close(self, failed: bool) -> None:
        if not failed:
            self.run.finish(exit_code=0)
            return
        try:  # the error that stopped the run is the one to see
            self.run.finish(exit_code=1)
        except Exception as exc:
            print(f"farsighter: wandb could not finish the run: {exc}", file=sys.stderr)


class CallbackTracker:
    """The ``on_scalar`` hooks of training callbacks, called once per scalar."""

    def __init__(self, callbacks: Sequence[ScalarCallback]) -> None:
        self.callbacks = list(callbacks)

    def scalars(self, items: Sequence[Scalar]) -> None:
        for tag, value, step in items:
            for callback in self.callbacks:
                callback.on_scalar(tag, value, step)

    def video(self, tag: str, file: Path, step: int) -> None:
        pass

    def close(self, failed: bool) -> None:
        pass


def run_trackers(cfg: Config, path: Path, resumed: bool, callbacks: Sequence[Any]) -> list[Tracker]:
    """The trackers of a run: the callbacks that have ``on_scalar``, then W&B with ``track``."""
    hooks = [cb for cb in callbacks if callable(getattr(cb, "on_scalar", None))]
    trackers: list[Tracker] = [CallbackTracker(hooks)] if hooks else []
    if cfg.runtime.track:
        trackers.append(WandbTracker(cfg, path, resumed))
    return trackers
