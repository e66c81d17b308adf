"""A run in progress, beside its directory (:mod:`farsighter.rundir`): the loop's counters, the
checkpoint schema (save and restore), what is logged per episode and per interval, evaluation,
and the summary. :func:`farsighter.train.train` composes these into the loop.

Evaluation (:mod:`farsighter.evaluation`) and what a vector step's results say
(:mod:`farsighter.step_info`) live beside this module and are re-exported from it.
"""

from __future__ import annotations

import json
import math
import pickle
import sys
import time
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import gymnasium as gym
import numpy as np
import torch
from tqdm import tqdm

from farsighter import jsonio
from farsighter.agents import Agent
from farsighter.config import Config
from farsighter.envs.video import VIDEO_DIR, EvalVideo, eval_video
from farsighter.errors import Diverged, RunDirError
from farsighter.evaluation import (  # noqa: F401  (re-exported)
    EVAL_MAX_ENVS,
    EvalResult,
    eval_step_cap,
    evaluate_episodes,
)
from farsighter.policy_file import policy_state
from farsighter.rundir import SUMMARY_FILE, RunLogger, load_checkpoint, save_checkpoint
from farsighter.step_info import (  # noqa: F401  (re-exported)
    check_transition,
    final_observations,
    finished_episodes,
)
from farsighter.tracking import VIDEO_TAG, run_trackers

POLICY_FILE = "policy.pt"  # what acting needs of the trained agent (farsighter.policy_file)
CHECKPOINT_VERSION = 2  # 2: agents save their counters as one dataclass (v0.3)
RECENT = 20  # episodes in the progress bar's and the summary's recent mean
NO_EPISODE_NOTICE = 10_000  # steps without one ended episode after which the run says so, once


class Callback(Protocol):
    """Observes a training run without changing it: ``farsighter.train(cfg, callbacks=[...])``
    (:func:`farsighter.seeds.train_seeds` takes one list per seed; studies use them to record
    what the loop does not).

    * ``on_step(global_step, info, agent)``: after every vector step, before its episodes are
      logged. ``global_step`` counts environment steps summed over the vector environments;
      ``info`` is the vector environment's info dict (``info["final_info"]["episode"]`` holds
      the episodes that ended); ``agent`` is read-only by contract.
    * ``on_finish(run_dir, agent)``: once, after the final evaluation, checkpoint and policy
      file (not for a run that stops early).
    * optionally ``on_scalar(tag, value, step)``: every scalar the run writes to TensorBoard,
      with its tag and step (``charts/episodic_return``, ``losses/td_loss``,
      ``eval/mean_return``, ...), in the order logged, delivered when the logs are written out
      (at least every 2 seconds, before each checkpoint, and all of them before ``on_finish``).
      A resume delivers again what was logged after its checkpoint.

    :class:`BaseCallback` has each hook do nothing: subclass it and override what you need."""

    def on_step(self, global_step: int, info: dict[str, Any], agent: Agent) -> None: ...

    def on_finish(self, run_dir: Path, agent: Agent) -> None: ...


class BaseCallback:
    """A :class:`Callback` whose hooks do nothing, ``on_scalar`` included: override those you
    need."""

    def on_step(self, global_step: int, info: dict[str, Any], agent: Agent) -> None:
        """After every vector step (:class:`Callback`)."""

    def on_finish(self, run_dir: Path, agent: Agent) -> None:
        """Once, at the end of a run that finished (:class:`Callback`)."""

    def on_scalar(self, tag: str, value: float, step: int) -> None:
        """Each scalar the run writes to TensorBoard (:class:`Callback`)."""


@dataclass
class LoopState:
    """Counters of the loop, saved in checkpoints as a whole."""

    global_step: int = 0
    episodes: int = 0
    evals: int = 0
    best_eval: float = float("-inf")
    last_eval: float = float("nan")
    loss_value: float = float("nan")  # the TD loss read at the latest log interval
    recent_returns: deque[float] = field(default_factory=lambda: deque(maxlen=RECENT))
    recent_successes: deque[float] = field(default_factory=lambda: deque(maxlen=RECENT))

    def to_dict(self) -> dict[str, Any]:
        out = dict(vars(self))
        out["recent_returns"], out["recent_successes"] = (
            list(self.recent_returns),
            list(self.recent_successes),
        )
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> LoopState:
        state = cls(**{k: v for k, v in data.items() if not k.startswith("recent_")})
        state.recent_returns.extend(data["recent_returns"])
        state.recent_successes.extend(data["recent_successes"])
        return state


