"""The skeleton every study shares; a study file gives only what is its own (:class:`Study`).

The runner parses a study command's flags (:class:`StudyArgs`, with tyro like ``farsighter
train``) and checks them, builds the grid (every agent x seed, a run directory
``runs/<slug>__s<seed>`` each; a study with tasks runs every agent x task x seed, in
``runs/<task slug>/<slug>__s<seed>``, each task with its own step budget), keeps the study's
settings in ``study.json``, resumes an interrupted study (finished runs are kept, unfinished
ones rerun), runs the jobs in worker processes with one progress bar, loads the saved files of
the finished runs and hands them to the study's outputs, which ``--plot-only`` redraws.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shlex
import shutil
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Protocol

import numpy as np
import tyro

from farsighter import jsonio
from farsighter.cli_args import parse_flags
from farsighter.config import Config, make_config, validate
from farsighter.errors import ConfigError, FarsighterError
from farsighter.provenance import code_version
from farsighter.rundir import slug
from farsighter.sweep.engine import (
    Backend,
    Progress,
    chunk_by,
    execute,
    parse_address,
    ray_init,
)

Runs = dict[str, list[dict[str, Any]]]
"""Per agent label, one dict per finished run: ``"seed"``, ``"steps"`` (its budget), ``"task"``
(the environment id of a study with tasks, else None) and the run's saved files."""

Task = tuple[str, int]
"""One task of a study with tasks: an environment id and its step budget."""


@dataclass(frozen=True)
class Agent:
    """One line of a study: a label, an algorithm and its overrides of the study's settings."""

    label: str
    algo: str
    overrides: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Job:
    """One run of the grid: an agent, a seed, its budget, and its task (None without tasks)."""

    label: str
    seed: int
    steps: int
    task: str | None = None

    def run_dir(self, out: Path) -> Path:
        """``runs/<slug>__s<seed>``, under ``runs/<task slug>/`` in a study with tasks."""
        runs = out / "runs" / slug(self.task) if self.task else out / "runs"
        return runs / f"{slug(self.label)}__s{self.seed}"


def run_config(
    agent: Agent, env: str, preset: str, seed: int, steps: int, run_dir: Path, **values: Any
) -> Config:
    """One run of a study: ``preset`` <- the study's ``values`` <- the agent's overrides, with the
    seed, the budget and the run directory; on one CPU thread unless ``values`` set
    ``torch_threads`` and ``device``, and without a progress bar of its own (the runner draws one
    for the whole study)."""
    return make_config(
        agent.algo,
        env,
        preset=preset,
        **{"torch_threads": 1, "device": "cpu", **values, **agent.overrides},
        seed=seed,
        total_steps=steps,
        run_dir=str(run_dir),
        progress=False,
        overwrite=True,
    )


class Settings(Protocol):
    """What every study's settings hold (a frozen dataclass, saved as ``study.json``)."""

    @property
    def seeds(self) -> tuple[int, ...]: ...
    @property
    def steps(self) -> int: ...
    @property
    def workers(self) -> int: ...
    @property
    def agents(self) -> tuple[str, ...]: ...


def _flag(metavar: str, hint: str) -> Any:
    return tyro.conf.arg(metavar=metavar, help_behavior_hint=hint)


_STUDY_DEFAULT = "(default: the study's)"


def study_flag(metavar: str) -> Any:
    """A study flag whose default the study's config decides (its help says so)."""
    return _flag(metavar, _STUDY_DEFAULT)


def nanmean(x: Sequence[float] | np.ndarray) -> float:
    """The mean of the finite values; NaN when there is none (without numpy's warning)."""
    x = np.asarray(x, dtype=float)
    return float(np.nanmean(x)) if np.isfinite(x).any() else float("nan")


SEEDS_PER_BATCH = 16
"""Most seeds of one agent and task that a study trains as one batch (``--seeds-per-batch``)."""


