"""Hash the trained weights of short runs of every algorithm (the refactoring check of issue #11).

A refactoring that changes no behaviour leaves every trained tensor byte-identical. This script
trains each run below for a few thousand steps on CPU with one thread and hashes what the agent
saves (the agent's state in ``checkpoint.pt``, written without the replay: what ``policy.pt`` held
before it kept only what acting needs): every floating-point tensor and array, hashed one by one
and combined as a sorted multiset, so renaming or regrouping the state does not change the hash,
any changed value does. Run it before and after a change and compare:

    python -m benchmarks.weights_hash --name weights_hash_before
    python -m benchmarks.weights_hash --name weights_hash_after --compare weights_hash_before
"""

from __future__ import annotations

import argparse
import hashlib
import json
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import torch

from benchmarks.common import RESULTS, write_result
from farsighter.config import make_config
from farsighter.train import train

CARTPOLE = {
    "preset": "cartpole",
    "learning_starts": 500,
    "target_update_every": 250,
    "blr.posterior_every": 500,
    "blr.posterior_samples": 1_000,
    "hidden_sizes": (32, 32),
}
PENDULUM = {
    "preset": "continuous",
    "learning_starts": 300,
    "naf.elbo_batch": 64,
    "batch_size": 64,
    "naf.hidden_sizes": (32, 16),
}
MAZE = {  # the maze study's shared settings, written out so this check does not move with them
    "preset": "control",
    "gamma": 1.0,
    "optimizer": "adam",
    "lr": 0.001,
    "optim_eps": 1e-8,
    "batch_size": 64,
    "buffer_size": 50_000,
    "learning_starts": 1_000,
    "target_update_every": 500,
    "eps_decay_steps": 10_000,
    "blr.posterior_every": 1_000,
    "blr.posterior_samples": 5_000,
    "blr.prior_std": 10.0,
    "blr.noise_std": 10.0,
}
GENERAL = {"preset": "auto", "learning_starts": 500}
ADAPTIVE = {"adaptive_k.enabled": True, "adaptive_k.k_min": 2, "adaptive_k.k_max": 12}

# name: (algo, env, steps, overrides)
RUNS: dict[str, tuple[str, str, int, dict[str, Any]]] = {
    "ddqn-cartpole": ("ddqn", "CartPole-v1", 3_000, CARTPOLE),
    "kddqn-cartpole": ("kddqn", "CartPole-v1", 3_000, CARTPOLE),
    "bdqn-cartpole": ("bdqn", "CartPole-v1", 3_000, CARTPOLE),
    "bdqn-preset-cartpole": (
        "bdqn",
        "CartPole-v1",
        3_000,
        {**CARTPOLE, "preset": "bdqn", "target_update_every": 250},
    ),
    "farsighter-cartpole": ("farsighter", "CartPole-v1", 3_000, CARTPOLE),
    "farsighter-stride-cartpole": (
        "farsighter",
        "CartPole-v1",
        3_000,
        {**CARTPOLE, "stride": True},
    ),
    "farsighter-adaptive-cartpole": ("farsighter", "CartPole-v1", 3_000, {**CARTPOLE, **ADAPTIVE}),
    "farsighter-incremental-cartpole": (
        "farsighter",
        "CartPole-v1",
        3_000,
        {**CARTPOLE, "blr.mode": "incremental", "blr.forgetting": 0.99},
    ),
    "ob2i-cartpole": ("ob2i", "CartPole-v1", 3_000, CARTPOLE),
    "rnd-cartpole": ("rnd", "CartPole-v1", 3_000, CARTPOLE),
    "krnd-cartpole": ("krnd", "CartPole-v1", 3_000, CARTPOLE),
    "ddqn-cartpole-2envs": ("ddqn", "CartPole-v1", 3_000, {**CARTPOLE, "num_envs": 2}),
    "naf-pendulum": ("naf", "Pendulum-v1", 1_500, PENDULUM),
    "knaf-pendulum": ("knaf", "Pendulum-v1", 1_500, {**PENDULUM, "naf.noise": "ou"}),
    "bnaf-pendulum": ("bnaf", "Pendulum-v1", 1_500, PENDULUM),
    "farsighter-naf-pendulum": ("farsighter-naf", "Pendulum-v1", 1_500, PENDULUM),
    "farsighter-naf-adaptive-pendulum": (
        "farsighter-naf",
        "Pendulum-v1",
        1_500,
        {**PENDULUM, **ADAPTIVE, "naf.elbo_every": 300, "naf.soft_update": "every_n"},
    ),
    "ddqn-maze": ("ddqn", "farsighter/BridgeMaze-v0", 4_000, MAZE),
    "bdqn-maze": ("bdqn", "farsighter/BridgeMaze-v0", 4_000, {**MAZE, "blr.redraw": "episode"}),
    "farsighter-maze": ("farsighter", "farsighter/BridgeMaze-v0", 4_000, {**MAZE, "k": 10}),
    "ob2i-maze": ("ob2i", "farsighter/BridgeMaze-v0", 4_000, MAZE),
    # the library's defaults (auto: the general preset; Farsighter over learned and random
    # features, incremental posterior refreshed every 100 steps, draws held for k)
    "ddqn-general-deepsea": ("ddqn", "farsighter/DeepSea10-v0", 3_000, GENERAL),
    "farsighter-general-deepsea": ("farsighter", "farsighter/DeepSea10-v0", 3_000, GENERAL),
    "bdqn-general-deepsea": ("bdqn", "farsighter/DeepSea10-v0", 3_000, GENERAL),
    # the defaults past their first positive reward (the chain L = 8 pays within the run): the
    # switch to the posterior mean's target cut before exploratory actions (blr.optimism)
    "farsighter-general-chain": ("farsighter", "farsighter/Chain8-v0", 3_000, GENERAL),
    # ... and past a first positive reward after its first update (the chain L = 10 pays at step
    # 1,208, learning_starts 1,000): the posterior refitted to the replay (blr.switch_restart)
    "farsighter-general-chain10": ("farsighter", "farsighter/Chain10-v0", 3_000, GENERAL),
    # ... and where a step can leave the agent where it was (FrozenLake's walls): no draw in a
    # target whose window ends where it began (blr.stay_optimism False, session 40)
    "farsighter-general-frozenlake": ("farsighter", "FrozenLake-v1", 3_000, GENERAL),
    # ... and where an episode after one that ran to its time limit comes back to a state (the
    # drifting lock: a wrong move goes one state back): a uniform action there
    # (blr.revisit_action uniform-timeout, session 42)
    "farsighter-general-driftchain": ("farsighter", "farsighter/DriftChain8-v0", 3_000, GENERAL),
}


