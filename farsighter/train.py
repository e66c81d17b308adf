"""The one training loop: any agent, any environment, resumable from its run directory."""

from __future__ import annotations

import json
import pickle
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import gymnasium as gym
import numpy as np
import torch
from tqdm import tqdm

from farsighter.agents import build_agent
from farsighter.config import Config, load_config, validate
from farsighter.envs import check_spaces, frame_stack_of, make_env, make_vector_env
from farsighter.errors import ConfigError, RunDirError
from farsighter.rundir import (
    CONFIG_FILE,
    SUMMARY_FILE,
    RunLogger,
    load_checkpoint,
    prepare_run_dir,
    save_checkpoint,
)

POLICY_FILE = "policy.pt"


def resolve_device(name: str) -> torch.device:
    """auto: CUDA when present, CPU otherwise."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name.startswith("cuda") and not torch.cuda.is_available():
        raise ConfigError(f"device '{name}' requested but CUDA is not available; use --device cpu")
    return torch.device(name)


@dataclass
class LoopState:
    """Counters of the loop, saved in checkpoints."""

    global_step: int = 0
    episodes: int = 0
    evals: int = 0
    best_eval: float = float("-inf")
    last_eval: float = float("nan")
    recent_returns: deque[float] = field(default_factory=lambda: deque(maxlen=20))
    recent_successes: deque[float] = field(default_factory=lambda: deque(maxlen=20))


@dataclass
class EvalResult:
    """Returns of the evaluation episodes, and ``info["is_success"]`` at each episode's end
    (goal-conditioned tasks; empty when the environment does not report it)."""

    returns: list[float]
    successes: list[float]


def evaluate_episodes(
    agent: Any, cfg: Config, env: gym.Env, episodes: int, seed: int, global_step: int
) -> EvalResult:
    """Greedy episodes (eval_epsilon-greedy for discrete actions; the posterior mean / noiseless
    mu for continuous ones) on an unclipped, non-life-loss environment."""
    rng = np.random.default_rng(seed)
    returns: list[float] = []
    successes: list[float] = []
    n_actions = int(env.action_space.n) if isinstance(env.action_space, gym.spaces.Discrete) else 0
    for i in range(episodes):
        obs, info = env.reset(seed=seed if i == 0 else None)
        total, steps, done = 0.0, 0, False
        while not done and steps < cfg.eval_max_steps:
            if n_actions and rng.random() < cfg.eval_epsilon:
                action = int(rng.integers(n_actions))
            else:
                action = agent.act(np.asarray(obs)[None], global_step, explore=False)[0]
            obs, reward, terminated, truncated, info = env.step(action)
            total += float(reward)
            steps += 1
            done = terminated or truncated
        returns.append(total)
        if "is_success" in info:
            successes.append(float(info["is_success"]))
    return EvalResult(returns, successes)


def evaluate(
    agent: Any, cfg: Config, env: gym.Env, episodes: int, seed: int, global_step: int
) -> list[float]:
    """Returns of greedy evaluation episodes (see :func:`evaluate_episodes`)."""
    return evaluate_episodes(agent, cfg, env, episodes, seed, global_step).returns


def _final_obs(info: dict[str, Any], num_envs: int) -> list[Any] | None:
    if "final_obs" not in info:
        return None
    mask = info["_final_obs"]
    return [info["final_obs"][i] if mask[i] else None for i in range(num_envs)]


def _finished_episodes(info: dict[str, Any]) -> list[tuple[float, int]]:
    final = info.get("final_info")
    if not final or "episode" not in final:
        return []
    ep, mask = final["episode"], final["_episode"]
    return [(float(ep["r"][i]), int(ep["l"][i])) for i in np.flatnonzero(mask)]


def _finished_successes(info: dict[str, Any]) -> list[float | None]:
    """``info["is_success"]`` of the episodes of :func:`_finished_episodes`, in the same order
    (None where the environment does not report it)."""
    final = info.get("final_info")
    if not final or "episode" not in final:
        return []
    has = final.get("_is_success")
    return [
        float(final["is_success"][i]) if has is not None and has[i] else None
        for i in np.flatnonzero(final["_episode"])
    ]


def _pickle_envs(envs: gym.vector.VectorEnv) -> bytes | None:
    try:
        return pickle.dumps(envs)
    except Exception:  # e.g. an environment holding an open window or a C handle
        return None


class Callback(Protocol):
    """Observes a run without changing it (studies use it to record what the loop does not)."""

    def on_step(self, global_step: int, info: dict[str, Any], agent: Any) -> None: ...

    def on_finish(self, run_dir: Path, agent: Any) -> None: ...


def train(cfg: Config, callbacks: Sequence[Callback] = ()) -> dict[str, Any]:
    """Train ``cfg.algo`` on ``cfg.env``; returns the run's summary (also in summary.json).

    ``callbacks`` see every vector step's ``info`` and the agent, read-only by contract."""
    validate(cfg)
    device = resolve_device(cfg.device)
    # Make the environments before touching the run directory: a bad id changes nothing.
    envs = make_vector_env(cfg, seed=cfg.seed)
    obs_space, act_space = envs.single_observation_space, envs.single_action_space
    check_spaces(cfg.algo, obs_space, act_space)
    path = prepare_run_dir(cfg)
    checkpoint = load_checkpoint(path) if cfg.resume else None
    if cfg.torch_threads:
        torch.set_num_threads(cfg.torch_threads)

    agent = build_agent(cfg, obs_space, act_space, frame_stack=frame_stack_of(cfg), device=device)
    eval_env = make_env(cfg, seed=cfg.seed + 1_000_003, training=False)
    state = LoopState()
    resumed_loss = float("nan")
    obs: np.ndarray
    if checkpoint is not None:
        agent.load_state_dict(checkpoint["agent"])
        loop = checkpoint["loop"]
        state.global_step, state.episodes, state.evals = (
            loop["global_step"],
            loop["episodes"],
            loop["evals"],
        )
        state.best_eval, state.last_eval = loop["best_eval"], loop["last_eval"]
        state.recent_returns.extend(loop["recent_returns"])
        state.recent_successes.extend(loop.get("recent_successes", []))
        resumed_loss = loop.get("loss_value", float("nan"))
        if checkpoint.get("envs") is not None:
            envs.close()
            envs = pickle.loads(checkpoint["envs"])
            obs = checkpoint["obs"]
        else:  # environment state was not saved: start fresh episodes
            obs, _ = envs.reset(seed=cfg.seed + state.global_step)
    else:
        obs, _ = envs.reset(seed=cfg.seed)

    logger = RunLogger(path, resume_step=state.global_step if checkpoint else None)
    bar = tqdm(
        total=cfg.total_steps,
        initial=state.global_step,
        unit="step",
        disable=not cfg.progress,
        dynamic_ncols=True,
        mininterval=1.0,
        desc=f"{cfg.algo} {cfg.env} s{cfg.seed}",
    )
    sps = 0.0
    loss_value = resumed_loss
    window_start_step, window_start_time = state.global_step, time.perf_counter()
    start_time, start_step = time.perf_counter(), state.global_step
    last_loss: torch.Tensor | None = None
    # Training-phase throughput: measured from the first step at or after learning_starts.
    train_phase: tuple[int, float] | None = None
    next_log = (state.global_step // cfg.log_every + 1) * cfg.log_every

    def checkpoint_now() -> None:
        save_checkpoint(
            path,
            {
                "version": 1,
                "loop": {
                    "global_step": state.global_step,
                    "episodes": state.episodes,
                    "evals": state.evals,
                    "best_eval": state.best_eval,
                    "last_eval": state.last_eval,
                    "recent_returns": list(state.recent_returns),
                    "recent_successes": list(state.recent_successes),
                    "loss_value": loss_value,
                },
                "agent": agent.state_dict(include_replay=cfg.save_replay),
                # Environment state only travels with the replay, whose rows it continues.
                "envs": _pickle_envs(envs) if cfg.save_replay else None,
                "obs": obs,
            },
        )

    def run_eval() -> None:
        state.evals += 1
        result = evaluate_episodes(
            agent,
            cfg,
            eval_env,
            cfg.eval_episodes,
            cfg.seed + 7919 * state.evals,
            state.global_step,
        )
        returns = result.returns
        mean, std = float(np.mean(returns)), float(np.std(returns))
        if result.successes:  # goal-conditioned tasks: eval/success_rate
            rate = float(np.mean(result.successes))
            logger.success(
                {
                    "global_step": state.global_step,
                    "eval_success_rate": rate,
                    "eval_episodes": len(result.successes),
                },
                evaluation=True,
            )
            logger.scalar("eval/success_rate", rate, state.global_step)
        state.last_eval, state.best_eval = mean, max(state.best_eval, mean)
        logger.eval.write(
            {
                "global_step": state.global_step,
                "eval_return_mean": mean,
                "eval_return_std": std,
                "eval_episodes": len(returns),
            }
        )
        logger.scalar("eval/mean_return", mean, state.global_step)
        logger.scalar("eval/std_return", std, state.global_step)

    try:
        while state.global_step < cfg.total_steps:
            actions = agent.act(obs, state.global_step)
            next_obs, rewards, terminated, truncated, info = envs.step(actions)
            agent.observe(
                obs, actions, rewards, terminated, truncated, _final_obs(info, cfg.num_envs)
            )
            obs = next_obs
            prev_step = state.global_step
            state.global_step += cfg.num_envs
            bar.update(cfg.num_envs)

            if train_phase is None and state.global_step >= cfg.learning_starts:
                train_phase = (state.global_step, time.perf_counter())
            metrics = agent.learn(state.global_step)
            if "td_loss" in metrics:
                last_loss = metrics["td_loss"]

            for callback in callbacks:
                callback.on_step(state.global_step, info, agent)
            for (ep_return, ep_length), success in zip(
                _finished_episodes(info), _finished_successes(info), strict=True
            ):
                state.episodes += 1
                if success is not None:  # goal-conditioned tasks: success.csv, not metrics.csv
                    state.recent_successes.append(success)
                    logger.success(
                        {
                            "global_step": state.global_step,
                            "episode": state.episodes,
                            "success": success,
                        }
                    )
                    logger.scalar(
                        "charts/success_rate",
                        float(np.mean(state.recent_successes)),
                        state.global_step,
                    )
                state.recent_returns.append(ep_return)
                diag = agent.diagnostics()
                logger.metrics.write(
                    {
                        "global_step": state.global_step,
                        "episode": state.episodes,
                        "episodic_return": ep_return,
                        "episodic_length": ep_length,
                        "SPS": sps,
                        "loss": loss_value,
                        "epsilon": diag.get("epsilon", float("nan")),
                        "k": diag.get("k", float("nan")),
                    }
                )
                logger.scalar("charts/episodic_return", ep_return, state.global_step)
                logger.scalar("charts/episodic_length", ep_length, state.global_step)

            if state.global_step >= next_log:
                now = time.perf_counter()
                sps = (state.global_step - window_start_step) / max(now - window_start_time, 1e-9)
                window_start_step, window_start_time = state.global_step, now
                next_log += cfg.log_every
                # One host sync per log interval, not per step.
                loss_value = float(last_loss.item()) if last_loss is not None else float("nan")
                logger.scalar("charts/SPS", sps, state.global_step)
                if last_loss is not None:
                    logger.scalar("losses/td_loss", loss_value, state.global_step)
                for name, value in agent.diagnostics().items():
                    logger.scalar(f"charts/{name}", value, state.global_step)
                recent = np.mean(state.recent_returns) if state.recent_returns else float("nan")
                bar.set_postfix(SPS=f"{sps:.0f}", ret=f"{recent:.1f}", refresh=False)

            if cfg.eval_every and prev_step // cfg.eval_every < state.global_step // cfg.eval_every:
                run_eval()
            if (
                cfg.checkpoint_every
                and prev_step // cfg.checkpoint_every < state.global_step // cfg.checkpoint_every
                and state.global_step < cfg.total_steps
            ):
                checkpoint_now()
        loop_end = time.perf_counter()
        if state.evals == 0 or (cfg.eval_every and state.global_step % cfg.eval_every):
            run_eval()  # always finish with an evaluation
        checkpoint_now()
        torch.save(agent.state_dict(include_replay=False), path / POLICY_FILE)
        for callback in callbacks:
            callback.on_finish(path, agent)
    finally:
        bar.close()
        logger.close()
        envs.close()
        eval_env.close()

    end_time = time.perf_counter()
    elapsed = end_time - start_time
    # Periodic evaluations and checkpoints count against it; the final ones do not.
    train_sps = (
        (state.global_step - train_phase[0]) / max(loop_end - train_phase[1], 1e-9)
        if train_phase is not None and state.global_step > train_phase[0]
        else float("nan")
    )
    summary = {
        "algo": cfg.algo,
        "env": cfg.env,
        "seed": cfg.seed,
        "global_step": state.global_step,
        "episodes": state.episodes,
        "final_eval_return": state.last_eval,
        "best_eval_return": state.best_eval,
        "mean_recent_return": float(np.mean(state.recent_returns))
        if state.recent_returns
        else None,
        "wall_seconds": elapsed,
        "sps": (state.global_step - start_step) / max(elapsed, 1e-9),
        "train_phase_sps": train_sps,
        "run_dir": str(path),
    }
    (path / SUMMARY_FILE).write_text(json.dumps(summary, indent=2) + "\n")
    return summary


class Policy:
    """A trained agent loaded from its run directory, for acting."""

    def __init__(self, agent: Any, cfg: Config) -> None:
        self.agent, self.config = agent, cfg

    def act(self, obs: np.ndarray, deterministic: bool = True) -> np.ndarray:
        """Actions for a batch of observations (greedy under the learned Q / posterior mean)."""
        return self.agent.act(np.asarray(obs), 0, explore=not deterministic)

    def make_env(self, seed: int = 0, training: bool = False) -> gym.Env:
        """An environment with the same preprocessing as training (evaluation flavour)."""
        return make_env(self.config, seed=seed, training=training)


def load_agent(run_dir: str | Path, device: str = "cpu") -> Policy:
    """Load a trained agent from a run directory (``policy.pt``, else the last checkpoint)."""
    path = Path(run_dir)
    if not (path / CONFIG_FILE).exists():
        raise RunDirError(f"{path} holds no run (no {CONFIG_FILE})")
    cfg = load_config(path / CONFIG_FILE)
    env = make_env(cfg, seed=0)
    agent = build_agent(
        cfg,
        env.observation_space,
        env.action_space,
        frame_stack=frame_stack_of(cfg),
        device=resolve_device(device),
    )
    env.close()
    if (path / POLICY_FILE).exists():
        state = torch.load(path / POLICY_FILE, map_location="cpu", weights_only=False)
    else:
        state = load_checkpoint(path)["agent"]
    agent.load_state_dict(state)
    return Policy(agent, cfg)
