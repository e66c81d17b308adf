"""``farsighter sweep SPEC``: run a sweep file's trials and aggregate them.

The sweep directory (``--out``, default ``sweeps/<name>``) holds::

    sweep.json         the file's path and text, and the trial names (a rerun must match them)
    trials/<name>/     one run directory per trial (config, metrics, eval.csv, checkpoints)
    trials/<name>.attempts.log   one line per start of the trial (time, host, pid, fresh|resume)
    results.csv        one row per trial: agent, env, seed, swept values, final and best
                       evaluation return, steps, attempts
    aggregate/         rliable statistics across environments (farsighter.aggregate)
    figures/curves.png evaluation return against steps, per environment
    report.md          what ran, where, how long, how many restarts, and the tables

A rerun of the same sweep skips finished trials and resumes unfinished ones from their last
checkpoint; so does a trial that the engine restarts after its worker died.
"""

from __future__ import annotations

import csv
import json
import os
import shutil
import socket
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import tyro

from farsighter import jsonio
from farsighter.cli_args import parse_flags
from farsighter.errors import FarsighterError
from farsighter.rundir import CHECKPOINT_FILE, EVAL_FILE, SUMMARY_FILE
from farsighter.stats import fmt
from farsighter.sweep.engine import (
    Backend,
    Progress,
    chunk_by,
    execute,
    parse_address,
    ray_init,
)
from farsighter.sweep.spec import SweepError, SweepSpec, Trial, load_spec


@dataclass(frozen=True)
class SweepArgs:
    """farsighter sweep FILE: run every trial of a sweep file (TOML or YAML; format:
    farsighter.sweep.spec), locally or on Ray, then aggregate the results."""

    spec: Annotated[str, tyro.conf.Positional, tyro.conf.arg(metavar="FILE")]
    """The sweep file."""
    out: Annotated[str | None, tyro.conf.arg(metavar="DIR")] = None
    """Sweep directory (default: sweeps/<name>)."""
    ray: tyro.conf.FlagCreatePairsOff[bool] = False
    """Run the trials as Ray tasks (a local Ray, or the cluster of --address); the default
    when Ray is installed."""
    local: tyro.conf.FlagCreatePairsOff[bool] = False
    """Run the trials on local worker processes even when Ray is installed."""
    address: Annotated[str | None, tyro.conf.arg(metavar="ADDR")] = None
    """Ray cluster to join with --ray (host:6379 or ray://host:10001)."""
    workers: Annotated[int | None, tyro.conf.arg(metavar="N")] = None
    """Trials at once (default: the file's resources.max_concurrent; 0: one per core locally, as
    resources allow on Ray; 1 without --ray: one after another in this process)."""
    overwrite: tyro.conf.FlagCreatePairsOff[bool] = False
    """Delete the sweep directory first."""
    dry_run: tyro.conf.FlagCreatePairsOff[bool] = False
    """List the trials and what is left to do, run nothing."""
    progress: bool = True
    """Show a progress bar over all trials."""


def main(argv: Sequence[str]) -> int:
    args = parse_flags(SweepArgs, argv, "farsighter sweep")
    spec = load_spec(args.spec)
    out = Path(args.out) if args.out else spec.default_dir
    if args.ray and args.local:
        raise FarsighterError(
            "--ray and --local exclude each other; pass one (default: Ray when installed)"
        )
    if args.address is not None and args.local:
        raise FarsighterError("--address joins a Ray cluster; it does not go with --local")
    use_ray = args.ray or args.address is not None or (not args.local and ray_installed())
    if args.workers is not None and args.workers < 0:
        raise FarsighterError(f"--workers must be >= 0 (got {args.workers})")
    res = spec.resources
    backend = Backend(
        workers=res.max_concurrent if args.workers is None else args.workers,
        retries=res.retries,
        ray=use_ray,
        address=args.address,
        cpus=res.cpus,
        gpus=res.gpus,
    )
    if backend.address is not None:
        parse_address(backend.address)
    if args.dry_run:
        todo = unfinished(spec, out)
        for trial in spec.trials:
            state = "to run" if trial in todo else "finished"
            print(f"{trial.name}  ({trial.algo}, {_steps(trial):,} steps)  {state}")
        print(f"{len(spec.trials)} trials, {len(todo)} to run, in {out}, on {backend.describe()}")
        return 0
    if backend.address is not None:
        ray_init(backend.address)  # join (or fail) before the sweep directory is touched
    if args.overwrite and out.exists():
        shutil.rmtree(out)
    t0 = time.perf_counter()
    run_sweep(spec, out, backend, show_progress=args.progress)
    print(f"sweep {spec.name} done in {time.perf_counter() - t0:.0f} s")
    print(f"report: {out / 'report.md'}")
    return 0