@dataclass(frozen=True)
class StudyArgs:
    """The flags every study command shares (a study may add its own in a subclass)."""

    quick: tyro.conf.FlagCreatePairsOff[bool] = False
    """The quick study (its settings are given above)."""
    out: Annotated[str | None, _flag("DIR", "(default: studies/<study>[-quick])")] = None
    """Study directory."""
    seeds: Annotated[tuple[int, ...] | None, _flag("SEED [SEED ...]", _STUDY_DEFAULT)] = None
    """Seeds to run, each >= 0."""
    steps: Annotated[int | None, _flag("N", _STUDY_DEFAULT)] = None
    """Environment steps of each run."""
    workers: Annotated[int, tyro.conf.arg(metavar="N")] = 0
    """Worker processes (0: one per core; 1: the runs go one after another in this process)."""
    seeds_per_batch: Annotated[int, tyro.conf.arg(metavar="N")] = SEEDS_PER_BATCH
    """Most seeds of one agent and task trained as one batch in one worker, where the agent has a
    seed-batched form (1: every run on its own; each run's numbers are the same either way)."""
    agents: Annotated[tuple[str, ...] | None, _flag("LABEL [LABEL ...]", _STUDY_DEFAULT)] = None
    """Agents by label (listed above), or 'all'."""
    plot_only: Annotated[str | None, _flag("DIR", "")] = None
    """Redraw the outputs of a study directory from its saved runs (takes no other flag)."""
    overwrite: tyro.conf.FlagCreatePairsOff[bool] = False
    """Delete the study directory (--out) first."""
    progress: bool = True
    """Show a progress bar over all runs."""
    ray: tyro.conf.FlagCreatePairsOff[bool] = False
    """Run the runs as Ray tasks (a local Ray, or the cluster of --address)."""
    address: Annotated[str | None, _flag("ADDR", "(default: start a local Ray)")] = None
    """Ray cluster to join with --ray (host:6379 or ray://host:10001)."""
    retries: Annotated[int, tyro.conf.arg(metavar="N")] = 2
    """Restarts of a run whose worker died or raised (a study's run restarts afresh)."""


@dataclass(frozen=True)
class Study:
    """What a study file gives the runner. The hooks are module-level functions (a job is pickled
    to a worker process)."""

    kind: str
    """The command's name (``farsighter <kind>``); names the study in messages."""
    description: str
    """First lines of ``--help``."""
    agents: tuple[Agent, ...]
    """Every agent the study can run."""
    full: Any
    """The default settings (a frozen dataclass with the fields of :class:`Settings`)."""
    quick: Any
    """The settings of ``--quick``."""
    run_config: Callable[..., Config]
    """(agent, settings, seed, run_dir) -> the run's config; in a study with tasks, (agent,
    settings, seed, run_dir, task) with the task's :data:`Task` (environment id, budget)."""
    write_outputs: Callable[[Path, dict[str, Any], Runs], None]
    """(study directory, its study.json, the finished runs) -> figures, tables, report."""
    run_files: tuple[str, ...]
    """Files loaded from each finished run (``*.csv``, ``*.npy``, ``*.json``), by stem; None
    where a run lacks one."""
    finished: tuple[str, ...] = ("summary.json",)
    """Files a finished run has: it is kept on resume and loaded for the outputs."""
    args: type[StudyArgs] = StudyArgs
    """The command's flags."""
    callback: Callable[[Any], Any] | None = None
    """settings -> a read-only callback of each run (what the loop does not record)."""
    resolve: Callable[[Any, Any], Any] | None = None
    """(settings, args) -> settings: a value the flags leave to the study."""
    check: Callable[[Any], None] | None = None
    """The study's own checks of its settings (raise :class:`FarsighterError`)."""
    name: Callable[[Any], str] | None = None
    """settings -> the default study directory's name under studies/ (default: kind)."""
    tasks: Callable[[Any], tuple[Task, ...]] | None = None
    """settings -> the tasks (environment id, step budget): the grid is then agent x task x seed
    and ``settings.steps`` is the study's to interpret (each run's budget is its task's)."""

    def agent(self, label: str) -> Agent:
        return next(a for a in self.agents if a.label == label)

    def labels(self) -> tuple[str, ...]:
        return tuple(a.label for a in self.agents)

    def grid(self, settings: Any) -> list[Job]:
        """Every run of the study: agent x seed, or agent x task x seed."""
        tasks = self.tasks(settings) if self.tasks else ((None, settings.steps),)
        return [
            Job(label, seed, steps, env)
            for label in settings.agents
            for env, steps in tasks
            for seed in settings.seeds
        ]

    def config(self, settings: Any, job: Job, run_dir: Path) -> Config:
        """The config of one run of the grid."""
        task = () if job.task is None else ((job.task, job.steps),)
        return self.run_config(self.agent(job.label), settings, job.seed, run_dir, *task)


# ------------------------------------------------------------------------------------------------
# The command: flags -> settings -> checks -> runs -> outputs.
# ------------------------------------------------------------------------------------------------