def passed_multiple(before: int, after: int, every: int) -> bool:
    """True when a multiple of ``every`` lies in (before, after]; never when ``every`` is 0."""
    return bool(every) and before // every < after // every


# --------------------------------------------------------------------------------------------
# Checkpoints: the loop's counters, the agent, and the environments with their observation.
# --------------------------------------------------------------------------------------------


def save_run(
    path: Path, cfg: Config, state: LoopState, agent: Agent, envs: gym.vector.VectorEnv, obs: Any
) -> None:
    save_checkpoint(
        path,
        {
            "version": CHECKPOINT_VERSION,
            "loop": state.to_dict(),
            "agent": agent.state_dict(include_replay=cfg.save_replay),
            # Environment state only travels with the replay, whose rows it continues.
            "envs": _pickle_envs(envs) if cfg.save_replay else None,
            "obs": obs,
        },
    )


def restore_run(
    path: Path,
    cfg: Config,
    agent: Agent,
    envs: gym.vector.VectorEnv,
    checkpoint: dict[str, Any] | None = None,
) -> tuple[LoopState, gym.vector.VectorEnv, Any]:
    """Load the last checkpoint (``checkpoint``: it, read already) into ``agent``; returns the
    loop state, the environments (those saved, or ``envs`` reset to fresh episodes when they
    were not) and the observation."""
    if checkpoint is None:
        checkpoint = load_checkpoint(path)
    version = checkpoint.get("version", 1)
    if version != CHECKPOINT_VERSION:
        raise RunDirError(
            f"checkpoint in {path} has format {version}, this version reads format "
            f"{CHECKPOINT_VERSION}; finish it with the version that wrote it or start afresh "
            "with --overwrite"
        )
    agent.load_state_dict(checkpoint["agent"])
    state = LoopState.from_dict(checkpoint["loop"])
    if checkpoint.get("envs") is None:  # environment state was not saved: fresh episodes
        obs, _ = envs.reset(seed=cfg.seed + state.global_step)
        return state, envs, obs
    envs.close()
    return state, pickle.loads(checkpoint["envs"]), checkpoint["obs"]


def _pickle_envs(envs: gym.vector.VectorEnv) -> bytes | None:
    try:
        return pickle.dumps(envs)
    except Exception:  # e.g. an environment holding an open window or a C handle
        return None


# --------------------------------------------------------------------------------------------
# What a run writes as it goes.
# --------------------------------------------------------------------------------------------


def episode_diagnostics(agent: Agent) -> dict[str, float]:
    """What an episode's metrics row reads of the agent (epsilon, k): its
    ``episode_diagnostics()`` where it has one (what it can say without costly work: Farsighter's
    Q-variance waits for the log interval), else its ``diagnostics()``."""
    cheap = getattr(agent, "episode_diagnostics", None)
    return cheap() if callable(cheap) else agent.diagnostics()


def no_episode_notice(cfg: Config, step: int) -> str:
    """The line a run prints once when ``step`` steps have ended no episode: with a hint when
    the environment has no time limit of its own and none was given."""
    line = f"farsighter: no episode of {cfg.env} has ended in {step:,} steps"
    try:
        limit = gym.spec(cfg.env).max_episode_steps
    except gym.error.Error:  # module:EnvId, or an id registered by its own package on make
        limit = -1
    if limit is None and not cfg.max_episode_steps:
        line += (
            f"; {cfg.env} has no time limit, so an episode lasts until the task ends it: give "
            "one with --max-episode-steps N"
        )
    return line