def ray_installed() -> bool:
    import importlib.util

    return importlib.util.find_spec("ray") is not None


def _steps(trial: Trial) -> int:
    return trial.config("").total_steps


def finished(run_dir: Path) -> bool:
    """A trial is finished when its run wrote its summary at the end of its budget."""
    return (run_dir / SUMMARY_FILE).exists()


def trial_dir(out: Path, trial: Trial) -> Path:
    """The run directory of ``trial`` in the sweep directory ``out``."""
    return out / "trials" / trial.name


def unfinished(spec: SweepSpec, out: Path) -> list[Trial]:
    return [t for t in spec.trials if not finished(trial_dir(out, t))]


def run_sweep(
    spec: SweepSpec, out: Path, backend: Backend, show_progress: bool = True
) -> dict[str, Any]:
    """Run every unfinished trial of ``spec`` on ``backend`` (finished ones are skipped,
    unfinished ones resume from their checkpoints), then write the results; returns what the
    report says of the run (wall time, attempts)."""
    _prepare(spec, out)
    todo = unfinished(spec, out)
    budget = {t.name: _steps(t) for t in spec.trials}
    steps = [budget[t.name] for t in todo]
    t0 = time.perf_counter()
    if todo and spec.resources.seeds_per_process > 1:
        groups = seed_groups(todo, spec.resources.seeds_per_process)
        execute(
            run_trials,
            [
                (tuple(g), tuple(str(trial_dir(out, t)) for t in g), str(trial_dir(out, g[0])))
                for g in groups
            ],
            steps=[sum(budget[t.name] for t in g) for g in groups],
            backend=backend,
            desc=f"sweep {spec.name}",
            show_progress=show_progress,
            done_before=sum(budget.values()) - sum(steps),
        )
    elif todo:
        execute(
            run_trial,
            [(trial, str(trial_dir(out, trial))) for trial in todo],
            steps=steps,
            backend=backend,
            desc=f"sweep {spec.name}",
            show_progress=show_progress,
            done_before=sum(budget.values()) - sum(steps),
        )
    run = {
        "backend": backend.describe(),
        "wall_seconds": time.perf_counter() - t0,
        "trials_run": len(todo),
    }
    write_outputs(spec, out, run)
    return run


def _prepare(spec: SweepSpec, out: Path) -> None:
    """Keep the sweep's file and trial list; a directory of another sweep is refused."""
    out.mkdir(parents=True, exist_ok=True)
    saved = out / "sweep.json"
    names = [t.name for t in spec.trials]
    if saved.exists():
        previous = json.loads(saved.read_text())
        if previous.get("trials") != names:
            raise SweepError(
                f"{out} holds another sweep ({previous.get('name')!r}, "
                f"{len(previous.get('trials', []))} trials); use another --out or --overwrite"
            )
    text = Path(spec.source).read_text() if Path(spec.source).is_file() else ""
    record = {"name": spec.name, "source": spec.source, "text": text, "trials": names}
    saved.write_text(jsonio.dumps(record) + "\n")


def run_trial(trial: Trial, run_dir: str, progress: Any) -> str:
    """One trial (in a worker): resume from its checkpoint if it has one, else start afresh
    (a run killed before its first checkpoint leaves nothing worth keeping)."""
    from farsighter.train import train

    train(_start(trial, Path(run_dir)), callbacks=[Progress(progress, run_dir)])
    return run_dir