def main(study: Study, argv: Sequence[str]) -> int:
    """``farsighter <study.kind> ARGV``: every flag is checked before anything is written."""
    args = parse(study, argv)
    if args.plot_only is not None:
        _alone(args)
        return redraw(study, Path(args.plot_only))
    settings = settings_from(study, args)
    check(study, settings)
    if args.seeds_per_batch < 1:
        raise ConfigError(
            f"--seeds-per-batch must be >= 1 (1: every run on its own; got {args.seeds_per_batch})"
        )
    backend = backend_of(args, settings.workers)
    out = out_dir(study, settings, args)
    if backend.address is not None:
        ray_init(backend.address)  # join (or fail) before the study directory is touched
    if args.overwrite and out.exists():
        shutil.rmtree(out)
    t0 = time.perf_counter()
    run_study(study, settings, out, args.progress, backend, args.seeds_per_batch)
    print(f"{study.kind} study done in {time.perf_counter() - t0:.0f} s")
    print(f"report: {out / 'report.md'}")
    print(f"figures: {out / 'figures'}")
    return 0


def backend_of(args: StudyArgs, workers: int) -> Backend:
    """Where the runs go: --workers, --retries, --ray, --address (checked: one line, exit 2)."""
    if args.address is not None and not args.ray:
        raise FarsighterError("--address joins a Ray cluster and needs --ray")
    if args.address is not None:
        parse_address(args.address)
    if args.retries < 0:
        raise FarsighterError(f"--retries must be >= 0 (got {args.retries})")
    return Backend(workers=workers, retries=args.retries, ray=args.ray, address=args.address)


def parse(study: Study, argv: Sequence[str]) -> StudyArgs:
    """The command's flags (tyro: a bad value or an unknown flag exits with 2)."""
    prog = f"farsighter {study.kind}"
    return parse_flags(study.args, argv, prog, description=_help(study))


def out_dir(study: Study, settings: Any, args: StudyArgs) -> Path:
    """--out, or studies/<the study's name>[-quick]."""
    if args.out:
        return Path(args.out)
    name = study.name(settings) if study.name else study.kind
    return Path("studies") / (name + ("-quick" if args.quick else ""))


def _help(study: Study) -> str:
    q = study.quick
    labels = ", ".join(repr(label) for label in study.labels())
    if study.tasks:
        tasks = study.tasks(q)
        budget = f"{len(tasks)} tasks ({', '.join(f'{env} {n:,}' for env, n in tasks)} steps)"
    else:
        budget = f"{q.steps:,} steps"
    return (
        f"{study.description}\n\n--quick: {', '.join(q.agents)}; {len(q.seeds)} seeds x "
        f"{budget}. Agents (--agents): {labels}."
    )


def _alone(args: StudyArgs) -> None:
    """--plot-only redraws a study where it is: the flags that set up a run do not apply."""
    others = [
        "--" + f.name.replace("_", "-")
        for f in dataclasses.fields(args)
        if f.name not in ("plot_only", "progress", "retries") and getattr(args, f.name) != f.default
    ]
    if others:
        raise FarsighterError(
            f"--plot-only DIR redraws the study in DIR from its saved runs and takes no other "
            f"flag (got {', '.join(others)}); to redraw elsewhere, copy DIR first"
        )


def settings_from(study: Study, args: StudyArgs) -> Any:
    """The quick or full settings with the flags given (those named like a field of them)."""
    base = study.quick if args.quick else study.full
    given = {
        f.name: getattr(args, f.name)
        for f in dataclasses.fields(base)
        if getattr(args, f.name, None) is not None
    }
    if args.agents == ("all",):
        given["agents"] = study.labels()
    settings = dataclasses.replace(base, **given)
    return study.resolve(settings, args) if study.resolve else settings


