"""``farsighter`` command line: train, evaluate, list presets (and run studies).

Bad input prints one line, ``farsighter: error: <what> ...(accepted: ...)``, and exits with 2.
"""

from __future__ import annotations

import dataclasses
import os
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import tyro

from farsighter import jsonio
from farsighter.cli_args import parse_flags
from farsighter.config import Config, load_config, make_config, resolve_preset_name, validate
from farsighter.errors import ConfigError, FarsighterError, Interrupted, RunDirError
from farsighter.rundir import CONFIG_FILE, check_same_run

USAGE = """usage: farsighter <command> [options]

commands:
  maze      the bridge-maze study (paper Fig. 1): farsighter maze [--quick] [--out DIR]
  robotics  the continuous-control study (Fig. 3, Table 3):
            farsighter robotics --env Walker2d-v5 --steps 30000 --seeds 1 2 3 [--quick]
  explore   the exploration suite (chain, MiniGrid, MountainCar at growing sizes):
            farsighter explore [--quick] [--families chain doorkey] [--sizes 5 10] [--out DIR]
  suite     the exploration suite's normalised scores, one aggregate (IQM) per selection and
            validation set: farsighter suite [--quick] [--set selection] [--families chain]
  k-study   the sweep over k (Fig. 4) with adaptive k, on the bridge maze or any discrete task:
            farsighter k-study [--quick] [--envs farsighter/BridgeMaze-v0 CartPole-v1] [--out DIR]
  atari     the Atari study (Fig. 2, Table 2), on ALE games or MinAtar:
            farsighter atari --games Breakout Pong --steps 100000 [--quick]
            farsighter atari --games minatar --steps 200000 --seeds 1 2
  sweep     run a sweep file (grid of agents x envs x seeds x any field), locally or on Ray:
            farsighter sweep benchmarks/sweeps/k-study.toml [--ray [--address ADDR]]
  train     train an agent:   farsighter train --algo farsighter --env CartPole-v1 [--help]
            continue a run:   farsighter train --run-dir DIR --resume [--total-steps N]
            several seeds:    farsighter train --algo ddqn --seeds 1 2 3 4  (one process;
                              batched where the agent allows it, each seed its own run dir)
  eval      evaluate a run:   farsighter eval RUN_DIR [--episodes 10] [--seed S]
            watch or record:  farsighter eval RUN_DIR --render human | --video DIR
  plot      draw a run's learning curve:  farsighter plot RUN_DIR
  inspect   probe trained runs' values (action gaps, Q against Q* or the returns that followed):
            farsighter inspect <probe> RUN_DIR [RUN_DIR ...]  (farsighter inspect --help)
  presets   list the named presets and their sources
"""


@dataclass(frozen=True)
class TrainLead:
    """The flags ``farsighter train`` reads before the others: they choose the default config."""

    algo: str = Config.algo
    """Algorithm whose values start the config."""
    env: str = Config.env
    """Environment id (chooses the ``auto`` preset)."""
    preset: str = Config.preset
    """Preset of the defaults (auto: by environment and algorithm)."""
    seed: int = Config.seed
    """Seed (with --resume and no --run-dir: names the run directory to continue)."""
    run_dir: str = Config.run_dir
    """Run directory (with --resume: the run to continue)."""
    resume: bool = Config.resume
    """Continue the run in run_dir with its saved config."""


@dataclass(frozen=True)
class EvalArgs:
    """Evaluate a trained run greedily and print the returns as JSON."""

    run_dir: Annotated[str, tyro.conf.Positional, tyro.conf.arg(metavar="RUN_DIR")]
    """Run directory written by ``farsighter train``."""
    episodes: int = 10
    """Evaluation episodes (>= 1)."""
    seed: int = 12345
    """Seed of the evaluation environment."""
    device: str = "cpu"
    """cpu, cuda, cuda:N or auto."""
    render: str = ""
    """Render the episodes, one at a time: human (a window) or rgb_array (frames; what --video
    records)."""
    video: Annotated[str, tyro.conf.arg(metavar="DIR")] = ""
    """Record every episode into DIR as an .mp4 (gymnasium's RecordVideo; needs moviepy: pip
    install 'farsighter[video]')."""
    env_kwargs: Annotated[tuple[str, ...] | None, tyro.conf.arg(metavar="NAME=VALUE ...")] = None
    """The environment's constructor arguments for this evaluation instead of the run's own
    (``is_slippery=True``: how a policy trained without slipping fares with it)."""


