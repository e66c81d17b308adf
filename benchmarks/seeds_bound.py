"""How far seeds in one process can go: the learning arithmetic's bound on S seeds' speed-up.

Issue #27 asks 16 seeds of one config in one process to train at 8x the steps/s of one seed
alone, on 2 cores. Batching shares what a step pays in Python and dispatch; it cannot share the
arithmetic, since every seed has its own weights and its own minibatch. So if one seed alone
spends a fraction f of its step in its updates' arithmetic, S seeds batched run at most 1 / f
times one seed's steps/s per core, however lean the rest.

This measures that bound for a task and an agent, in one process and one torch thread (and two,
for the second core):

* ``alone_sps``: one seed's steps/s, a real run (``farsighter.train.train``, the final
  evaluation excluded, as :mod:`benchmarks.seeds_sps` counts it);
* ``update_ms``: one update of that seed's agent (median), on a replay filled with the task's
  own transitions (uniform actions);
* ``update_ms_seed_batch``: one update of the S seeds as the library batches them
  (``Algorithm.seed_batch``: each seed's products computed as it computes them alone);
* ``update_ms_all_rows``: one update of the same agent with S times the minibatch: the S seeds'
  rows through one network: less work than the S seeds' (one product over all rows instead of
  S smaller ones, and one set of weights for the optimizer where S seeds have S), so a time no
  batched form of them can beat;
* Farsighter: ``refresh_ms``, one posterior refresh (Eq. 9, a Cholesky factor and a triangular
  inverse per action): each seed refreshes its own posterior, so S of them per period.

The bound: an S-seed batch step costs at least ``update_ms_all_rows / train_every`` plus
``S refresh_ms / posterior_every``, with nothing for acting, environments, replay writes or logs,
so ``bound_ratio = S * step_alone / that`` is an upper bound on what any batched form reaches;
``bound_ratio_seed_batch_update`` is the same with the library's batched update in place of the
one-network one.

    python -m benchmarks.seeds_bound [--tasks cartpole deepsea] [--algos ddqn farsighter]
        [--seeds 16] [--name seeds_bound]
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
from collections.abc import Callable
from typing import Any

import numpy as np
import torch

from benchmarks.common import cpu_model, median_ms, write_result
from benchmarks.seeds_sps import GOAL, TASKS, run_one, task_spec


def fill(
    envs: list[Any], cfgs: list[Any], observe: Callable[[list[Any]], None], steps: int
) -> None:
    """``steps`` vector steps of uniform actions in each seed's environments (``envs[s]``, reset
    with ``cfgs[s].seed``), handed to ``observe`` as one VectorStep a seed; the envs closed."""
    from farsighter.replay import VectorStep
    from farsighter.session import final_observations

    n, num_envs = int(envs[0].single_action_space.n), cfgs[0].num_envs
    rng = np.random.default_rng(0)
    obs = [e.reset(seed=c.seed)[0] for e, c in zip(envs, cfgs, strict=True)]
    for _ in range(steps):
        vector_steps = []
        for s, e in enumerate(envs):
            actions = rng.integers(0, n, size=num_envs)
            next_obs, rewards, terminated, truncated, info = e.step(actions)
            final = final_observations(info, num_envs)
            vector_steps.append(VectorStep(obs[s], actions, rewards, terminated, truncated, final))
            obs[s] = next_obs
        observe(vector_steps)
    for e in envs:
        e.close()


def filled_agent(cfg: Any, batch_size: int, transitions: int) -> Any:
    """The config's agent over a seed axis of one (``build_seed_agents``: its ``update`` is one
    update) with ``batch_size`` rows a minibatch, its replay filled with ``transitions`` steps
    of uniform actions in the task's own environment."""
    from farsighter.agents import build_seed_agents
    from farsighter.envs import frame_stack_of, make_vector_env

    cfg = dataclasses.replace(cfg, batch_size=batch_size)
    envs = make_vector_env(cfg, seed=cfg.seed)
    agent = build_seed_agents(
        [cfg],
        envs.single_observation_space,
        envs.single_action_space,
        frame_stack=frame_stack_of(cfg),
        device=torch.device("cpu"),
    )
    fill([envs], [cfg], agent.observe, transitions)
    return agent