def run_trials(
    trials: tuple[Trial, ...], run_dirs: tuple[str, ...], key: str, progress: Any
) -> str:
    """Trials that differ only in seed, in one worker (``resources.seeds_per_process``): each
    resumes or starts as :func:`run_trial` would, and they train together
    (:func:`farsighter.seeds.train_seeds`). ``key``: the job's name in ``progress``, where it
    reports -1 when all are done."""
    from farsighter.seeds import train_seeds

    cfgs = [_start(t, Path(d)) for t, d in zip(trials, run_dirs, strict=True)]
    first = [Progress(progress, key, runs=len(cfgs))]  # the seeds of a batch step together
    train_seeds(cfgs, callbacks=[first, *[[] for _ in cfgs[1:]]])
    progress[key] = -1
    return key


def seed_groups(trials: Sequence[Trial], size: int) -> list[list[Trial]]:
    """``trials`` in groups of at most ``size`` that differ only in seed, in the sweep's order."""
    return chunk_by(trials, lambda trial: replace(trial, seed=0), size)


def _start(trial: Trial, path: Path) -> Any:
    """The trial's config, resuming when it has a checkpoint; one line in its attempts log."""
    resume = (path / CHECKPOINT_FILE).exists()
    attempts_log(path).parent.mkdir(parents=True, exist_ok=True)
    with open(attempts_log(path), "a") as log:
        how = "resume" if resume else "fresh"
        log.write(f"{time.time():.3f} {socket.gethostname()} pid {os.getpid()} {how}\n")
    return replace(trial.config(path), resume=resume, overwrite=not resume)


def attempts_log(run_dir: Path) -> Path:
    """``<run dir>.attempts.log`` beside the run directory (a fresh start replaces the run
    directory, not its log): one line per start of the trial (time, host, pid, fresh|resume)."""
    return run_dir.with_name(run_dir.name + ".attempts.log")


def attempts(run_dir: Path) -> int:
    """How many times the trial was started."""
    file = attempts_log(run_dir)
    return len(file.read_text().splitlines()) if file.exists() else 0


# ------------------------------------------------------------------------------------------------
# Outputs
# ------------------------------------------------------------------------------------------------


def variant(trial: Trial) -> str:
    """The trial's agent and swept values: what the aggregate compares (``farsighter k=10``)."""
    return " ".join([trial.agent, *(f"{k}={v}" for k, v in trial.swept)])


def results(spec: SweepSpec, out: Path) -> list[dict[str, Any]]:
    """One row per finished trial, from its summary.json."""
    rows = []
    for trial in spec.trials:
        path = trial_dir(out, trial)
        if not finished(path):
            continue
        summary = json.loads((path / SUMMARY_FILE).read_text())
        rows.append(
            {
                "trial": trial.name,
                "agent": trial.agent,
                "variant": variant(trial),
                "env": trial.env,
                "seed": trial.seed,
                **{k: v for k, v in trial.swept},
                "steps": summary["global_step"],
                # null in summary.json: no finite value (strict JSON has no NaN)
                "final_eval_return": _number(summary["final_eval_return"]),
                "best_eval_return": _number(summary["best_eval_return"]),
                "attempts": attempts(path),
            }
        )
    return rows


def _number(value: float | None) -> float:
    return float("nan") if value is None else float(value)


def normalization(envs: Sequence[str]) -> str:
    """human (every env an ALE game with reference scores), raw (one env), else minmax."""
    from farsighter.envs.atari import game_of
    from farsighter.envs.atari_scores import BASELINES

    if all(game_of(env) in BASELINES for env in envs):
        return "human"
    return "raw" if len(envs) == 1 else "minmax"


def score_table(rows: list[dict[str, Any]], how: str) -> tuple[dict[str, np.ndarray], list[str]]:
    """Per variant a (seeds x envs) array of final evaluation returns, normalised: ``human``
    (Atari: random 0, human 1), ``minmax`` (per env: the lowest run of any variant 0, the highest
    1), or ``raw``. Only the seeds a variant finished on every env are kept."""
    from farsighter.aggregate import minmax_normalized
    from farsighter.envs.atari import game_of
    from farsighter.envs.atari_scores import human_normalized

    envs = sorted({r["env"] for r in rows})
    score = {(r["variant"], r["env"], r["seed"]): float(r["final_eval_return"]) for r in rows}
    if how == "human":
        score = {key: human_normalized(str(game_of(key[1])), v) for key, v in score.items()}
    table = {}
    for name in dict.fromkeys(r["variant"] for r in rows):
        per_env = [{s for (v, e, s) in score if v == name and e == env} for env in envs]
        seeds = sorted(set.intersection(*per_env))
        if seeds:
            table[name] = np.array([[score[(name, env, s)] for env in envs] for s in seeds])
    if how == "minmax" and table:
        table = minmax_normalized(table)
    return table, envs