RENDER_MODES = ("human", "rgb_array")


@dataclass(frozen=True)
class PlotArgs:
    """Draw a run's learning curve (training episode returns and evaluation returns)."""

    run_dir: Annotated[str, tyro.conf.Positional, tyro.conf.arg(metavar="RUN_DIR")]
    """Run directory written by ``farsighter train``."""
    out: Annotated[str | None, tyro.conf.arg(metavar="PATH")] = None
    """PNG path (default RUN_DIR/learning_curve.png)."""


def _without_help(argv: Sequence[str]) -> list[str]:
    return [a for a in argv if a not in ("-h", "--help")]


def train_config(argv: Sequence[str]) -> Config:
    """The config of ``farsighter train ARGV``, in two tyro passes.

    The first pass reads only :class:`TrainLead` (every other flag is left for later) to build
    the default: ``make_config(algo, env, preset)``, or with ``--resume`` the config saved in the
    run directory (``--run-dir``, else ``runs/<env>__<algo>__s<seed>``). The second pass parses
    the whole command line over :class:`Config` with that default, so ``--help`` lists every
    field and each given flag overrides one field; a changed field that a resume may not change
    is refused by :func:`farsighter.rundir.prepare_run_dir`.
    """
    prog = "farsighter train"
    lead, _ = parse_flags(TrainLead, _without_help(argv), prog, return_unknown_args=True)
    if lead.resume:
        path = (
            Path(lead.run_dir)
            if lead.run_dir
            else Config(algo=lead.algo, env=lead.env, seed=lead.seed).default_run_dir()
        )
        if not (path / CONFIG_FILE).is_file():
            raise RunDirError(f"cannot resume: {path} holds no run (no {CONFIG_FILE})")
        default = dataclasses.replace(
            load_config(path / CONFIG_FILE), resume=True, overwrite=False, run_dir=str(path)
        )
        description = f"Continue the run in {path}: its saved config is the default below; "
        description += "give only the flags that change (such as --total-steps)."
    else:
        default = make_config(lead.algo, lead.env, lead.preset)
        description = "Train an agent. --algo, --env and --preset pick the defaults; any other "
        description += "field below overrides them. --resume continues a run with its saved config."
    cfg = parse_flags(Config, argv, prog, default=default, description=description)
    if lead.resume:  # another --algo or --env: said so before a preset or a check that follows
        check_same_run(cfg, saved=default)
    if cfg.preset != default.preset:  # given again: store the resolved name, as make_config does
        cfg = dataclasses.replace(cfg, preset=resolve_preset_name(cfg.preset, cfg.env, cfg.algo))
    return cfg


def split_seeds(argv: Sequence[str]) -> tuple[list[str], list[int] | None]:
    """``argv`` without ``--seeds N [N ...]``, and those seeds (None when not given)."""
    args = list(argv)
    if "--seeds" not in args:
        return args, None
    at = args.index("--seeds")
    end = at + 1
    while end < len(args) and not args[end].startswith("--"):
        end += 1
    values = args[at + 1 : end]
    bad = [v for v in values if not v.lstrip("-").isdigit()]
    if bad or not values:
        raise ConfigError(
            f"--seeds takes one or more whole numbers (got {' '.join(values) or 'none'})"
        )
    return args[:at] + args[end:], [int(v) for v in values]


def cmd_train(argv: Sequence[str]) -> int:
    """Training, where SIGINT (Ctrl-C) and SIGTERM save a checkpoint after the step in progress
    and exit with 130 and 143 (:mod:`farsighter.interrupt`)."""
    from farsighter.interrupt import stop_on_signal

    with stop_on_signal():
        return _train_command(argv)


