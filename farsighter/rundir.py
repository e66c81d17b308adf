"""Run directories: resolved config, metrics, TensorBoard events and atomic checkpoints."""

from __future__ import annotations

import csv
import os
import shutil
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import torch

from farsighter.config import Config, load_config, save_config
from farsighter.config.presets import flat_fields, with_values
from farsighter.errors import RunDirError

if TYPE_CHECKING:
    from farsighter.tracking import Tracker

CONFIG_FILE = "config.json"
CHECKPOINT_FILE = "checkpoint.pt"
METRICS_FILE = "metrics.csv"
EVAL_FILE = "eval.csv"
SUMMARY_FILE = "summary.json"
METRIC_COLUMNS = (
    "global_step",
    "episode",
    "episodic_return",
    "episodic_length",
    "SPS",
    "loss",
    "epsilon",
    "k",
)
EVAL_COLUMNS = ("global_step", "eval_return_mean", "eval_return_std", "eval_episodes")
# Goal-conditioned tasks only (created on the first episode that reports info["is_success"]),
# so metrics.csv keeps its fixed columns for every run.
SUCCESS_FILE = "success.csv"
SUCCESS_COLUMNS = ("global_step", "episode", "success")
EVAL_SUCCESS_FILE = "eval_success.csv"
EVAL_SUCCESS_COLUMNS = ("global_step", "eval_success_rate", "eval_episodes")

# Fields that may differ between the original command and its --resume: where and how the run
# continues and how long it trains, plus bookkeeping that does not change what is learned
# (dotted names for nested fields).
RESUMABLE_FIELDS = {
    "resume",
    "overwrite",
    "total_steps",
    "runtime.device",
    "runtime.cuda_graph",
    "runtime.compile",
    "runtime.gpu_replay",
    "runtime.target_cache",
    "progress",
    "run_dir",
    "runtime.torch_threads",
    "runtime.capture_video",
    "runtime.track",
    "runtime.wandb_project",
    "runtime.wandb_entity",
    "log_every",
    "checkpoint_every",
}


def slug(label: str) -> str:
    """A label as a directory name: ``"Farsighter (k=10)"`` -> ``farsighter-k-10``."""
    return "".join(c if c.isalnum() else "-" for c in label.lower()).strip("-").replace("--", "-")


# What a run is: a resume that names other values is another run, refused before anything else.
RUN_IDENTITY = ("algo", "env")


def check_same_run(cfg: Config, saved: Config | None = None) -> None:
    """With ``resume``: refuse another algorithm or environment than the saved run's, in one line
    naming the saved and the given values. Checked first, so that the message is not about a
    field that only follows from them (a ``k_target`` the other algorithm does not take).
    ``saved``: the run's config, read from ``cfg``'s run directory when not given; a directory
    without a run is left to :func:`prepare_run_dir` to refuse."""
    if not cfg.resume:
        return
    path = cfg.resolved_run_dir
    if saved is None:
        if not (path / CONFIG_FILE).is_file():
            return
        saved = load_config(path / CONFIG_FILE)
    diffs = [
        f"{name} (saved {getattr(saved, name)!r}, given {getattr(cfg, name)!r})"
        for name in RUN_IDENTITY
        if getattr(saved, name) != getattr(cfg, name)
    ]
    if diffs:
        raise RunDirError(
            f"cannot resume the run in {path} as another run: "
            + "; ".join(diffs)
            + " (a resume continues the saved algo and env: drop those flags, or use a new "
            "--run-dir)"
        )