def check(study: Study, settings: Settings) -> None:
    """Raise :class:`FarsighterError` with one line on the first bad setting; then every run's
    config is validated as ``farsighter train`` validates one, so nothing starts that would fail."""
    labels = study.labels()
    seeds = " ".join(str(s) for s in settings.seeds)
    unknown = [a for a in settings.agents if a not in labels]
    checks: list[tuple[bool, str]] = [
        (
            settings.workers >= 0,
            f"--workers must be >= 0 (0: one per core; got {settings.workers})",
        ),
        (
            study.tasks is not None or settings.steps >= 1,
            f"--steps must be >= 1 (got {settings.steps})",
        ),
        (len(settings.seeds) >= 1, "--seeds must name at least one seed"),
        (all(s >= 0 for s in settings.seeds), f"--seeds must be >= 0 (got {seeds})"),
        (len(set(settings.seeds)) == len(settings.seeds), f"--seeds name a seed twice ({seeds})"),
        (len(settings.agents) >= 1, f"--agents must name at least one of: {', '.join(labels)}"),
        (
            not unknown,
            f"unknown {study.kind} agent(s) {unknown}; accepted: {', '.join(labels)}, all",
        ),
        (len(set(settings.agents)) == len(settings.agents), "--agents name an agent twice"),
    ]
    for ok, message in checks:
        if not ok:
            raise FarsighterError(message)
    if study.check:
        study.check(settings)
    for job in study.grid(settings):
        try:
            validate(study.config(settings, job, Path(".")))
        except ConfigError as exc:
            task = f" on {job.task}" if job.task else ""
            raise ConfigError(f"{study.kind} agent '{job.label}'{task}: {exc}") from None


def run_study(
    study: Study,
    settings: Any,
    out: Path,
    show_progress: bool = True,
    backend: Backend | None = None,
    seeds_per_batch: int = SEEDS_PER_BATCH,
) -> Path:
    """Run (or resume) every agent x seed (x task) on ``backend`` (default: ``settings.workers``
    local processes), then write the study's outputs."""
    todo = _prepare(study, settings, out)
    if todo:
        groups = seed_batches(study, settings, out, todo, seeds_per_batch)
        execute(
            _run_jobs,
            [(study, settings, tuple(g), str(out), str(g[0].run_dir(out))) for g in groups],
            steps=[sum(job.steps for job in g) for g in groups],
            backend=backend or Backend(workers=settings.workers),
            desc=f"{study.kind} study",
            show_progress=show_progress,
            done_before=sum(job.steps for job in study.grid(settings)) - sum(j.steps for j in todo),
        )
    _write(study, out)
    return out


def _prepare(study: Study, settings: Any, out: Path) -> list[Job]:
    """Save the settings (a study.json with other settings is refused) and list the runs to do,
    the longest first: a finished run is kept, an unfinished one removed and done again."""
    out.mkdir(parents=True, exist_ok=True)
    saved = out / "study.json"
    current = json.loads(jsonio.dumps(dataclasses.asdict(settings)))
    made_by: list[dict[str, Any]] = []
    if saved.exists():
        # a field added since it was saved takes its default
        before = _read(saved)
        previous = json.loads(jsonio.dumps(dataclasses.asdict(settings_of(study, before))))
        if {**previous, "workers": 0} != {**current, "workers": 0}:
            raise FarsighterError(
                f"{out} holds a study with other settings ({saved}); use another --out or "
                "--overwrite"
            )
        made_by = list(before.get("made_by", []))
    # the code of each session that ran it (a resumed study may span commits)
    version = code_version()
    if not made_by or made_by[-1] != version:
        made_by.append(version)
    saved.write_text(jsonio.dumps({**current, "made_by": made_by}) + "\n")
    todo = []
    for job in study.grid(settings):
        run_dir = job.run_dir(out)
        if _finished(study, run_dir):
            continue
        if run_dir.exists():
            shutil.rmtree(run_dir)  # interrupted: its callbacks' state is gone, rerun it
        todo.append(job)
    return sorted(todo, key=lambda job: -job.steps)  # stable: the grid's order among equals


def _finished(study: Study, run_dir: Path) -> bool:
    return all((run_dir / name).exists() for name in study.finished)