def _train_command(argv: Sequence[str]) -> int:
    from farsighter.seeds import seed_configs, train_seeds
    from farsighter.train import train

    rest, seeds = split_seeds(argv)
    if seeds is None:
        summary = train(train_config(rest))
        print(jsonio.dumps(summary))
        return 0
    lead, _ = parse_flags(
        TrainLead, _without_help(rest), "farsighter train", return_unknown_args=True
    )
    if lead.resume:  # each seed's saved config, from its own directory
        dirs = [c.run_dir for c in seed_configs(Config(run_dir=lead.run_dir), seeds)]
        cfgs = [
            train_config([*rest, "--seed", str(s), *(["--run-dir", d] if d else [])])
            for s, d in zip(seeds, dirs, strict=True)
        ]
    else:
        cfgs = seed_configs(train_config(rest), seeds)
    summaries = train_seeds(cfgs)
    print(jsonio.dumps(summaries))
    return 0


def cmd_eval(argv: Sequence[str]) -> int:
    import numpy as np

    from farsighter.envs import make_eval_envs
    from farsighter.envs.video import check_video, record_episodes
    from farsighter.session import EVAL_MAX_ENVS
    from farsighter.train import evaluate_episodes, load_agent

    args = parse_flags(EvalArgs, argv, "farsighter eval")
    if args.episodes < 1:
        raise FarsighterError(f"--episodes must be >= 1 (got {args.episodes})")
    if args.render and args.render not in RENDER_MODES:
        raise ConfigError(f"unknown --render '{args.render}'; accepted: {', '.join(RENDER_MODES)}")
    if args.video and args.render == "human":
        raise ConfigError(
            "--video records rgb_array frames and --render human shows a window; give one of them"
        )
    if args.video:
        check_video()  # without moviepy: one line naming the extra, before anything is loaded
    policy = load_agent(args.run_dir, device=args.device)
    if args.env_kwargs is not None:  # the run's environment made otherwise
        policy.config = dataclasses.replace(policy.config, env_kwargs=args.env_kwargs)
        validate(policy.config)
        with policy.make_env(seed=args.seed) as probe:
            space = probe.observation_space
        if space != policy.observation_space:
            raise ConfigError(
                f"with --env-kwargs {' '.join(args.env_kwargs)} the environment observes "
                f"{space}; the run's agent takes {policy.observation_space}"
            )
    cfg = policy.config
    if args.video or args.render:  # one environment that renders, its episodes in turn
        env = policy.make_env(
            seed=args.seed, render_mode="rgb_array" if args.video else args.render
        )
        envs = [record_episodes(env, args.video) if args.video else env]
    else:
        envs = make_eval_envs(cfg, min(args.episodes, EVAL_MAX_ENVS), seed=args.seed)
    try:
        result = evaluate_episodes(
            policy.agent, cfg, envs, args.episodes, args.seed, 0, progress=cfg.progress
        )
    finally:
        for env in envs:
            env.close()
    returns = result.returns
    report = {
        "run_dir": args.run_dir,
        "env_kwargs": list(cfg.env_kwargs),
        "episodes": args.episodes,
        "mean_return": float(np.mean(returns)),
        "std_return": float(np.std(returns)),
        "returns": returns,
    }
    if result.successes:  # goal-conditioned tasks report info["is_success"]
        report["success_rate"] = float(np.mean(result.successes))
    if args.video:  # written as each episode ended, the last one on close
        report["videos"] = sorted(str(p) for p in Path(args.video).glob("*.mp4"))
    print(jsonio.dumps(report))
    return 0


def cmd_plot(argv: Sequence[str]) -> int:
    from farsighter.plots import plot_run

    args = parse_flags(PlotArgs, argv, "farsighter plot")
    print(plot_run(args.run_dir, args.out))
    return 0


@dataclass(frozen=True)
class PresetsArgs:
    """List the named presets with their sources, then every algorithm with the values that
    define it; with --algo, the values a run of that algorithm gets instead, each with where it
    comes from. A config is built in five layers: field defaults <- preset <- algorithm <- the
    preset's values for that algorithm <- your flags (a preset made for one algorithm, such as
    bdqn, comes after that algorithm's values)."""

    algo: str = ""
    """Show the values a run of this algorithm gets (with --env and --preset), and their source."""
    env: str = "CartPole-v1"
    """The environment id of --algo's run (auto picks the preset from it)."""
    preset: str = "auto"
    """The preset of --algo's run."""
    all: bool = False
    """With --algo: also the fields left at their defaults."""


