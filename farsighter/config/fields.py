"""The fields of a run's configuration: frozen dataclasses with a docstring per field (tyro turns
those into ``--help`` text), one per agent family beside the run's own.

The run's own is :class:`Config`, here; the sections it holds live in
:mod:`~farsighter.config.fields_blr` (the BLR head, adaptive k) and
:mod:`~farsighter.config.fields_sections` (Atari, NAF, OB2I, RND, runtime), and are re-exported
from this module."""

from __future__ import annotations

import ast
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal

import tyro

from farsighter.config.fields_blr import AdaptiveKConfig, BLRConfig
from farsighter.config.fields_sections import (
    AtariConfig,
    NAFConfig,
    OB2IConfig,
    RNDConfig,
    RuntimeConfig,
)

KTarget = Literal["k", "max", "max-mean", "cut"]
"""The values of ``Config.k_target``."""
RESERVED_ENV_KWARGS = {
    "render_mode": "each use chooses it (training, evaluation, video)",
    "max_episode_steps": "the field max_episode_steps sets it",
}
"""gymnasium.make's keywords that ``Config.env_kwargs`` leaves to the library, and why."""


def env_kwargs_dict(items: tuple[str, ...]) -> dict[str, Any]:
    """``Config.env_kwargs`` as gymnasium.make's keywords: each VALUE as the Python literal it
    reads as (False, 8, 0.5, 'x', [1, 2]), else as its text (``map_name=8x8``)."""
    out: dict[str, Any] = {}
    for item in items:
        name, _, text = item.partition("=")
        try:
            out[name.strip()] = ast.literal_eval(text.strip())
        except (ValueError, SyntaxError):
            out[name.strip()] = text.strip()
    return out


def env_kwargs_problem(items: tuple[str, ...]) -> str:
    """What is wrong with ``Config.env_kwargs`` ('' when nothing)."""
    names: list[str] = []
    for item in items:
        name, equals, _ = item.partition("=")
        name = name.strip()
        if not equals or not name.isidentifier():
            return f"env_kwargs takes NAME=VALUE items such as is_slippery=False (got {item!r})"
        if name in RESERVED_ENV_KWARGS:
            return f"env_kwargs cannot set {name}: {RESERVED_ENV_KWARGS[name]}"
        if name in names:
            return f"env_kwargs sets {name} twice"
        names.append(name)
    return ""