def _drop(state: Any, keys: frozenset[str]) -> Any:
    """``state`` without the dict entries named in ``keys``, at any depth."""
    if isinstance(state, dict):
        return {k: _drop(v, keys) for k, v in state.items() if k not in keys}
    if isinstance(state, list | tuple):
        return [_drop(v, keys) for v in state]
    return state


def _leaves(state: Any) -> list[bytes]:
    """Bytes of every floating-point tensor / array in a nested state (order-free)."""
    if isinstance(state, torch.Tensor):
        return (
            [state.detach().cpu().contiguous().numpy().tobytes()]
            if state.is_floating_point()
            else []
        )
    if isinstance(state, np.ndarray):
        return [np.ascontiguousarray(state).tobytes()] if state.dtype.kind == "f" else []
    if isinstance(state, dict):
        return [b for v in state.values() for b in _leaves(v)]
    if isinstance(state, list | tuple):
        return [b for v in state for b in _leaves(v)]
    return []


def weights_hash(state: Any) -> tuple[str, int]:
    """sha256 over the sorted sha256s of the leaves, and the number of leaves."""
    digests = sorted(hashlib.sha256(b).hexdigest() for b in _leaves(state))
    return hashlib.sha256("".join(digests).encode()).hexdigest(), len(digests)


def run_hash(name: str, root: Path, ignore: frozenset[str] = frozenset()) -> dict[str, Any]:
    algo, env, steps, overrides = RUNS[name]
    values = dict(overrides)
    preset = values.pop("preset")
    cfg = make_config(
        algo,
        env,
        preset=preset,
        seed=3,
        total_steps=steps,
        run_dir=str(root / name),
        save_replay=False,  # the checkpoint's agent state: what policy.pt held before
        progress=False,
        device="cpu",
        torch_threads=1,
        eval_every=0,
        eval_episodes=1,
        checkpoint_every=0,
        **values,
    )
    summary = train(cfg)
    saved = torch.load(root / name / "checkpoint.pt", map_location="cpu", weights_only=False)
    state = saved["agent"]
    digest, leaves = weights_hash(_drop(state, ignore))
    return {"sha256": digest, "tensors": leaves, "final_eval_return": summary["final_eval_return"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--name", default="weights_hash", help="results file name")
    parser.add_argument("--compare", default="", help="an earlier results file name to compare")
    parser.add_argument("--only", nargs="*", default=None, help="run names (default: all)")
    parser.add_argument(
        "--ignore-keys",
        nargs="*",
        default=[],
        help="state entries to leave out of the hash (a statistic a change adds: its other "
        "tensors can still be compared with a run from before it)",
    )
    args = parser.parse_args()
    names = args.only or list(RUNS)
    torch.set_num_threads(1)
    with tempfile.TemporaryDirectory() as tmp:
        runs = {name: run_hash(name, Path(tmp), frozenset(args.ignore_keys)) for name in names}
    figures: dict[str, Any] = {"runs": runs, "ignored_keys": args.ignore_keys}
    if args.compare:
        before = json.loads((RESULTS / f"{args.compare}.json").read_text())["runs"]
        same = {n: before[n]["sha256"] == r["sha256"] for n, r in runs.items() if n in before}
        figures["compared_with"] = args.compare
        figures["identical"] = same
        figures["new_runs"] = [n for n in runs if n not in before]  # nothing to compare with
        figures["all_identical"] = all(same.values()) and len(same) == len(runs)
    write_result(args.name, figures)
    if args.compare and not figures["all_identical"]:
        differ = [n for n, s in same.items() if not s]
        said = [f"trained weights differ: {', '.join(differ)}" if differ else "no weights differ"]
        if figures["new_runs"]:
            said.append(f"not in {args.compare}: {', '.join(figures['new_runs'])}")
        raise SystemExit("; ".join(said))


if __name__ == "__main__":
    main()