def cmd_presets(argv: Sequence[str]) -> int:
    from farsighter import algorithms
    from farsighter.config import PRESETS, explain_config, resolve_preset_name

    args = parse_flags(PresetsArgs, argv, "farsighter presets")
    if args.algo:
        rows = explain_config(args.algo, args.env, args.preset)
        name = resolve_preset_name(args.preset, args.env, args.algo)
        print(f"--algo {args.algo} --env {args.env} --preset {args.preset} (resolves to {name}):")
        width = max(len(key) for key, _, _ in rows)
        for key, value, source in rows:
            if args.all or source != "field default":
                print(f"  {key:<{width}} = {value!r:<24} ({source})")
        if not args.all:
            print("  (every other field at its default: --all lists them)")
        return 0
    for p in PRESETS.values():
        only = f" (for --algo {p.algo} only; applied over its values)" if p.algo else ""
        print(f"{p.name}{only}: {p.doc}\n  source: {p.source}")
        for key, value in p.values.items():
            print(f"    {key} = {value!r}")
        for name, values in p.per_algo.items():
            print(f"    for --algo {name} (over its values):")
            for key, value in values.items():
                print(f"      {key} = {value!r}")
    print("\nalgorithms (their values apply after a preset; your flags still override them):")
    for algo in algorithms.TABLE:
        print(f"{algo.name} [{algo.actions} actions]: {algo.summary}")
        for key, value in algo.defaults.items():
            print(f"    {key} = {value!r}")
    return 0


def cmd_inspect(argv: Sequence[str]) -> int:
    from farsighter.probes import main as inspect_main

    return inspect_main(argv)


def cmd_maze(argv: Sequence[str]) -> int:
    from farsighter.studies.maze import main as maze_main

    return maze_main(argv)


def cmd_robotics(argv: Sequence[str]) -> int:
    from farsighter.studies.robotics import main as robotics_main

    return robotics_main(argv)


def cmd_explore(argv: Sequence[str]) -> int:
    from farsighter.studies.explore import main as explore_main

    return explore_main(argv)


def cmd_suite(argv: Sequence[str]) -> int:
    from farsighter.studies.suite import main as suite_main

    return suite_main(argv)


def cmd_k_study(argv: Sequence[str]) -> int:
    from farsighter.studies.kstudy import main as k_study_main

    return k_study_main(argv)


def cmd_sweep(argv: Sequence[str]) -> int:
    from farsighter.sweep.run import main as sweep_main

    return sweep_main(argv)


def cmd_atari(argv: Sequence[str]) -> int:
    from farsighter.studies.atari import main as atari_main

    return atari_main(argv)


COMMANDS: dict[str, Callable[[Sequence[str]], int]] = {
    "maze": cmd_maze,
    "robotics": cmd_robotics,
    "explore": cmd_explore,
    "suite": cmd_suite,
    "k-study": cmd_k_study,
    "atari": cmd_atari,
    "sweep": cmd_sweep,
    "train": cmd_train,
    "eval": cmd_eval,
    "plot": cmd_plot,
    "inspect": cmd_inspect,
    "presets": cmd_presets,
}


def main(argv: Sequence[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] in ("-h", "--help"):
        print(USAGE)
        return 0
    command = COMMANDS.get(args[0])
    if command is None:
        print(
            f"farsighter: error: unknown command '{args[0]}'; accepted: {', '.join(COMMANDS)}",
            file=sys.stderr,
        )
        return 2
    try:
        return command(args[1:])
    except FarsighterError as exc:
        print(f"farsighter: error: {exc}", file=sys.stderr)
        return 2
    except Interrupted as exc:  # farsighter train: saved, or stopped by a second signal
        print(f"farsighter: {exc}", file=sys.stderr)
        return 128 + exc.signum
    except KeyboardInterrupt:
        print("farsighter: interrupted; continue the run with --resume", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `farsighter train --help | head`: the reader left, quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # (the exit's flush)
        return 141  # 128 + SIGPIPE, as a shell reports a writer whose reader left


if __name__ == "__main__":
    sys.exit(main())