def seed_batches(
    study: Study, settings: Any, out: Path, jobs: Sequence[Job], most: int = SEEDS_PER_BATCH
) -> list[list[Job]]:
    """The jobs as the worker processes take them: the seeds of one agent and task together
    where the agent trains seeds as one batch (:func:`farsighter.seeds.batchable`), every other
    job alone; in the order of ``jobs``. A batch holds at most ``most`` seeds
    (``--seeds-per-batch``) and no more than an even share of the jobs per worker
    (``settings.workers``), so that a study of
    one agent's five seeds on two workers runs as batches of three and two rather than leaving a
    core idle beside one batch of five."""
    from farsighter.seeds import batchable

    workers = settings.workers or os.cpu_count() or 1
    size = max(1, min(most, -(-len(jobs) // workers)))

    batches: dict[tuple[str, str | None], bool] = {}

    def key(job: Job) -> Any:
        run = (job.label, job.task)
        if run not in batches:
            batches[run] = batchable(study.config(settings, job, job.run_dir(out)))
        return run if batches[run] else job  # a job of its own where the agent has no batch

    return chunk_by(jobs, key, size)


def _run_jobs(
    study: Study, settings: Any, jobs: tuple[Job, ...], out: str, key: str, progress: Any
) -> str:
    """Jobs in one worker process: one run with the study's callback, or the seeds of one agent
    and task as one batch (each with its callback, as alone). A restarted job starts afresh
    (``overwrite``): the callbacks' state is not checkpointed. ``key``: the first run's
    directory, the job's name in ``progress``."""
    from farsighter.seeds import train_seeds
    from farsighter.train import train

    cfgs = [study.config(settings, job, job.run_dir(Path(out))) for job in jobs]
    hooks = [[study.callback(settings)] if study.callback else [] for _ in cfgs]
    if len(cfgs) == 1:
        train(cfgs[0], callbacks=[*hooks[0], Progress(progress, key)])
        return key
    hooks[0].append(Progress(progress, key, runs=len(cfgs)))  # the batch's seeds step together
    train_seeds(cfgs, callbacks=hooks)
    progress[key] = -1
    return key


# ------------------------------------------------------------------------------------------------
# Outputs: drawn from the saved files only.
# ------------------------------------------------------------------------------------------------


def redraw(study: Study, path: Path) -> int:
    """--plot-only: the outputs again from a study directory's saved files."""
    if not (path / "study.json").exists():
        raise FarsighterError(f"{path} holds no {study.kind} study (no study.json)")
    _write(study, path)
    print(f"report: {path / 'report.md'}")
    return 0


def _write(study: Study, out: Path) -> None:
    saved, runs = load_runs(study, out)
    (out / "figures").mkdir(exist_ok=True)
    study.write_outputs(out, saved, runs)
    report = out / "report.md"
    if report.exists() and saved.get("made_by"):
        text = report.read_text().rstrip("\n")
        report.write_text(f"{text}\n\n{made_by_line(saved['made_by'])}\n")


def made_by_line(made_by: list[dict[str, Any]]) -> str:
    """The report's last line: the code the study's runs were made with (study.json's
    ``made_by``, one entry per session that ran some of them)."""
    names = [
        f"commit {v['commit'][:10]}" + (" with uncommitted changes" if v.get("dirty") else "")
        if "commit" in v
        else f"farsighter {v.get('version', '?')} (not a git checkout)"
        for v in made_by
    ]
    return "Made with " + ", then ".join(names) + " (study.json, `made_by`)."


def load_runs(study: Study, out: Path) -> tuple[dict[str, Any], Runs]:
    """``study.json``, and per agent the saved files of its finished runs (task, then seed
    order)."""
    saved = json.loads((out / "study.json").read_text())
    runs: Runs = {}
    for job in study.grid(settings_of(study, saved)):
        run_dir = job.run_dir(out)
        if _finished(study, run_dir):
            files = {Path(name).stem: _read(run_dir / name) for name in study.run_files}
            run = {"seed": job.seed, "steps": job.steps, "task": job.task, **files}
            runs.setdefault(job.label, []).append(run)
    if not runs:
        raise FarsighterError(
            f"{out} holds no finished {study.kind} runs (runs/*/{' and '.join(study.finished)})"
        )
    return saved, runs


def settings_of(study: Study, saved: dict[str, Any]) -> Any:
    """The settings saved in a study.json as the study's dataclass (lists as tuples; a key that
    is no field of it any more is left out)."""
    fields = {f.name for f in dataclasses.fields(study.full)}
    values = {k: tuple(v) if isinstance(v, list) else v for k, v in saved.items() if k in fields}
    return dataclasses.replace(study.full, **values)


def command_line(
    kind: str, settings: Any, base: Any, names: Sequence[str], quick: bool, out: Path
) -> str:
    """``farsighter KIND [--quick] --NAME VALUE... --out OUT``: each of ``names`` whose value in
    ``settings`` differs from ``base`` (the full or the quick form the flags start from)."""
    line = ["farsighter", kind, *(["--quick"] if quick else [])]
    for name in names:
        value = getattr(settings, name)
        if value != getattr(base, name):
            values = value if isinstance(value, tuple) else (value,)
            line += [f"--{name}", *map(str, values)]
    return shlex.join([*line, "--out", str(out)])


def _read(file: Path) -> Any:
    from farsighter.plots import read_csv

    if not file.exists():
        return None
    if file.suffix == ".csv":
        return read_csv(file)
    if file.suffix == ".npy":
        return np.load(file)
    return json.loads(file.read_text())