@dataclass(frozen=True)
class Config:
    """One training run: everything needed to reproduce it."""

    algo: str = "ddqn"
    """Algorithm: one of ddqn, kddqn, bdqn, farsighter, ob2i, rnd, krnd (discrete actions); naf,
    knaf, bnaf, farsighter-naf (continuous). farsighter.algorithms is the table."""
    env: str = "CartPole-v1"
    """Any Gymnasium id, passed to gymnasium.make unchanged (``module:EnvId`` works)."""
    seed: int = 1
    """Seed of the run (networks, exploration, replay sampling, environments)."""
    total_steps: int = 100_000
    """Environment steps to train for (summed over vectorised environments)."""
    run_dir: str = ""
    """Run directory; empty means runs/<env>__<algo>__s<seed>."""
    preset: str = "auto"
    """Preset the defaults came from (auto: atari for Atari ids, continuous for the NAF agents,
    general otherwise)."""
    resume: bool = False
    """Continue the run in run_dir from its last checkpoint."""
    overwrite: bool = False
    """Delete an existing run_dir and start afresh."""
    num_envs: int = 1
    """Environments stepped together (acting is batched over them)."""
    max_episode_steps: int = 0
    """Time limit of an episode, in agent steps, for the training and evaluation environments
    (``gymnasium.make(env, max_episode_steps=N)``, which truncates the episode); 0 keeps the
    environment's own. A task registered without one (CliffWalking-v1) otherwise runs each
    episode until the task itself ends it, which an agent that has not yet learned the way may
    never do. Not for ALE ids (atari.max_frames_per_episode caps those)."""
    env_kwargs: tuple[str, ...] = ()
    """Arguments of the environment's constructor, ``NAME=VALUE`` each (``is_slippery=False
    map_name=8x8``), given to gymnasium.make for training and evaluation; a VALUE that reads as
    a Python literal (False, 8, 0.5, 'x', [1, 2]) is that value, any other is its text."""

    # ----- learning (paper Table 1 unless noted) -----
    optimizer: Literal["rmsprop", "adam"] = "rmsprop"
    """Optimizer of the representation. Table 1: RMSProp."""
    lr: float = 0.0025
    """Learning rate. Table 1: 0.0025."""
    rmsprop_alpha: float = 0.95
    """RMSProp decay of the (squared) gradient averages; Table 1's 'momentum 0.95'."""
    rmsprop_centered: bool = True
    """Centered RMSProp (Graves 2013) as in DQN, whose 'gradient momentum' Table 1 reuses."""
    optim_eps: float = 0.01
    """Epsilon of the optimizer (DQN's 'min squared gradient' 0.01 for RMSProp)."""
    gamma: float = 0.99
    """Discount factor. Table 1: 0.99."""
    k: int = 1
    """Steps per return: 1 is one-step TD; k > 1 uses k-step returns with gamma^k bootstraps."""
    k_target: KTarget = "k"
    """k: the k-step target (section 4.4). max (bdqn, farsighter): the larger of the k-step and
    the one-step target of each sampled start. A k-step return follows the behaviour for k steps,
    so an exploratory episode that ended early makes it pessimistic and stops optimism from
    propagating; in a deterministic task every realised return is a lower bound on Q*, and the
    max keeps the one-step optimality target while the k-step return still carries found reward
    k steps back at once (lower-bound Q-learning, Tang 2020). Biased upwards where rewards or
    transitions are noisy; one more forward pass per update. max-mean: the one of the two whose
    value under the posterior mean is larger, with its draw (``blr.target sample``'s noise does
    not choose, so the max of two draws adds no optimism of its own). cut (farsighter): the
    k-step return stopped before the first action the behaviour took that the posterior mean's
    greedy policy would not have (recorded when acting; a Thompson draw's choice that differs
    from the mean's, and every uniform action before ``learning_starts``), bootstrapping from
    the state where it was taken: Watkins's Q(lambda) cut at k steps. Like max it keeps an
    exploratory detour from making the target pessimistic, without the max's upward bias (the
    larger of two noisy estimates), which adds up over 1 / (1 - gamma) bootstraps into a bonus
    for not ending the episode (docs/design.md, "The plainest MiniGrid room"); no extra forward
    pass. Our extension, not the paper's."""
    stride: bool = False
    """Algorithm 1 literally: one k-step tuple per k steps instead of one starting at every step."""
    batch_size: int = 32
    """Minibatch size of the representation update. Table 1: 32."""
    buffer_size: int = 1_000_000
    """Replay capacity in transitions. Table 1: 1M."""
    sample_recent: bool = False
    """Draw minibatches only from the latest `recent_window` transitions (Algorithm 1 line 4)."""
    recent_window: int = 0
    """Size of that window; 0 means N = target_update_every, as the paper says."""
    learning_starts: int = 1_000
    """Environment steps of pure exploration before the first update."""
    train_every: int = 4
    """Environment steps between representation updates. Table 1: 4."""
    target_update_every: int = 1_000
    """N: steps between target network copies. Table 1: 1k control, 10k Atari."""
    loss: Literal["huber", "mse"] = "huber"
    """TD loss: mse is Eq. 3 literally; huber is DQN's error clipping, more stable."""
    max_grad_norm: float = 10.0
    """Gradient norm clip (0 disables)."""
    eps_start: float = 1.0
    """Initial epsilon of epsilon-greedy exploration (ddqn, kddqn)."""
    eps_end: float = 0.05
    """Final epsilon."""
    eps_decay_steps: int = 10_000
    """Steps of the linear decay from eps_start to eps_end."""
    hidden_sizes: tuple[int, ...] = (64, 64)
    """MLP torso for flat observations (images use the Nature CNN, appendix 9.1.1)."""

    # ----- evaluation, logging, checkpoints -----
    eval_every: int = 10_000
    """Steps between evaluation phases (0 disables periodic evaluation)."""
    eval_episodes: int = 10
    """Episodes per evaluation phase."""
    eval_epsilon: float = 0.0
    """Epsilon of the evaluation policy (greedy under the posterior mean for Bayesian agents)."""
    eval_max_steps: int = 27_000
    """Cap on agent steps of one evaluation episode (27,000 = 108,000 frames at frame skip 4).
    ALE ids are also truncated by the emulator at atari.max_frames_per_episode frames, which
    binds first. A run shorter than the cap is no protocol run: its evaluation episodes are
    capped at total_steps // eval_episodes, so that an evaluation plays at most as many steps
    as the run trains."""
    checkpoint_every: int = 25_000
    """Steps between checkpoints (0: only at the end)."""
    save_replay: bool = True
    """Store the replay buffer in checkpoints, so a resumed run equals an uninterrupted one."""
    log_every: int = 1_000
    """Steps between SPS/loss rows in TensorBoard."""
    progress: bool = True
    """Show a progress bar (steps, SPS, recent return)."""

    runtime: Annotated[RuntimeConfig, tyro.conf.OmitArgPrefixes] = field(
        default_factory=RuntimeConfig
    )
    """How the run is computed: device, precision, the update's fast paths, threads."""
    blr: BLRConfig = field(default_factory=BLRConfig)
    """Bayesian linear regression head (bdqn, farsighter)."""
    adaptive_k: AdaptiveKConfig = field(default_factory=AdaptiveKConfig)
    """Adaptive k (farsighter)."""
    atari: AtariConfig = field(default_factory=AtariConfig)
    """Atari preprocessing (applied automatically to ALE ids)."""
    ob2i: OB2IConfig = field(default_factory=OB2IConfig)
    """OB2I heads, bonus and backward update (ob2i)."""
    rnd: RNDConfig = field(default_factory=RNDConfig)
    """Random network distillation bonus (rnd, krnd)."""
    naf: NAFConfig = field(default_factory=NAFConfig)
    """Continuous-action agents (naf, knaf, bnaf, farsighter-naf)."""

    def checks(self) -> list[tuple[bool, str]]:
        """(holds, what was wrong and what is accepted) for each of the run's own fields; each
        section checks its own (``checks`` beside its fields), and farsighter.config.checks
        what depends on the algorithm."""
        kwargs_problem = env_kwargs_problem(self.env_kwargs)
        return [
            (not kwargs_problem, kwargs_problem),
            (self.k >= 1, f"k must be an integer >= 1 (got {self.k})"),
            (self.lr > 0, f"lr must be > 0 (got {self.lr})"),
            (self.buffer_size > 0, f"buffer_size must be > 0 (got {self.buffer_size})"),
            (self.batch_size > 0, f"batch_size must be > 0 (got {self.batch_size})"),
            (
                self.batch_size <= self.buffer_size,
                f"batch_size ({self.batch_size}) must not exceed buffer_size ({self.buffer_size})",
            ),
            (self.total_steps > 0, f"total_steps must be > 0 (got {self.total_steps})"),
            (self.num_envs >= 1, f"num_envs must be >= 1 (got {self.num_envs})"),
            (
                self.max_episode_steps >= 0,
                "max_episode_steps must be >= 0 (0: the environment's own time limit; got "
                f"{self.max_episode_steps})",
            ),
            (0.0 <= self.gamma <= 1.0, f"gamma must be in [0, 1] (got {self.gamma})"),
            (self.train_every >= 1, f"train_every must be >= 1 (got {self.train_every})"),
            (
                self.target_update_every >= 1,
                f"target_update_every must be >= 1 (got {self.target_update_every})",
            ),
            (
                self.learning_starts >= 0,
                f"learning_starts must be >= 0 (got {self.learning_starts})",
            ),
            (
                0.0 <= self.eps_end <= 1.0 and 0.0 <= self.eps_start <= 1.0,
                "eps_start and eps_end must be in [0, 1]",
            ),
            (0.0 <= self.eval_epsilon <= 1.0, "eval_epsilon must be in [0, 1]"),
            (self.eps_decay_steps >= 0, "eps_decay_steps must be >= 0"),
            (self.recent_window >= 0, "recent_window must be >= 0 (0 means target_update_every)"),
            (
                self.effective_recent_window <= self.buffer_size,
                f"recent window ({self.effective_recent_window}) must not exceed buffer_size "
                f"({self.buffer_size})",
            ),
            (  # max(.., 1): the list is built whole, so a bad num_envs must not divide by zero here
                self.k <= self.buffer_size // max(self.num_envs, 1),
                f"k ({self.k}) must not exceed the per-environment buffer "
                f"({self.buffer_size // max(self.num_envs, 1)})",
            ),
            (all(h > 0 for h in self.hidden_sizes), "hidden_sizes must be positive integers"),
            (self.eval_episodes >= 1, "eval_episodes must be >= 1"),
            (
                self.eval_every >= 0,
                f"eval_every must be >= 0 (0: no periodic evaluation; got {self.eval_every})",
            ),
            (self.eval_max_steps >= 1, f"eval_max_steps must be >= 1 (got {self.eval_max_steps})"),
            (self.log_every >= 1, f"log_every must be >= 1 (got {self.log_every})"),
            (self.checkpoint_every >= 0, "checkpoint_every must be >= 0"),
        ]

    @property
    def effective_recent_window(self) -> int:
        """Window of Algorithm 1 line 4 (N when `recent_window` is 0)."""
        return self.recent_window or self.target_update_every

    def default_run_dir(self) -> Path:
        safe_env = self.env.replace("/", "-").replace(":", "-")
        return Path("runs") / f"{safe_env}__{self.algo}__s{self.seed}"

    @property
    def resolved_run_dir(self) -> Path:
        return Path(self.run_dir) if self.run_dir else self.default_run_dir()