class RunLog:
    """Episode rows, log-interval scalars (SPS, loss, diagnostics), evaluations, the progress
    bar and the summary of one run; reopened consistently on resume. Its scalars also reach the
    ``on_scalar`` hooks of ``callbacks`` and, with ``track``, Weights & Biases
    (:mod:`farsighter.tracking`)."""

    def __init__(
        self,
        path: Path,
        cfg: Config,
        state: LoopState,
        resumed: bool,
        callbacks: Sequence[Callback] = (),
    ) -> None:
        self.path, self.cfg = path, cfg
        self.finished = False  # set at the end of finish(): a run closed before is not
        self.logger = RunLogger(
            path,
            resume_step=state.global_step if resumed else None,
            trackers=run_trackers(cfg, path, resumed, callbacks),
        )
        try:
            self.eval_envs = _make_eval_envs(cfg, path)
        except BaseException:
            self.logger.close(failed=True)
            raise
        self.bar = tqdm(
            total=cfg.total_steps,
            initial=state.global_step,
            unit="step",
            disable=not cfg.progress,
            dynamic_ncols=True,
            mininterval=1.0,
            desc=f"{cfg.algo} {cfg.env} s{cfg.seed}",
        )
        now = time.perf_counter()
        self.start = self.window = (state.global_step, now)
        self.loop_end = now
        # Training-phase throughput: measured from the first step at or after learning_starts.
        self.train_phase: tuple[int, float] | None = None
        self.next_log = (state.global_step // cfg.log_every + 1) * cfg.log_every
        self.sps = 0.0
        self.last_loss: torch.Tensor | None = None
        self.noticed = False

    def step(
        self, state: LoopState, info: dict[str, Any], metrics: dict[str, torch.Tensor], agent: Agent
    ) -> None:
        """After one vector step: episodes that ended, and the log interval when it is due."""
        self.bar.update(self.cfg.num_envs)
        if self.train_phase is None and state.global_step >= self.cfg.learning_starts:
            self.train_phase = (state.global_step, time.perf_counter())
        self.last_loss = metrics.get("td_loss", self.last_loss)
        for ep_return, ep_length, success in finished_episodes(info):
            self.episode(state, ep_return, ep_length, success, agent)
        if state.global_step >= self.next_log:
            self.interval(state, agent)

    def episode(
        self,
        state: LoopState,
        ep_return: float,
        ep_length: int,
        success: float | None,
        agent: Agent,
    ) -> None:
        state.episodes += 1
        log, step = self.logger, state.global_step
        if success is not None:  # goal-conditioned tasks: success.csv, not metrics.csv
            state.recent_successes.append(success)
            log.success({"global_step": step, "episode": state.episodes, "success": success})
            log.scalar("charts/success_rate", float(np.mean(state.recent_successes)), step)
        state.recent_returns.append(ep_return)
        diag = episode_diagnostics(agent)
        log.metrics.write(
            {
                "global_step": step,
                "episode": state.episodes,
                "episodic_return": ep_return,
                "episodic_length": ep_length,
                "SPS": self.sps,
                "loss": state.loss_value,
                "epsilon": diag.get("epsilon", float("nan")),
                "k": diag.get("k", float("nan")),
            }
        )
        log.scalar("charts/episodic_return", ep_return, step)
        log.scalar("charts/episodic_length", ep_length, step)

    def interval(self, state: LoopState, agent: Agent) -> None:
        """SPS, the TD loss (one host sync per interval, not per step) and the diagnostics."""
        log, step, now = self.logger, state.global_step, time.perf_counter()
        self.sps = (step - self.window[0]) / max(now - self.window[1], 1e-9)
        self.window = (step, now)
        self.next_log += self.cfg.log_every
        log.scalar("charts/SPS", self.sps, step)
        loss = self.last_loss
        state.loss_value = float(loss.item()) if loss is not None else float("nan")
        if loss is not None:
            if not math.isfinite(state.loss_value):
                raise Diverged(f"the TD loss is {state.loss_value} at step {step}")
            log.scalar("losses/td_loss", state.loss_value, step)
        for name, value in agent.diagnostics().items():
            log.scalar(f"charts/{name}", value, step)
        recent = np.mean(state.recent_returns) if state.recent_returns else float("nan")
        self.bar.set_postfix(SPS=f"{self.sps:.0f}", ret=f"{recent:.1f}", refresh=False)
        if state.episodes == 0 and step >= NO_EPISODE_NOTICE and not self.noticed:
            self.noticed = True
            tqdm.write(no_episode_notice(self.cfg, step), file=sys.stderr)

    def evaluate(self, state: LoopState, agent: Agent) -> None:
        """One evaluation phase: eval.csv, eval_success.csv (goal tasks) and TensorBoard."""
        cfg, log, step = self.cfg, self.logger, state.global_step
        state.evals += 1
        seed = cfg.seed + 7919 * state.evals
        video, name = self.eval_envs[0], f"eval-step-{step}"
        if isinstance(video, EvalVideo):  # --capture-video: this evaluation's first episode
            video.arm(name)
        try:
            result = evaluate_episodes(
                agent, cfg, self.eval_envs, cfg.eval_episodes, seed, step, progress=cfg.progress
            )
        finally:
            if isinstance(video, EvalVideo):
                video.finish()
        file = self.path / VIDEO_DIR / f"{name}.mp4"
        if isinstance(video, EvalVideo) and file.is_file():  # for the trackers (W&B)
            log.video(VIDEO_TAG, file, step)
        mean, std = float(np.mean(result.returns)), float(np.std(result.returns))
        if result.successes:
            rate = float(np.mean(result.successes))
            row = {"global_step": step, "eval_success_rate": rate}
            log.success({**row, "eval_episodes": len(result.successes)}, evaluation=True)
            log.scalar("eval/success_rate", rate, step)
        state.last_eval, state.best_eval = mean, max(state.best_eval, mean)
        log.eval.write(
            {
                "global_step": step,
                "eval_return_mean": mean,
                "eval_return_std": std,
                "eval_episodes": len(result.returns),
            }
        )
        log.scalar("eval/mean_return", mean, step)
        log.scalar("eval/std_return", std, step)

    def after_step(
        self,
        state: LoopState,
        prev_step: int,
        info: dict[str, Any],
        metrics: dict[str, torch.Tensor],
        agent: Agent,
        envs: gym.vector.VectorEnv,
        obs: Any,
        callbacks: Sequence[Callback],
    ) -> None:
        """What follows a vector step (from ``prev_step`` to ``state.global_step``): the
        callbacks, :meth:`step`, and the evaluation and the checkpoint when one is due."""
        cfg, step = self.cfg, state.global_step
        for callback in callbacks:
            callback.on_step(step, info, agent)
        self.step(state, info, metrics, agent)
        if passed_multiple(prev_step, step, cfg.eval_every):
            self.evaluate(state, agent)
        if passed_multiple(prev_step, step, cfg.checkpoint_every) and step < cfg.total_steps:
            self.checkpoint(state, agent, envs, obs)

    def checkpoint(
        self, state: LoopState, agent: Agent, envs: gym.vector.VectorEnv, obs: Any
    ) -> None:
        """A checkpoint after the step just logged (periodic, or on an interrupt): the logs up
        to it reach the disk first, so a resume from it keeps them and repeats none."""
        self.logger.flush()
        save_run(self.path, self.cfg, state, agent, envs, obs)

    def finish(
        self,
        state: LoopState,
        agent: Agent,
        envs: gym.vector.VectorEnv,
        obs: Any,
        callbacks: Sequence[Callback],
    ) -> None:
        """After the last step: a final evaluation unless one was just made, the last
        checkpoint, the policy file, and the callbacks' ``on_finish``."""
        cfg = self.cfg
        self.end_of_training()
        if state.evals == 0 or (cfg.eval_every and state.global_step % cfg.eval_every):
            self.evaluate(state, agent)  # always finish with an evaluation
        self.logger.flush()
        save_run(self.path, cfg, state, agent, envs, obs)
        torch.save(policy_state(agent, cfg.algo), self.path / POLICY_FILE)
        for callback in callbacks:
            callback.on_finish(self.path, agent)
        self.finished = True

    def end_of_training(self) -> None:
        """Marks the end of the steps (the final evaluation and checkpoint do not count in SPS)."""
        self.loop_end = time.perf_counter()

    def summary(self, state: LoopState) -> dict[str, Any]:
        """The run's summary, also written to summary.json."""
        elapsed = time.perf_counter() - self.start[1]
        phase = self.train_phase
        train_sps = (
            (state.global_step - phase[0]) / max(self.loop_end - phase[1], 1e-9)
            if phase is not None and state.global_step > phase[0]
            else float("nan")
        )
        summary = run_summary(self.cfg, self.path, state)
        run_dir = summary.pop("run_dir")
        summary.update(
            wall_seconds=elapsed,
            sps=(state.global_step - self.start[0]) / max(elapsed, 1e-9),
            train_phase_sps=train_sps,
            run_dir=run_dir,
        )
        (self.path / SUMMARY_FILE).write_text(jsonio.dumps(summary) + "\n")
        return summary

    def close(self) -> None:
        """The bar, the logs and the trackers (a W&B run ends as failed unless :meth:`finish`
        completed), and the evaluation environments."""
        self.bar.close()
        try:
            self.logger.close(failed=not self.finished)
        finally:
            for env in self.eval_envs:
                env.close()


def run_summary(cfg: Config, path: Path, state: LoopState) -> dict[str, Any]:
    """What the summary says of a run at ``state`` (the timings aside)."""
    recent = state.recent_returns
    return {
        "algo": cfg.algo,
        "env": cfg.env,
        "seed": cfg.seed,
        "global_step": state.global_step,
        "episodes": state.episodes,
        "final_eval_return": state.last_eval,
        "best_eval_return": state.best_eval,
        "mean_recent_return": float(np.mean(recent)) if recent else None,
        "run_dir": str(path),
    }


def nothing_to_resume(cfg: Config, checkpoint: Mapping[str, Any]) -> dict[str, Any] | None:
    """A resume (``cfg.resume``) that asks for no more steps than its checkpoint has done: one
    line on stderr saying so, and the run's summary (summary.json's, when the run finished at
    that step), with nothing in the run directory changed. None when steps are left, or when
    the checkpoint is at ``total_steps`` but the run did not finish there (stopped in its final
    evaluation or files: the resume completes them)."""
    path, done = cfg.resolved_run_dir, int(checkpoint["loop"]["global_step"])
    if cfg.total_steps > done:
        return None
    try:
        saved = json.loads((path / SUMMARY_FILE).read_text())
    except (OSError, ValueError):
        saved = None
    finished = isinstance(saved, dict) and saved.get("global_step") == done
    if not finished and cfg.total_steps == done:
        return None
    again = "give a larger --total-steps to continue it"
    if finished:
        line = f"the run in {path} has finished its {done:,} steps; nothing to do ({again})"
    else:
        line = (
            f"the run in {path} has done {done:,} steps, more than --total-steps "
            f"{cfg.total_steps:,}; nothing to do ({again})"
        )
    print(f"farsighter: {line}", file=sys.stderr)
    if finished:
        assert isinstance(saved, dict)
        return saved
    return run_summary(cfg, path, LoopState.from_dict(checkpoint["loop"]))


def _make_eval_envs(cfg: Config, path: Path) -> list[gym.Env]:
    """The evaluation environments of a run; with ``capture_video`` the first renders frames and
    records (:class:`~farsighter.envs.video.EvalVideo`) into ``path / videos``."""
    from farsighter.envs import make_eval_envs

    count = min(cfg.eval_episodes, EVAL_MAX_ENVS)
    envs = make_eval_envs(
        cfg,
        count,
        seed=cfg.seed + 1_000_003,
        render_mode="rgb_array" if cfg.runtime.capture_video else None,
    )
    if cfg.runtime.capture_video:
        try:
            envs[0] = eval_video(envs[0], path / VIDEO_DIR)
        except BaseException:
            for env in envs[1:]:
                env.close()
            raise
    return envs