def check_resume(cfg: Config) -> tuple[Config, Config]:
    """With ``resume``: the run directory's saved config and the config this resume records
    there (the saved one with the :data:`RESUMABLE_FIELDS` given, such as a longer
    ``total_steps``). Refuses (:class:`RunDirError`, one line) a directory without a run and a
    config that differs from the saved one outside those fields; writes nothing."""
    path = cfg.resolved_run_dir
    if cfg.overwrite:
        raise RunDirError("--resume and --overwrite exclude each other; pass one")
    if not (path / CONFIG_FILE).is_file():
        raise RunDirError(f"cannot resume: {path} holds no run (no {CONFIG_FILE})")
    saved = load_config(path / CONFIG_FILE)
    check_same_run(cfg, saved)
    before, given = dict(flat_fields(saved)), dict(flat_fields(cfg))
    diffs = [
        f"{name} (saved {before[name]!r}, given {given[name]!r})"
        for name in given
        if name not in RESUMABLE_FIELDS and before[name] != given[name]
    ]
    if diffs:
        raise RunDirError(
            "cannot resume with a different config: "
            + "; ".join(diffs[:3])
            + " (resume with the original flags, or use a new --run-dir)"
        )
    # Record what this resume changed (where the run lives and the flags stay as saved).
    recorded = sorted(RESUMABLE_FIELDS - {"resume", "overwrite", "run_dir"})
    return saved, with_values(saved, {name: given[name] for name in recorded})


def prepare_run_dir(cfg: Config) -> Path:
    """Create (or reopen with ``resume``) the run directory; never overwrite unless asked.

    A resume must match the saved config outside :data:`RESUMABLE_FIELDS`; the resumable values
    it gives (a longer ``total_steps``, say) are recorded in config.json (:func:`check_resume`).
    A directory that cannot be created or written raises :class:`RunDirError`, one line with the
    reason."""
    path = cfg.resolved_run_dir
    if cfg.resume:
        saved, updated = check_resume(cfg)
        if updated != saved:
            try:
                save_config(updated, path / CONFIG_FILE)
            except OSError as exc:
                raise RunDirError(
                    f"cannot write {path / CONFIG_FILE}: {exc.strerror or exc}"
                ) from None
        return path
    try:
        if path.exists() and not path.is_dir():
            raise RunDirError(f"cannot create run directory {path}: a file of that name exists")
        if path.exists() and any(path.iterdir()):
            if not cfg.overwrite:
                raise RunDirError(
                    f"run directory {path} already exists; pass --resume to continue it or "
                    "--overwrite to replace it (or choose another --run-dir)"
                )
            shutil.rmtree(path)
        path.mkdir(parents=True, exist_ok=True)
        save_config(cfg, path / CONFIG_FILE)
    except OSError as exc:
        raise RunDirError(f"cannot create run directory {path}: {exc.strerror or exc}") from None
    return path


def save_checkpoint(path: Path, state: dict[str, Any]) -> None:
    """Write atomically: a crash mid-write leaves the previous checkpoint intact."""
    tmp = path / (CHECKPOINT_FILE + ".tmp")
    torch.save(state, tmp)
    os.replace(tmp, path / CHECKPOINT_FILE)


def load_checkpoint(path: Path) -> dict[str, Any]:
    file = path / CHECKPOINT_FILE
    if not file.exists():
        raise RunDirError(f"cannot resume: no checkpoint in {path} (expected {CHECKPOINT_FILE})")
    try:
        state = torch.load(file, map_location="cpu", weights_only=False)
    except Exception as exc:  # truncated/garbled files raise many different errors
        raise RunDirError(
            f"checkpoint {file} is corrupt or unreadable ({type(exc).__name__}); "
            "delete it to restart from scratch with --overwrite"
        ) from None
    if not isinstance(state, dict) or "loop" not in state or "agent" not in state:
        raise RunDirError(f"checkpoint {file} is not a farsighter checkpoint")
    return state


