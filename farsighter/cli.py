"""``farsighter`` command line: train, evaluate, list presets (and run studies).

Bad input prints one line, ``farsighter: error: <what> ...(accepted: ...)``, and exits with 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Sequence

from farsighter.errors import FarsighterError

USAGE = """usage: farsighter <command> [options]

commands:
  maze      the bridge-maze study (paper Fig. 1): farsighter maze [--quick] [--out DIR]
  robotics  the continuous-control study (Fig. 3, Table 3):
            farsighter robotics --env Walker2d-v5 --steps 30000 --seeds 1 2 3 [--quick]
  train     train an agent:   farsighter train --algo farsighter --env CartPole-v1 [--help]
  eval      evaluate a run:   farsighter eval RUN_DIR [--episodes 10]
  plot      draw a run's learning curve:  farsighter plot RUN_DIR
  presets   list the named presets and their sources
"""


def _split_known(argv: Sequence[str], names: Sequence[str]) -> tuple[dict[str, str], list[str]]:
    """Pull ``--name value`` / ``--name=value`` for the given names out of argv."""
    found: dict[str, str] = {}
    rest: list[str] = []
    i = 0
    while i < len(argv):
        arg = argv[i]
        key, eq, value = arg.partition("=")
        name = key[2:] if key.startswith("--") else ""
        if name in names:
            if eq:
                found[name] = value
            elif i + 1 < len(argv):
                found[name] = argv[i + 1]
                i += 1
            else:
                raise FarsighterError(f"--{name} needs a value")
        else:
            rest.append(arg)
        i += 1
    return found, rest


def cmd_train(argv: Sequence[str]) -> int:
    import tyro

    from farsighter.config import Config, make_config
    from farsighter.train import train

    # algo, env and preset choose the defaults (algorithm defaults <- preset), so they are read
    # first; every other flag then overrides a field of that default.
    known, rest = _split_known(argv, ("algo", "env", "preset"))
    default = make_config(
        known.get("algo", "ddqn"), known.get("env", "CartPole-v1"), known.get("preset", "auto")
    )
    cfg = tyro.cli(
        Config,
        default=default,
        args=list(rest),
        prog="farsighter train",
        description="Train an agent. --algo, --env and --preset pick the defaults; any other "
        "field below overrides them.",
    )
    summary = train(cfg)
    print(json.dumps(summary, indent=2))
    return 0


def cmd_eval(argv: Sequence[str]) -> int:
    import numpy as np

    from farsighter.train import evaluate_episodes, load_agent

    parser = argparse.ArgumentParser(prog="farsighter eval", description="Evaluate a trained run.")
    parser.add_argument("run_dir")
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--seed", type=int, default=12345)
    parser.add_argument("--device", default="cpu")
    args = parser.parse_args(list(argv))
    if args.episodes < 1:
        raise FarsighterError(f"--episodes must be >= 1 (got {args.episodes})")
    policy = load_agent(args.run_dir, device=args.device)
    env = policy.make_env(seed=args.seed)
    result = evaluate_episodes(policy.agent, policy.config, env, args.episodes, args.seed, 0)
    env.close()
    returns = result.returns
    report = {
        "run_dir": args.run_dir,
        "episodes": args.episodes,
        "mean_return": float(np.mean(returns)),
        "std_return": float(np.std(returns)),
        "returns": returns,
    }
    if result.successes:  # goal-conditioned tasks report info["is_success"]
        report["success_rate"] = float(np.mean(result.successes))
    print(json.dumps(report, indent=2))
    return 0


def cmd_plot(argv: Sequence[str]) -> int:
    from farsighter.plots import plot_run

    parser = argparse.ArgumentParser(prog="farsighter plot", description="Draw a run's curves.")
    parser.add_argument("run_dir")
    parser.add_argument("--out", default=None, help="PNG path (default RUN_DIR/learning_curve.png)")
    args = parser.parse_args(list(argv))
    print(plot_run(args.run_dir, args.out))
    return 0


def cmd_presets(argv: Sequence[str]) -> int:
    from farsighter.config import ALGO_PINNED, PRESETS

    for p in PRESETS.values():
        print(f"{p.name}: {p.doc}\n  source: {p.source}")
        for key, value in p.values.items():
            print(f"    {key} = {value!r}")
    print("applied after any preset (algorithm-defining; your flags still override them):")
    for algo, values in ALGO_PINNED.items():
        for key, value in values.items():
            print(f"    {algo}: {key} = {value!r}")
    return 0


def cmd_maze(argv: Sequence[str]) -> int:
    from farsighter.studies.maze import main as maze_main

    return maze_main(argv)


def cmd_robotics(argv: Sequence[str]) -> int:
    from farsighter.studies.robotics import main as robotics_main

    return robotics_main(argv)


COMMANDS: dict[str, Callable[[Sequence[str]], int]] = {
    "maze": cmd_maze,
    "robotics": cmd_robotics,
    "train": cmd_train,
    "eval": cmd_eval,
    "plot": cmd_plot,
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
    except KeyboardInterrupt:
        print("farsighter: interrupted; continue the run with --resume", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