def write_outputs(spec: SweepSpec, out: Path, run: dict[str, Any] | None = None) -> None:
    rows = results(spec, out)
    if not rows:
        return
    keys = list(dict.fromkeys(k for row in rows for k in row))
    with open(out / "results.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=keys)
        writer.writeheader()
        writer.writerows(rows)
    how = normalization(sorted({r["env"] for r in rows}))
    table, envs = score_table(rows, how)
    agg_md = ""
    if table:
        from farsighter import aggregate

        paths = aggregate.write_outputs(
            out / "aggregate", table, envs, normalized_name=_NORM_TEXT[how]
        )
        agg_md = paths["aggregate_md"].read_text()
    (out / "figures").mkdir(exist_ok=True)
    _plot_curves(spec, out, out / "figures" / "curves.png")
    _report(spec, out, rows, agg_md, how, run)


_NORM_TEXT = {
    "human": "human-normalised score (random 0, human 1)",
    "minmax": "min-max normalised score per environment (lowest run 0, highest 1)",
    "raw": "raw final evaluation return",
}


def _plot_curves(spec: SweepSpec, out: Path, file: Path) -> None:
    from farsighter.plots import band, figure, finish_axes, read_csv

    envs = list(dict.fromkeys(t.env for t in spec.trials))
    with figure(file, 1, len(envs), figsize=(5 * len(envs), 3.6), squeeze=False) as (_, axes):
        for ax, env in zip(axes[0], envs, strict=True):
            curves: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
            for trial in spec.trials:
                path = trial_dir(out, trial) / EVAL_FILE
                if trial.env != env or not path.exists():
                    continue
                data = read_csv(path)
                if len(data.get("global_step", [])):
                    curves.setdefault(variant(trial), []).append(
                        (data["global_step"], data["eval_return_mean"])
                    )
            for name, runs in curves.items():
                n = min(len(x) for x, _ in runs)
                band(ax, runs[0][0][:n], np.stack([y[:n] for _, y in runs]), None, name)
            finish_axes(ax, "environment steps", "evaluation return", env, fontsize=7)


def _report(
    spec: SweepSpec,
    out: Path,
    rows: list[dict[str, Any]],
    agg_md: str,
    how: str,
    run: dict[str, Any] | None,
) -> None:
    from farsighter.plots import markdown_table

    restarts = sum(max(r["attempts"] - 1, 0) for r in rows)
    lines = [
        f"# Sweep {spec.name}",
        "",
        spec.description,
        "",
        f"- Sweep file: `{spec.source}`; {len(spec.trials)} trials, {len(rows)} finished.",
        f"- Restarts (a trial started again after its worker died or raised): {restarts}.",
    ]
    if run:
        lines.append(
            f"- This invocation: {run['trials_run']} trials run on {run['backend']} in "
            f"{run['wall_seconds']:.0f} s."
        )
    lines += ["", "## Final evaluation return per environment (mean ± std over seeds)", ""]
    groups: dict[tuple[str, str], list[float]] = {}
    for r in rows:
        groups.setdefault((r["variant"], r["env"]), []).append(float(r["final_eval_return"]))
    cells = []
    for (name, env), values in groups.items():
        v = np.array(values)
        sd = v.std(ddof=1) if len(v) > 1 else 0.0
        cells.append([name, env, str(len(v)), f"{fmt(float(v.mean()))} ± {fmt(float(sd))}"])
    lines.append(markdown_table(["agent", "environment", "seeds", "final return"], cells))
    if agg_md:
        lines += ["", f"## Across environments ({_NORM_TEXT[how]})", "", agg_md.strip()]
        lines += ["", "![aggregate](aggregate/figures/aggregate.png)"]
    lines += ["", "![curves](figures/curves.png)", ""]
    (out / "report.md").write_text("\n".join(lines))