def truncate_csv(file: Path, max_step: int) -> None:
    """Drop rows logged after ``max_step`` (work after the checkpoint is redone on resume)."""
    if not file.exists():
        return
    with file.open(newline="") as fh:
        rows = list(csv.reader(fh))
    if not rows:
        return
    header, body = rows[0], rows[1:]
    kept = [r for r in body if r and int(float(r[0])) <= max_step]
    with file.open("w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(header)
        writer.writerows(kept)


FLUSH_SECONDS = 2.0
"""A run's logs reach the disk at least this often, before every checkpoint, and at the end.
Writing each episode's rows and scalars through at once cost a short-episode task more than its
environment step: every TensorBoard scalar wakes the writer's thread, which then takes the GIL
from the loop (about 2 ms a scalar with both cores busy), and every row was flushed on its own.
A resume discards what was logged after its checkpoint anyway (:func:`truncate_csv`, the
writer's ``purge_step``), so holding rows between flushes loses nothing a resume keeps."""


class CsvLog:
    """Append-only CSV with a fixed header (rows reach the disk at :meth:`flush`)."""

    def __init__(self, file: Path, columns: tuple[str, ...]) -> None:
        self.columns = columns
        new = not file.exists()
        self.fh = file.open("a", newline="")
        self.writer = csv.writer(self.fh)
        if new:
            self.writer.writerow(columns)
            self.fh.flush()

    def write(self, row: dict[str, Any]) -> None:
        self.writer.writerow([_fmt(row.get(c, "")) for c in self.columns])

    def flush(self) -> None:
        self.fh.flush()

    def close(self) -> None:
        self.fh.close()


def _fmt(value: Any) -> Any:
    if isinstance(value, float):
        return f"{value:.6g}"
    return value


class RunLogger:
    """Metrics CSV, evaluation CSV and TensorBoard events under fixed namespaces
    (``charts/``, ``losses/``, ``eval/``), reopened consistently on resume. Rows and scalars are
    held and written out together every :data:`FLUSH_SECONDS` and at :meth:`flush` (each
    scalar with the wall time it was logged at). ``trackers`` (:mod:`farsighter.tracking`:
    Weights & Biases, the callbacks' ``on_scalar``) get the same scalars at each flush, and
    the videos given to :meth:`video`; :meth:`close` ends them."""

    def __init__(
        self, path: Path, resume_step: int | None, trackers: Sequence[Tracker] = ()
    ) -> None:
        from torch.utils.tensorboard import SummaryWriter

        if resume_step is not None:
            for name in (METRICS_FILE, EVAL_FILE, SUCCESS_FILE, EVAL_SUCCESS_FILE):
                truncate_csv(path / name, resume_step)
        self.path = path
        self.metrics = CsvLog(path / METRICS_FILE, METRIC_COLUMNS)
        self.eval = CsvLog(path / EVAL_FILE, EVAL_COLUMNS)
        self._success: dict[str, CsvLog] = {}
        # purge_step discards events written after the checkpoint by the interrupted process.
        self.tb = SummaryWriter(str(path), purge_step=resume_step)
        self._scalars: list[tuple[str, float, int, float]] = []
        self._flushed = time.monotonic()
        self.trackers = list(trackers)

    def scalar(self, tag: str, value: float, step: int) -> None:
        self._scalars.append((tag, value, step, time.time()))
        if time.monotonic() - self._flushed >= FLUSH_SECONDS:
            self.flush()

    def flush(self) -> None:
        """Everything logged so far to the disk: the held scalars to the TensorBoard writer,
        then every file flushed."""
        for tag, value, step, walltime in self._scalars:
            self.tb.add_scalar(tag, value, step, walltime=walltime)
        held = [(tag, value, step) for tag, value, step, _ in self._scalars]
        self._scalars.clear()
        for tracker in self.trackers if held else ():
            tracker.scalars(held)
        for log in (self.metrics, self.eval, *self._success.values()):
            log.flush()
        self.tb.flush()
        self._flushed = time.monotonic()

    def video(self, tag: str, file: Path, step: int) -> None:
        """An .mp4 written at ``step``, for the trackers (TensorBoard keeps scalars only), after
        the scalars logged before it."""
        if self.trackers:
            self.flush()
        for tracker in self.trackers:
            tracker.video(tag, file, step)

    def success(self, row: dict[str, Any], evaluation: bool = False) -> None:
        """A row of success.csv (training episodes) or eval_success.csv (evaluation phases)."""
        name, columns = (
            (EVAL_SUCCESS_FILE, EVAL_SUCCESS_COLUMNS)
            if evaluation
            else (SUCCESS_FILE, SUCCESS_COLUMNS)
        )
        if name not in self._success:
            self._success[name] = CsvLog(self.path / name, columns)
        self._success[name].write(row)

    def close(self, failed: bool = False) -> None:
        """Flush and close the files, then end the trackers: ``failed`` when the run stops
        before its end (an error, a signal)."""
        try:
            self.flush()
        except BaseException:
            failed = True
            raise
        finally:
            self.metrics.close()
            self.eval.close()
            for log in self._success.values():
                log.close()
            self.tb.close()
            for tracker in self.trackers:
                tracker.close(failed)