def filled_batch(cfg: Any, seeds: int, transitions: int) -> Any:
    """The seed-batched form of the config's agent (``Algorithm.seed_batch``) for seeds
    1..S, each seed's streams filled with ``transitions`` uniform steps of its own environment."""
    from farsighter.agents import build_seed_agents
    from farsighter.envs import make_vector_env
    from farsighter.seeds import seed_configs

    cfgs = seed_configs(cfg, list(range(1, seeds + 1)))
    envs = [make_vector_env(c, seed=c.seed) for c in cfgs]
    batch = build_seed_agents(
        cfgs,
        envs[0].single_observation_space,
        envs[0].single_action_space,
        frame_stack=1,
        device=torch.device("cpu"),
    )
    fill(envs, cfgs, batch.observe, transitions)
    return batch


def measure(task: str, algo: str, seeds: int, repeats: int) -> dict[str, Any]:
    from benchmarks.seeds_sps import _config

    env_id, steps, values = task_spec(task)
    torch.set_num_threads(1)
    alone = run_one(env_id, steps, values, 0, 1, algo)
    with tempfile.TemporaryDirectory() as tmp:
        cfg = _config(env_id, steps, values, tmp, 1, algo)
    fill = max(cfg.learning_starts, seeds * cfg.batch_size + 100)
    one = filled_agent(cfg, cfg.batch_size, fill)
    rows = filled_agent(cfg, seeds * cfg.batch_size, fill)
    batch = filled_batch(cfg, seeds, max(cfg.learning_starts, cfg.batch_size + 100))
    out: dict[str, Any] = {
        "task": task,
        "env": env_id,
        "algo": algo,
        "preset": cfg.preset,
        "seeds": seeds,
        "batch_size": cfg.batch_size,
        "train_every": cfg.train_every,
        "alone_sps": alone["total_sps"],
    }
    step_alone_us = 1e6 / alone["total_sps"]
    for threads in (1, 2):
        torch.set_num_threads(threads)
        upd = median_ms(one.update, repeats)
        upd_rows = median_ms(rows.update, repeats)
        floor_us = 1e3 * upd_rows / cfg.train_every
        upd_batch = median_ms(batch.update, max(5, repeats // 4))
        entry: dict[str, Any] = {
            "update_ms": round(upd, 3),
            "update_ms_all_rows": round(upd_rows, 3),
            "update_ms_seed_batch": round(upd_batch, 3),
        }
        learning_alone_us = 1e3 * upd / cfg.train_every
        if algo == "farsighter":
            refresh = median_ms(one.refresh_posterior, max(5, repeats // 10), warmup=1)
            entry["refresh_ms"] = round(refresh, 3)
            floor_us += 1e3 * seeds * refresh / cfg.blr.posterior_every
            learning_alone_us += 1e3 * refresh / cfg.blr.posterior_every
        entry["batch_step_floor_us"] = round(floor_us, 1)
        # the same bound with the seed batch's own update (its products keep each seed's bits)
        batch_us = floor_us + 1e3 * (upd_batch - upd_rows) / cfg.train_every
        entry["bound_ratio_seed_batch_update"] = round(seeds * step_alone_us / batch_us, 2)
        # the share of a step alone that its learning arithmetic takes (the bound is about 1 / it)
        entry["learning_share_alone"] = round(learning_alone_us / step_alone_us, 3)
        entry["bound_ratio"] = round(seeds * step_alone_us / floor_us, 2)
        out[f"threads_{threads}"] = entry
    torch.set_num_threads(1)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tasks", nargs="+", default=["cartpole", "deepsea"], choices=TASKS)
    parser.add_argument(
        "--algos", nargs="+", default=["ddqn", "farsighter"], choices=["ddqn", "farsighter"]
    )
    parser.add_argument("--seeds", type=int, default=16)
    parser.add_argument("--repeats", type=int, default=100)
    parser.add_argument("--name", default="seeds_bound")
    args = parser.parse_args()
    import torch._dynamo  # noqa: F401  (the optimizers import it once; not a run's cost)

    results = [
        measure(task, algo, args.seeds, args.repeats) for task in args.tasks for algo in args.algos
    ]
    for r in results:
        print(
            f"{r['algo']:>10} {r['task']:>8}: alone {r['alone_sps']:8.1f} steps/s; "
            f"{r['seeds']} seeds at most {r['threads_1']['bound_ratio']}x (one thread), "
            f"{r['threads_2']['bound_ratio']}x (two); with the batch's own update "
            f"{r['threads_1']['bound_ratio_seed_batch_update']}x, "
            f"{r['threads_2']['bound_ratio_seed_batch_update']}x; goal {GOAL}x"
        )
    write_result(args.name, {"cpu": cpu_model(), "goal_ratio": GOAL, "results": results})


if __name__ == "__main__":
    main()
