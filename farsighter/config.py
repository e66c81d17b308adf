"""Typed run configuration, named presets and their sources.

A run is a pure function of its :class:`Config` and seed. Configs are frozen dataclasses with a
docstring per field (tyro turns those into ``--help`` text). Presets are named sets of field
values whose numbers cite their source; ``make_config`` layers them as

    field defaults  <-  preset  <-  algorithm  <-  preset for that algorithm  <-  explicit overrides

where "algorithm" is the values that define it (:mod:`farsighter.algorithms`), so a preset's
generic schedule never replaces them. A preset made for one algorithm (``Preset.algo``, e.g.
``bdqn``: that algorithm as its authors' code ran) is that algorithm's own variant: it is only
accepted with it and applies over its values. Nothing mutates a config after it is built.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from farsighter import algorithms
from farsighter.errors import ConfigError


@dataclass(frozen=True)
class BLRConfig:
    """Bayesian linear regression head (paper section 4.2, Eq. 7 and 9)."""

    prior_std: float = 0.1
    """sigma in Eq. 9: the prior is N(0, sigma^2 I). Paper Table 1: 0.1."""
    noise_std: float = 1.0
    """sigma_eps in Eq. 9: the likelihood noise is N(0, sigma_eps^2). Paper Table 1: 1."""
    cov_scale: float = 1.0
    """Multiplies the posterior covariance used for Thompson draws (BDQN code: the prior variance)."""
    posterior_every: int = 10_000
    """M: environment steps between posterior refreshes. Paper Table 1: M = 10 N."""
    posterior_samples: int = 1_000
    """D: most recent transitions used by a batch-mode refresh. Table 1: 1k control, 100k Atari."""
    mode: Literal["batch", "incremental"] = "batch"
    """batch: recompute Phi Phi^T from D tuples each refresh; incremental: running statistics."""
    forgetting: float = 1.0
    """Incremental mode: statistics are multiplied by this before each accumulation (1 = none)."""
    scale: Literal["fixed", "residual"] = "fixed"
    """fixed: sigma and sigma_eps are the constants above (the paper). residual: at every refresh
    sigma_eps = max(noise_std, RMS residual of the regression targets under the posterior mean)
    and sigma = sigma_eps * prior_std / noise_std, so the posterior follows the scale of the
    values (noise_std is then a floor and prior_std / noise_std the prior's ratio to it)."""
    redraw: Literal["step", "k", "every", "episode", "revisit"] = "step"
    """When a fresh Thompson draw z is made, per environment: every step (Algorithm 2), held for k
    steps (the horizon of the k-step target), every `redraw_every` steps, once per episode, or
    revisit: held while the episode reaches new states, redrawn at its start and whenever it
    returns to an observation it already saw (commits like a draw per episode, breaks the loops
    a fixed greedy policy walks; farsighter.ops.revisit). Our extension, not the paper's."""
    redraw_every: int = 1
    """T for ``redraw=every``."""
    target: Literal["mean", "thompson", "sample"] = "mean"
    """Value of the next state in the Q-loss target. mean: argmax and value under the posterior
    mean (Eq. 8). thompson: argmax under the latest acting Thompson draw, one weight set for the
    whole minibatch (the BDQN authors' code). sample: a fresh posterior draw per target row is
    added to both the online and the target Q of s' (argmax and value), so uncertainty about
    the next state raises the target: optimism propagates back along the chain of bootstraps,
    as in randomised value functions (Osband et al. 2019); our extension, not the paper's. With
    gamma = 1 that optimism is not discounted along loops (on the bridge maze, with the general
    posterior, Farsighter failed 2 of 2 seeds that the maze preset solves: docs/results/explore)."""
    posterior_sampling: Literal["recent", "uniform"] = "recent"
    """Batch-mode refresh tuples: the latest D transitions (Table 1's 'most recent'), or D starts
    drawn uniformly from the whole buffer with replacement (the BDQN authors' code)."""
    posterior_target: Literal["double", "max"] = "double"
    """Regression targets of a refresh: Eq. 8's double-Q target (argmax under the online features
    and posterior mean, value under the target network and target mean), or the plain
    max_a phi_target(s')^T mean_target_a (the BDQN authors' code)."""


@dataclass(frozen=True)
class AdaptiveKConfig:
    """Adaptive k (paper section 4.5, Algorithm 1 line 7)."""

    enabled: bool = False
    """Adjust k after every posterior refresh from the Q-variance."""
    variance_target: float = 1.0
    """epsilon of Algorithm 1: k += 1 when the Q-variance is below it, k -= 1 when above."""
    k_min: int = 1
    """Lower bound for k."""
    k_max: int = 500
    """Upper bound for k."""
    empty_buffer: bool = True
    """Empty the replay buffer after each change of k (k-step targets are formed on sampling, so
    keeping it is possible; off keeps every stored step)."""
    empty_every_refresh: bool = False
    """Empty the replay buffer after every posterior refresh whether k changed or not, as
    Algorithm 1 line 7 reads literally ('...; Empty Replay buffer.' follows both branches)."""


@dataclass(frozen=True)
class AtariConfig:
    """Standard Atari preprocessing (SPEC section 3; Machado et al. 2018, Mnih et al. 2015)."""

    frame_skip: int = 4
    """Environment frames per agent step (max-pooled over the last two)."""
    noop_max: int = 30
    """Each game starts with a uniform 1..noop_max no-op emulator frames, in training and
    evaluation (0: none)."""
    screen_size: int = 84
    """Side of the square grey observation."""
    frame_stack: int = 4
    """Number of stacked frames; the replay stores each frame once and stacks at sample time."""
    terminal_on_life_loss: bool = True
    """Training only: treat a life loss as terminal (the game continues)."""
    clip_rewards: bool = True
    """Training only: clip rewards to their sign."""
    repeat_action_probability: float = 0.0
    """Sticky actions (ALE v5 uses 0.25); 0 reproduces the DQN/BDQN protocol."""
    backend: Literal["auto", "gymnasium", "envpool"] = "auto"
    """Training environments: envpool's C++ vector (pip install 'farsighter[envpool]'), the
    Gymnasium wrappers, or auto (envpool when installed, the game is there and noop_max >= 1).
    Same preprocessing and step contract (tests/test_envpool_vec.py); no-op and sticky-action
    draws come from each backend's own generators, so the same seed gives equally distributed
    but different starts. Evaluation always uses Gymnasium."""
    envpool_threads: int = 0
    """envpool worker threads (0: one per environment, up to the CPU count)."""
    max_frames_per_episode: int = 108_000
    """Emulator frames after which ALE truncates an episode, no-ops included (108,000 frames =
    30 minutes of play; ALE v5's max_num_frames_per_episode, Machado et al. 2018); training
    and evaluation."""


@dataclass(frozen=True)
class NAFConfig:
    """Continuous agents naf, knaf, bnaf, farsighter-naf (paper sections 3.3, 4.3; Algorithm 3).

    The TD update of theta, theta_V, theta_P uses the top-level optimizer, lr, batch_size,
    train_every, loss and gamma; the fields below are what NAF adds.
    """

    hidden_sizes: tuple[int, ...] = (64, 32)
    """Representation MLP phi(s). Appendix 9.1.2: two layers of 64 and 32 units."""
    tau: float = 0.005
    """Rate of the soft target update theta' <- tau theta + (1 - tau) theta' (Algorithm 3 line
    11). Gu et al. (2016) use 0.001; 0.005 is TD3's / SB3's default."""
    soft_update: Literal["every_update", "every_n"] = "every_update"
    """When the soft target update runs: after every TD update (the convention of NAF's and
    DDPG's code, Gu et al. 2016, Lillicrap et al. 2016), or once every N =
    ``target_update_every`` environment steps, as Algorithm 3 line 11 reads literally."""
    updates_per_step: int = 1
    """TD updates per ``train_every`` environment steps (the I iterations of Algorithm 3 line 7)."""
    noise: Literal["gaussian", "ou"] = "gaussian"
    """Action noise of naf/knaf: Gaussian (TD3-style) or Ornstein-Uhlenbeck (DDPG, used by Gu et
    al. 2016). The Bayesian agents explore by sampling mu-layer weights instead."""
    noise_std: float = 0.1
    """Noise scale as a fraction of the half action range. TD3 uses 0.1; DDPG's OU sigma is 0.2."""
    ou_theta: float = 0.15
    """Mean reversion of the OU process x += -theta x + sigma N(0, 1) (Lillicrap et al. 2016)."""
    mu_penalty: float = 0.0
    """L2 penalty on the mu-layer's pre-tanh output (mean weights), added to naf/knaf's TD loss
    and to the Bayesian agents' ELBO (0: off; bnaf and farsighter-naf default to 0.1, our
    tuning). The Bayesian agents explore only through weight draws of the mu-layer: deep in
    tanh's saturation the draws no longer move the action, and with little action spread NAF's
    P is not identified. On Pendulum-v1 farsighter-naf (k = 2) without it saturated (|pre-tanh|
    ~ 20) and P fell to its floor in 2 of 3 seeds; at 0.01 one seed still lost P; at 0.1 all
    learned (benchmarks/results/learning_pendulum.json). SAC's code regularises its pre-tanh
    mean with 1e-3 (Haarnoja et al. 2018). naf/knaf explore with additive action noise, which
    saturation does not silence, and keep 0."""
    prior_std: float = 0.1
    """Prior N(0, prior_std^2) on every mu-layer weight; Table 1's prior sigma = 0.1."""
    init_sigma: float = 0.002
    """Initial posterior std of every mu-layer weight. Our choice: the pre-tanh action spread
    is |phi| sigma, and |phi| grows to ~80 with the value scale on Pendulum (spread ~0.16)."""
    noise_std_eps: float = 1.0
    """sigma_eps of the Gaussian likelihood of the TD targets in the ELBO (Table 1: 1)."""
    elbo_every: int = 10_000
    """M: environment steps between ELBO updates of the mu-layer (Table 1: M = 10 N, N = 1k for
    robotic control)."""
    elbo_steps: int = 100
    """Gradient steps of one ELBO update (the paper does not say; our choice)."""
    elbo_batch: int = 1_000
    """Minibatch of one ELBO step; Table 1: posterior update mini-batch 1k tuples (robotic)."""
    elbo_lr: float = 0.001
    """Adam learning rate of the mu-layer's means in the ELBO update."""
    elbo_rho_lr: float = 0.01
    """Adam learning rate of the mu-layer's rho (sigma = softplus(rho)): sigma moves slowly
    with the means' rate (a note of bayes_layer's author)."""
    kl_weight: float = 0.01
    """Weight of KL(q || prior) / |replay| in the ELBO (1: the true ELBO of Eq. 10). Our choice
    (a tempered posterior): at 1 the KL's pull of the means to 0 (w / prior_std^2 / |replay|)
    erased mu's state dependence and its pull of sigma to prior_std flooded the actions with
    noise, and NAF's P collapsed to 0 on Pendulum with k >= 2 (our runs)."""
    her: bool = False
    """Hindsight experience replay, future strategy (Andrychowicz et al. 2017), for
    goal-conditioned (dict-observation) tasks; relabels goals when sampling."""
    her_ratio: float = 0.8
    """Fraction of relabelled samples; 0.8 is the paper's future_k = 4 (1 - 1 / (1 + 4))."""


@dataclass(frozen=True)
class OB2IConfig:
    """OB2I (Bai et al. 2021): bootstrapped Q-heads, UCB-bonus, episodic backward update.

    Defaults are the authors' code (Baichenjia/OB2I, ``run_atari.py --ebu --reward-type ucb``) as
    recorded in SPEC section 2.3; the epsilon schedule 1.0 -> 0.1 is the ob2i algorithm's own
    (:mod:`farsighter.algorithms`).
    """

    num_heads: int = 10
    """K: linear Q-heads on the shared torso, all trained on every sample (code: --num-ensemble 10)."""
    separate_heads: bool = True
    """Each head has its own last hidden layer, as in the authors' network (a 512-unit layer per
    head on the shared convolutional torso; for an MLP torso the last layer of hidden_sizes is
    replicated per head). False: linear heads on one shared torso (this library before v0.2)."""
    beta: float = 0.5
    """Diffusion factor of the episodic backward update (EBU, Lee et al. 2019; code: --beta 0.5)."""
    bonus_reward_weight: float = 5e-5
    """alpha_1: weight of the immediate UCB-bonus, the std over online heads of Q_k(s, a)
    (code: --rew-immed-ratio-ebu 5e-5)."""
    bonus_next_weight: float = 5e-5
    """alpha_2: weight of the next-state UCB-bonus, the std over target heads at (s', a'_k)
    (code: --rew-nextq-ratio-ebu 5e-5)."""
    normalize_next_bonus: bool = True
    """Divide the next-state bonus by a running std of its values (code: --normnxq-ebu True)."""
    normalize_reward_bonus: bool = False
    """Same for the immediate bonus (code: --normrew-ebu False; the code's EBU path normalises it
    anyway through a tuple-truthiness slip, so True reproduces what it ran)."""
    eval_policy: Literal["vote", "mean"] = "vote"
    """Greedy (evaluation) action: majority vote of the heads (the authors' evaluation), ties
    broken by the mean Q; or the argmax of the heads' mean Q."""


@dataclass(frozen=True)
class RNDConfig:
    """Random network distillation (Burda et al. 2018) on DDQN: rnd (1-step) and krnd (k-step),
    the RND and TD(K)+RND baselines of the paper's appendix 9.1.1."""

    intrinsic_weight: float = 0.5
    """Weight of the normalised intrinsic reward added to the extrinsic reward (RND paper:
    intrinsic and extrinsic advantage coefficients 1 and 2, i.e. 0.5 relative)."""
    feature_dim: int = 512
    """Output size of the fixed random target network and of the predictor (RND paper: 512)."""
    lr: float = 1e-4
    """Adam learning rate of the predictor (RND paper: 1e-4)."""
    normalize_obs: bool = True
    """Whiten flat observations with a running mean/std before both RND networks (RND paper
    section 2.4); image observations are scaled to [0, 1] instead."""
    obs_clip: float = 5.0
    """Whitened observations are clipped to [-obs_clip, obs_clip] (RND paper: 5)."""


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
    device: str = "auto"
    """auto (CUDA when present, else CPU), cpu, cuda or cuda:N."""
    precision: Literal["fp32", "bf16"] = "fp32"
    """Arithmetic of the networks' torsos: fp32, or bf16 autocast (bfloat16 convolutions and
    matmuls). Its speed depends on the CPU, not only on its flags, so measure it there
    (python -m benchmarks.update_profile): Atari updates 1.37x faster on one of this project's
    machines (AVX-512 BF16, no AMX: 13.9 ms against 19.1 ms fp32), slower on a user's CPU with
    the same flags (38.9 ms against 26.9 ms fp32; issue #26); no faster on an H100 at batch 32, where
    the update is bound by kernel launches; slow where the hardware lacks bfloat16. Features,
    heads, the BLR posterior, targets, losses, parameters and optimizer state stay fp32 either
    way. Never on unless asked; docs/design.md gives its measured effect on learning."""
    cuda_graph: Literal["auto", "on", "off"] = "auto"
    """Capture the update step (forward, loss, backward, optimizer) as a CUDA graph and replay it
    each update, so the host launches it once instead of kernel by kernel
    (farsighter.agents.cuda_graph). auto: on a CUDA device, for the agents whose update allows
    it (ddqn, kddqn, bdqn, farsighter); on: insist (refused for the others, and on CPU); off:
    eager. The updates are the same either way. Off when compile is on."""
    overlap_env: Literal["auto", "on", "off"] = "auto"
    """Step the environments while the updates run: at each vector step the actions are sent,
    the updates owed are made while the games step on their own threads, and the step's
    transitions are stored after them (so those updates sample the replay one vector step
    older; the next ones see it). Needs environments that step asynchronously (the envpool
    Atari backend). auto: on with such environments on a CUDA device; on: also on a CPU
    (refused where the environments cannot); off: act, step, store, update in turn."""
    gpu_replay: Literal["auto", "off"] = "auto"
    """auto: on a CUDA device, the replay's observations are also kept in GPU memory and
    minibatches are stacked there, so only row indices cross from the host per update (one byte
    per pixel: 0.7 GB of GPU memory per 100k Atari frames, 7 GB for a 1M buffer), when that fits
    in half the GPU's free memory (else on the host, with a warning); off: stacked on the host
    and copied. The minibatches are the same either way."""
    target_cache: Literal["auto", "off"] = "auto"
    """auto: with ``sample_recent`` and an eager update (no CUDA graph, not compiled), Farsighter
    and BDQN keep the target network's features of each sampled next state until the next
    target copy (farsighter.replay.target_cache), so an update runs the target network only
    over next states not seen since that copy (with Table 1's values each is drawn about 8
    times per copy). The math is the same; the float rounding can differ from off, as the
    target network then sees other batch sizes. off: the target network runs over every
    minibatch."""
    compile: bool = False
    """torch.compile the update step (forward, target, loss, backward, clip, optimizer) of
    ddqn, kddqn, bdqn and farsighter (farsighter.agents.cuda_graph.wrap_step): fused
    element-wise work, on CPU in C++. The first update compiles (about 20 s on a 2-core CPU; a
    few seconds once the kernels are in Inductor's disk cache), and a CPU needs a C++ compiler.
    The math is the same; the float rounding differs from eager. Measured and tested on CPU;
    docs/design.md gives its speed."""
    resume: bool = False
    """Continue the run in run_dir from its last checkpoint."""
    overwrite: bool = False
    """Delete an existing run_dir and start afresh."""
    num_envs: int = 1
    """Environments stepped together (acting is batched over them)."""

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
    k_target: Literal["k", "max"] = "k"
    """k: the k-step target (section 4.4). max (bdqn, farsighter): the larger of the k-step and
    the one-step target of each sampled start. A k-step return follows the behaviour for k steps,
    so an exploratory episode that ended early makes it pessimistic and stops optimism from
    propagating; in a deterministic task every realised return is a lower bound on Q*, and the
    max keeps the one-step optimality target while the k-step return still carries found reward
    k steps back at once (lower-bound Q-learning, Tang 2020). Biased upwards where rewards or
    transitions are noisy; one more forward pass per update. Our extension, not the paper's."""
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
    binds first."""
    checkpoint_every: int = 25_000
    """Steps between checkpoints (0: only at the end)."""
    save_replay: bool = True
    """Store the replay buffer in checkpoints, so a resumed run equals an uninterrupted one."""
    log_every: int = 1_000
    """Steps between SPS/loss rows in TensorBoard."""
    progress: bool = True
    """Show a progress bar (steps, SPS, recent return)."""
    torch_threads: int = 0
    """CPU threads for torch (0: torch's default)."""

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


# --------------------------------------------------------------------------------------------
# Presets: each value cites its source.
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Preset:
    """A named set of field values (dotted keys for nested fields) and where they come from."""

    name: str
    doc: str
    source: str
    values: dict[str, Any]
    algo: str = ""
    """Made for this algorithm only (its variant): refused with others, applied over its values."""
    per_algo: dict[str, dict[str, Any]] = field(default_factory=dict)
    """Values for one algorithm that apply over that algorithm's own (defining) values."""


# Table 1, robotic/low-dimensional column (the control preset; general starts from it, and the
# atari preset from its shared rows).
_CONTROL: dict[str, Any] = {
    "optimizer": "rmsprop",
    "lr": 0.0025,
    "rmsprop_alpha": 0.95,
    "gamma": 0.99,
    "train_every": 4,
    "batch_size": 32,
    "buffer_size": 1_000_000,
    "target_update_every": 1_000,  # N = 1k (robotic controls)
    "blr.posterior_every": 10_000,  # M = 10 N
    "blr.posterior_samples": 1_000,  # D = 1k tuples
    "blr.prior_std": 0.1,
    "blr.noise_std": 1.0,
}

# The posterior of the general preset (and of the cartpole preset): fresh, scaled, propagating.
_FRESH_POSTERIOR: dict[str, Any] = {
    # Incremental statistics make a refresh O(|A| d^3): refresh every 100 steps instead of
    # Table 1's M = 10 N = 10k, which on a task of a few thousand episodes leaves the posterior
    # stale for most of the run.
    "blr.mode": "incremental",
    "blr.posterior_every": 100,
    # sigma_eps follows the residuals (never below 1, a reward of order 1); the prior sigma
    # equals it.
    "blr.scale": "residual",
    "blr.prior_std": 1.0,
    "blr.noise_std": 1.0,
    # Uncertainty about the next state raises the target, so optimism propagates.
    "blr.target": "sample",
}
# The learner of the general preset (what `auto` gives a small discrete task), for every agent
# alike: Adam with a target copy every 500 steps, an update every 4 steps on minibatches of 64
# drawn from the whole replay, a 128 x 128 torso. Table 1's control column (RMSProp 0.0025, a
# target copy per 1,000 steps, the minibatch from the latest N transitions) was set for robotic
# tasks of 100M steps; on small tasks it learned too slowly to use what the posterior found
# (bsuite deep sea N = 10 and 14: 0 of 4 seeds; this learner 4 of 4; benchmarks/
# small_task_learner.py, docs/design.md "The learner of small tasks").
_SMALL_TASK_LEARNER: dict[str, Any] = {
    "optimizer": "adam",
    "lr": 0.001,
    "optim_eps": 1e-8,
    "train_every": 4,
    "batch_size": 64,
    "target_update_every": 500,
    "hidden_sizes": (128, 128),
    "buffer_size": 100_000,
}
# Over the algorithms' own values: BDQN holds one draw per episode (its own default is the BDQN
# paper's every T = 1,000 steps), and Farsighter's k-step target is no lower than the one-step
# target. Farsighter keeps Algorithm 2's draw at every step: on the chain it solved as often as a
# draw held per episode (5/5 seeds at every length, docs/results/explore), and on MiniGrid
# DoorKey-5x5 a draw held per episode never reached the goal in 1,200 episodes (3 seeds x 100k
# steps; a fixed greedy policy walks in circles until the time limit) where a draw per step
# reached it in 10 episodes (median) (docs/results/explore/doorkey/report.md).
_FRESH_PER_ALGO: dict[str, dict[str, Any]] = {
    "bdqn": {"blr.redraw": "episode"},
    "farsighter": {"k_target": "max"},
}
# The general preset's: Farsighter's minibatches from the whole replay too. Algorithm 1 line 4's
# latest-N window (500 transitions with this learner: 50 episodes of deep sea N = 10) forgets a
# rarely found reward within a few dozen episodes; on deep sea N = 14 the whole replay held the
# greedy solution in 1 of 2 seeds, the window in 0 of 2 (docs/design.md).
_GENERAL_PER_ALGO: dict[str, dict[str, Any]] = {
    **_FRESH_PER_ALGO,
    "farsighter": {**_FRESH_PER_ALGO["farsighter"], "sample_recent": False},
}
# The cartpole preset's learning checks (tests/test_learning_slow.py) were measured with a draw
# held per episode; kept so that they stay what was measured.
_CARTPOLE_PER_ALGO: dict[str, dict[str, Any]] = {
    "bdqn": {"blr.redraw": "episode"},
    "farsighter": {"blr.redraw": "episode", "k_target": "max"},
}

PRESETS: dict[str, Preset] = {
    p.name: p
    for p in (
        Preset(
            "control",
            "Table 1, robotic/low-dimensional column.",
            "Farsighter paper, appendix 9.2 Table 1",
            dict(_CONTROL),
        ),
        Preset(
            "general",
            "What `auto` gives a discrete task that is not Atari: a learner for small tasks "
            "(Adam 1e-3, an update every 4 steps on 64 transitions from the whole replay, a "
            "target copy every 500 steps, 128 x 128) for every agent, with a posterior that "
            "stays fresh and scaled and whose uncertainty propagates, so that Thompson "
            "exploration works on tasks nobody tuned it for (docs/results/explore). Reproduce "
            "the paper with --preset control or atari.",
            "Farsighter paper Table 1 (control column) for gamma and the BLR values; the "
            "learner and the posterior settings are ours, chosen on the exploration suite "
            "(benchmarks/small_task_learner.py, farsighter explore)",
            {
                **_CONTROL,
                **_SMALL_TASK_LEARNER,
                **_FRESH_POSTERIOR,
            },
            per_algo=_GENERAL_PER_ALGO,
        ),
        Preset(
            "atari",
            "Table 1, Atari column, with the DQN evaluation protocol for what Table 1 omits.",
            "Farsighter paper Table 1; learning_starts, epsilon schedule and eval epsilon from "
            "Dopamine's DQN/Rainbow Atari configs (Castro et al. 2018)",
            {
                **_CONTROL,  # the rows Table 1's two columns share
                "target_update_every": 10_000,  # N = 10k (Atari)
                "blr.posterior_every": 100_000,  # M = 10 N
                "blr.posterior_samples": 100_000,  # D = 100k tuples
                "learning_starts": 20_000,  # Dopamine min_replay_history
                "eps_end": 0.01,  # Dopamine epsilon_train
                "eps_decay_steps": 250_000,  # Dopamine epsilon_decay_period (agent steps)
                "eval_epsilon": 0.001,  # Dopamine epsilon_eval
                "eval_max_steps": 27_000,  # 108,000 frames / frame skip 4 (ALE v5's episode cap)
                "eval_every": 250_000,
                "eval_episodes": 10,
                "checkpoint_every": 250_000,
                "save_replay": False,  # a 1M-frame buffer is 7 GB; opt in with --save-replay
                "log_every": 10_000,
            },
        ),
        Preset(
            "atari100k",
            "Atari 100k (100k agent steps = 400k frames, the data-efficient regime of Kaiser et "
            "al. 2020): Table 1's Atari column for the learning, its schedules shrunk to the "
            "budget (learning from step 1,600, target copied every 2,000 steps, epsilon 1 to "
            "0.01 over 2,000 steps, a 100k buffer that holds the whole run) and the general "
            "preset's posterior for the Bayesian agents; the Atari evaluation protocol.",
            "Farsighter paper Table 1 (Atari column: RMSProp 0.0025, update every 4 steps, "
            "batch 32); learning start, target period and epsilon schedule of data-efficient "
            "Rainbow (van Hasselt et al. 2019, Dopamine's DER config); evaluation as the atari "
            "preset; posterior as the general preset",
            {
                **_CONTROL,
                "target_update_every": 2_000,
                "learning_starts": 1_600,
                "buffer_size": 100_000,
                "eps_end": 0.01,
                "eps_decay_steps": 3_600,  # 2,000 steps of decay after the 1,600-step start
                "eval_epsilon": 0.001,
                "eval_max_steps": 27_000,
                "eval_every": 25_000,
                "eval_episodes": 10,
                "checkpoint_every": 25_000,
                "save_replay": False,
                "log_every": 5_000,
                **_FRESH_POSTERIOR,
            },
            per_algo=_FRESH_PER_ALGO,
        ),
        Preset(
            "minatar",
            "MinAtar (what `auto` gives a MinAtar id): Young & Tian's DQN settings for the "
            "learning (one update per step, 100k buffer, target copied every 1k steps, epsilon "
            "1 to 0.1 over 100k steps after a 5k-step start), with the general preset's "
            "posterior for the Bayesian agents.",
            "Young & Tian 2019, MinAtar (examples/dqn.py of kenjyoung/MinAtar: batch 32, "
            "buffer 100k, target update 1k, training every frame, replay start 5k, epsilon "
            "1 -> 0.1 over 100k frames, centred RMSProp lr 2.5e-4, decay 0.95, eps 0.01, "
            "Huber loss, gamma 0.99); the posterior settings are the general preset's",
            {
                **_CONTROL,
                "lr": 0.00025,
                "optim_eps": 0.01,
                "rmsprop_centered": True,
                "train_every": 1,
                "buffer_size": 100_000,
                "learning_starts": 5_000,
                "target_update_every": 1_000,
                "eps_start": 1.0,
                "eps_end": 0.1,
                "eps_decay_steps": 105_000,  # 100k steps of decay after the 5k-step start
                "loss": "huber",
                "eval_every": 50_000,
                "eval_episodes": 10,
                "eval_epsilon": 0.0,
                **_FRESH_POSTERIOR,
            },
            per_algo=_FRESH_PER_ALGO,
        ),
        Preset(
            "bdqn",
            "The BDQN authors' code as it runs (Atari scale), for the bdqn agent. Its redraw "
            "condition `if frame_counter % f_sampling:` (f_sampling = 1000) is true on 999 of "
            "1,000 frames, so the published BDQN redraws at every step except every 1,000th: "
            "this preset redraws at every step (the skipped 1-in-1,000 redraw is the one "
            "deliberate deviation). The bdqn algorithm's own default keeps the BDQN paper's "
            "redraw every T = 1,000 steps.",
            "kazizzad/BDQN-MxNet-Gluon (public code), as listed in SPEC section 2.1",
            algo="bdqn",
            values={
                "target_update_every": 10_000,
                "learning_starts": 50_000,  # the code's learning start
                "blr.prior_std": math.sqrt(1e-3),  # prior variance 1e-3
                "blr.noise_std": 1.0,  # noise variance 1
                "blr.cov_scale": 1e-3,  # stored covariance multiplied by the prior variance
                "blr.posterior_every": 100_000,
                "blr.posterior_samples": 100_000,  # min(|buffer|, 100k), statistics reset each time
                "blr.posterior_sampling": "uniform",  # from the whole buffer, with replacement
                "blr.posterior_target": "max",  # regression on r + gamma max_a phi'^T E_W_target
                "blr.mode": "batch",
                "blr.redraw": "step",  # true on 999 of 1,000 frames in the code (see above)
                "blr.target": "thompson",  # Q-loss argmax under the acting draw, value target mean
            },
        ),
        Preset(
            "cartpole",
            "Control preset with a faster optimiser and shorter schedules for CartPole-sized "
            "tasks (our tuning; used by the learning checks and the README quick start).",
            "Farsighter tuning on CartPole-v1 (benchmarks/learning.py), with the general preset's "
            "posterior (checked by tests/test_learning_slow.py); Adam as in CleanRL's "
            "dqn.py classic-control defaults",
            per_algo=_CARTPOLE_PER_ALGO,
            values={
                "optimizer": "adam",
                "lr": 0.0005,
                "optim_eps": 1e-8,
                "gamma": 0.99,
                "train_every": 1,
                "batch_size": 64,
                "buffer_size": 50_000,
                "learning_starts": 1_000,
                "target_update_every": 500,
                "eps_end": 0.02,
                "eps_decay_steps": 15_000,
                "hidden_sizes": (128, 128),
                **_FRESH_POSTERIOR,
                # CartPole's reward is dense (+1 a step): the novelty bonus is a nuisance there,
                # and at 0.5 RND reached 475 in 2 of 3 seeds only (our runs).
                "rnd.intrinsic_weight": 0.1,
                "eval_every": 5_000,
                "eval_episodes": 5,
                "loss": "huber",
            },
        ),
        Preset(
            "maze",
            "The bridge-maze study's shared settings (paper section 5.1, Fig. 1): every agent of "
            "the study runs with these, so the agents differ only in how they explore.",
            "gamma = 1 so that Q*(start) = 75 exactly (paper section 5.1); the rest is our tuning "
            "for the 159-cell maze (docs/results/maze)",
            {
                "gamma": 1.0,
                "optimizer": "adam",
                "lr": 0.001,
                "optim_eps": 1e-8,
                "hidden_sizes": (64, 64),
                "batch_size": 64,
                "train_every": 4,
                "buffer_size": 50_000,
                "learning_starts": 1_000,
                "target_update_every": 500,
                "eps_decay_steps": 10_000,
                "eps_end": 0.05,
                "loss": "huber",
                "eval_every": 2_000,
                "eval_episodes": 1,  # the maze is deterministic: one greedy episode says it all
                "eval_max_steps": 200,
                "checkpoint_every": 0,
                "log_every": 1_000,
                "blr.posterior_every": 1_000,
                "blr.posterior_samples": 5_000,
                # Q-values here are of order 100 (Atari's clipped rewards keep them near 1), so
                # the BLR noise and prior are scaled up: with sigma_eps = sigma = 1 the posterior
                # sd (~0.1) is negligible beside Q differences and Thompson sampling does not
                # explore (measured; see the maze report).
                "blr.prior_std": 10.0,
                "blr.noise_std": 10.0,
            },
        ),
        Preset(
            "continuous",
            "Continuous control (naf, knaf, bnaf, farsighter-naf; the auto preset for them): "
            "Table 1's robotic column where it applies, NAF's usual optimiser for the rest.",
            "Farsighter paper Table 1 (gamma, buffer, N = 1k, posterior minibatch 1k, "
            "sigma_eps, prior sigma); Adam at 1e-3 as DDPG's critic (Lillicrap et al. 2016); "
            "batch 128, one update per step, no gradient clipping, ELBO cadence: our tuning on "
            "Pendulum-v1 (benchmarks/learning_pendulum.py)",
            {
                "optimizer": "adam",
                "lr": 0.001,
                "optim_eps": 1e-8,
                "gamma": 0.99,
                "batch_size": 128,
                "train_every": 1,
                "buffer_size": 1_000_000,
                "learning_starts": 1_000,
                "loss": "mse",  # Algorithm 3 line 9
                # Clipping the squared-error gradient at norm 10 stalled NAF on Pendulum (our runs).
                "max_grad_norm": 0.0,
                "target_update_every": 1_000,  # N (only the recent window uses it for NAF)
                "naf.tau": 0.005,
                "naf.updates_per_step": 1,
                "naf.elbo_every": 1,
                "naf.elbo_steps": 1,
                "naf.elbo_batch": 128,
                "naf.prior_std": 0.1,
                "naf.noise_std_eps": 1.0,
                "eval_every": 5_000,
                "eval_episodes": 5,
                "eval_max_steps": 1_000,
            },
        ),
    )
}


def _nested_replace(obj: Any, dotted: dict[str, Any]) -> Any:
    """``dataclasses.replace`` with dotted keys for nested dataclasses; unknown keys raise."""
    direct: dict[str, Any] = {}
    nested: dict[str, dict[str, Any]] = {}
    names = {f.name for f in dataclasses.fields(obj)}
    for key, value in dotted.items():
        head, _, rest = key.partition(".")
        if head not in names:
            raise ConfigError(f"unknown config field '{key}'")
        if rest:
            nested.setdefault(head, {})[rest] = value
        else:
            direct[head] = value
    for head, sub in nested.items():
        direct[head] = _nested_replace(getattr(obj, head), sub)
    return dataclasses.replace(obj, **direct)


def is_minatar_id(env_id: str) -> bool:
    """True for MinAtar ids (``MinAtar/Breakout-v1``) without importing minatar."""
    return env_id.split(":")[-1].startswith("MinAtar/")


def is_atari_id(env_id: str) -> bool:
    """True for ALE ids (``ALE/Pong-v5``, ``PongNoFrameskip-v4``) without importing ale-py."""
    name = env_id.split(":")[-1]
    return name.startswith("ALE/") or "NoFrameskip" in name


def resolve_preset_name(preset: str, env: str, algo: str = "") -> str:
    """auto: atari for ALE ids, minatar for MinAtar ids, continuous for the NAF agents, general
    otherwise."""
    if preset == "auto":
        if is_atari_id(env):
            return "atari"
        if is_minatar_id(env):
            return "minatar"
        continuous = algo and algorithms.get(algo).actions == "continuous"
        return "continuous" if continuous else "general"
    if preset not in PRESETS:
        raise ConfigError(f"unknown preset '{preset}'; accepted: auto, {', '.join(PRESETS)}")
    return preset


def config_layers(algo: str, env: str, preset: str = "auto") -> list[tuple[str, dict[str, Any]]]:
    """The layers a config is built from, in the order they apply, each with its name: the
    preset, the algorithm's defining values (a preset made for the algorithm comes after them),
    then the preset's values for this algorithm. Field defaults come before them all and the
    caller's overrides after."""
    spec = algorithms.get(algo)
    name = resolve_preset_name(preset, env, algo)
    chosen = PRESETS[name]
    if chosen.algo and chosen.algo != algo:
        raise ConfigError(
            f"preset '{name}' is made for --algo {chosen.algo} (got --algo {algo}); "
            f"accepted presets for {algo}: auto, "
            + ", ".join(p.name for p in PRESETS.values() if p.algo in ("", algo))
        )
    preset_layer = (f"preset {name}", dict(chosen.values))
    algo_layer = (f"algorithm {algo}", dict(spec.defaults))
    layers = [algo_layer, preset_layer] if chosen.algo else [preset_layer, algo_layer]
    if algo in chosen.per_algo:
        layers.append((f"preset {name}, for {algo}", dict(chosen.per_algo[algo])))
    return layers


def make_config(
    algo: str = "ddqn", env: str = "CartPole-v1", preset: str = "auto", **overrides: Any
) -> Config:
    """Build a config: field defaults <- :func:`config_layers` (preset, algorithm, the preset's
    values for this algorithm) <- ``overrides``.

    ``overrides`` use field names; nested fields are written ``blr__prior_std`` or passed in a
    dict as ``{"blr.prior_std": ...}`` via ``**{"blr.prior_std": 0.1}``.
    """
    values: dict[str, Any] = {}
    for _, layer in config_layers(algo, env, preset):
        values.update(layer)
    values.update({k.replace("__", "."): v for k, v in overrides.items()})
    values.update({"algo": algo, "env": env, "preset": resolve_preset_name(preset, env, algo)})
    return _nested_replace(Config(), values)


def explain_config(algo: str, env: str, preset: str = "auto") -> list[tuple[str, Any, str]]:
    """(dotted field, value, where the value comes from) for every field of the config that
    ``make_config(algo, env, preset)`` builds, in field order: a layer's name, or ``field
    default``."""
    source: dict[str, str] = {}
    for name, layer in config_layers(algo, env, preset):
        for key in layer:
            source[key] = name
    cfg = make_config(algo, env, preset)
    rows: list[tuple[str, Any, str]] = []

    def walk(obj: Any, prefix: str) -> None:
        for f in dataclasses.fields(obj):
            value = getattr(obj, f.name)
            if dataclasses.is_dataclass(value):
                walk(value, f"{prefix}{f.name}.")
            else:
                key = prefix + f.name
                rows.append((key, value, source.get(key, "field default")))

    walk(cfg, "")
    return rows


def validate(cfg: Config) -> None:
    """Raise :class:`ConfigError` with one line naming the first problem and what is accepted."""
    spec = algorithms.get(cfg.algo)
    for part in (_run_checks, _ob2i_rnd_checks, _algorithm_checks, _naf_checks):
        for ok, message in part(cfg, spec):
            if not ok:
                raise ConfigError(message)


def _run_checks(cfg: Config, spec: algorithms.Algorithm) -> list[tuple[bool, str]]:
    """The run, learning and BLR fields."""
    return [
        (cfg.k >= 1, f"k must be an integer >= 1 (got {cfg.k})"),
        (cfg.lr > 0, f"lr must be > 0 (got {cfg.lr})"),
        (cfg.buffer_size > 0, f"buffer_size must be > 0 (got {cfg.buffer_size})"),
        (cfg.batch_size > 0, f"batch_size must be > 0 (got {cfg.batch_size})"),
        (
            cfg.batch_size <= cfg.buffer_size,
            f"batch_size ({cfg.batch_size}) must not exceed buffer_size ({cfg.buffer_size})",
        ),
        (cfg.total_steps > 0, f"total_steps must be > 0 (got {cfg.total_steps})"),
        (cfg.num_envs >= 1, f"num_envs must be >= 1 (got {cfg.num_envs})"),
        (0.0 <= cfg.gamma <= 1.0, f"gamma must be in [0, 1] (got {cfg.gamma})"),
        (cfg.train_every >= 1, f"train_every must be >= 1 (got {cfg.train_every})"),
        (
            cfg.target_update_every >= 1,
            f"target_update_every must be >= 1 (got {cfg.target_update_every})",
        ),
        (cfg.learning_starts >= 0, f"learning_starts must be >= 0 (got {cfg.learning_starts})"),
        (
            0.0 <= cfg.eps_end <= 1.0 and 0.0 <= cfg.eps_start <= 1.0,
            "eps_start and eps_end must be in [0, 1]",
        ),
        (0.0 <= cfg.eval_epsilon <= 1.0, "eval_epsilon must be in [0, 1]"),
        (cfg.eps_decay_steps >= 0, "eps_decay_steps must be >= 0"),
        (cfg.recent_window >= 0, "recent_window must be >= 0 (0 means target_update_every)"),
        (
            cfg.effective_recent_window <= cfg.buffer_size,
            f"recent window ({cfg.effective_recent_window}) must not exceed buffer_size "
            f"({cfg.buffer_size})",
        ),
        (  # max(.., 1): the list is built whole, so a bad num_envs must not divide by zero here
            cfg.k <= cfg.buffer_size // max(cfg.num_envs, 1),
            f"k ({cfg.k}) must not exceed the per-environment buffer "
            f"({cfg.buffer_size // max(cfg.num_envs, 1)})",
        ),
        (all(h > 0 for h in cfg.hidden_sizes), "hidden_sizes must be positive integers"),
        (cfg.atari.frame_skip >= 1, f"atari.frame_skip must be >= 1 (got {cfg.atari.frame_skip})"),
        (
            cfg.atari.frame_stack >= 1,
            f"atari.frame_stack must be >= 1 (got {cfg.atari.frame_stack})",
        ),
        (cfg.atari.noop_max >= 0, f"atari.noop_max must be >= 0 (got {cfg.atari.noop_max})"),
        (
            cfg.atari.envpool_threads >= 0,
            f"atari.envpool_threads must be >= 0 (0: one per environment; got "
            f"{cfg.atari.envpool_threads})",
        ),
        (
            0.0 <= cfg.atari.repeat_action_probability <= 1.0,
            "atari.repeat_action_probability must be in [0, 1] (0.25: sticky actions, Machado et "
            f"al. 2018; got {cfg.atari.repeat_action_probability})",
        ),
        (
            cfg.atari.max_frames_per_episode >= 0,
            "atari.max_frames_per_episode must be >= 0 (0: no cap; got "
            f"{cfg.atari.max_frames_per_episode})",
        ),
        (cfg.blr.prior_std > 0, f"blr.prior_std must be > 0 (got {cfg.blr.prior_std})"),
        (cfg.blr.noise_std > 0, f"blr.noise_std must be > 0 (got {cfg.blr.noise_std})"),
        (cfg.blr.cov_scale > 0, f"blr.cov_scale must be > 0 (got {cfg.blr.cov_scale})"),
        (0 < cfg.blr.forgetting <= 1, "blr.forgetting must be in (0, 1]"),
        (cfg.blr.posterior_every >= 1, "blr.posterior_every must be >= 1"),
        (cfg.blr.posterior_samples >= 1, "blr.posterior_samples must be >= 1"),
        (cfg.blr.redraw_every >= 1, "blr.redraw_every must be >= 1"),
        (
            1 <= cfg.adaptive_k.k_min <= cfg.adaptive_k.k_max,
            "adaptive_k bounds must satisfy 1 <= k_min <= k_max",
        ),
        (
            not cfg.adaptive_k.enabled or cfg.adaptive_k.k_min <= cfg.k <= cfg.adaptive_k.k_max,
            f"with adaptive k, the initial k ({cfg.k}) must lie in [k_min, k_max] = "
            f"[{cfg.adaptive_k.k_min}, {cfg.adaptive_k.k_max}]",
        ),
        (cfg.eval_episodes >= 1, "eval_episodes must be >= 1"),
        (
            cfg.eval_every >= 0,
            f"eval_every must be >= 0 (0: no periodic evaluation; got {cfg.eval_every})",
        ),
        (cfg.eval_max_steps >= 1, f"eval_max_steps must be >= 1 (got {cfg.eval_max_steps})"),
        (cfg.log_every >= 1, f"log_every must be >= 1 (got {cfg.log_every})"),
        (cfg.checkpoint_every >= 0, "checkpoint_every must be >= 0"),
        (cfg.torch_threads >= 0, "torch_threads must be >= 0"),
        (
            cfg.precision in ("fp32", "bf16"),
            f"precision must be fp32 or bf16 (got {cfg.precision!r})",
        ),
    ]


def _ob2i_rnd_checks(cfg: Config, spec: algorithms.Algorithm) -> list[tuple[bool, str]]:
    """OB2I and RND fields."""
    ob, rn = cfg.ob2i, cfg.rnd
    return [
        (ob.num_heads >= 2, f"ob2i.num_heads must be >= 2 (got {ob.num_heads})"),
        (0.0 <= ob.beta <= 1.0, f"ob2i.beta must be in [0, 1] (got {ob.beta})"),
        (ob.bonus_reward_weight >= 0, "ob2i.bonus_reward_weight must be >= 0"),
        (ob.bonus_next_weight >= 0, "ob2i.bonus_next_weight must be >= 0"),
        (ob.eval_policy in ("vote", "mean"), "ob2i.eval_policy must be 'vote' or 'mean'"),
        (
            rn.intrinsic_weight >= 0,
            f"rnd.intrinsic_weight must be >= 0 (got {rn.intrinsic_weight})",
        ),
        (rn.feature_dim >= 1, f"rnd.feature_dim must be >= 1 (got {rn.feature_dim})"),
        (rn.lr > 0, f"rnd.lr must be > 0 (got {rn.lr})"),
        (rn.obs_clip > 0, f"rnd.obs_clip must be > 0 (got {rn.obs_clip})"),
        (
            not spec.episodic or (cfg.k == 1 and not cfg.stride and not cfg.sample_recent),
            f"{cfg.algo} learns from whole episodes (episodic backward update): k must be 1 and "
            "stride and sample_recent off",
        ),
    ]


STEP_AGENTS = ("ddqn", "farsighter")
"""Agents whose update is one step function that can be captured as a CUDA graph or compiled
(farsighter.agents.cuda_graph); OB2I, RND and NAF update eagerly."""


def _algorithm_checks(cfg: Config, spec: algorithms.Algorithm) -> list[tuple[bool, str]]:
    """What the algorithm table allows, and the device."""
    adaptive = " and ".join(a.name for a in algorithms.TABLE if a.adaptive_k)
    device_ok = cfg.device in ("auto", "cpu", "cuda") or cfg.device.startswith("cuda:")
    step_algos = ", ".join(a.name for a in algorithms.TABLE if a.agent in STEP_AGENTS)
    return [
        (
            not cfg.adaptive_k.enabled or spec.adaptive_k,
            f"adaptive_k.enabled is only supported by --algo {adaptive}",
        ),
        (device_ok, f"unknown device '{cfg.device}'; accepted: auto, cpu, cuda, cuda:N"),
        (
            cfg.cuda_graph in ("auto", "on", "off"),
            f"cuda_graph must be auto, on or off (got {cfg.cuda_graph!r})",
        ),
        (
            cfg.overlap_env in ("auto", "on", "off"),
            f"overlap_env must be auto, on or off (got {cfg.overlap_env!r})",
        ),
        (
            cfg.gpu_replay in ("auto", "off"),
            f"gpu_replay must be auto or off (got {cfg.gpu_replay!r})",
        ),
        (
            cfg.cuda_graph != "on" or cfg.device != "cpu",
            "cuda_graph on needs a CUDA device (device cpu given); use auto or off",
        ),
        (
            cfg.cuda_graph != "on" or spec.agent in STEP_AGENTS,
            f"cuda_graph on is supported by --algo {step_algos}; use auto or off",
        ),
        (
            not cfg.compile or spec.agent in STEP_AGENTS,
            f"compile is supported by --algo {step_algos}",
        ),
        (
            not (cfg.compile and cfg.cuda_graph == "on"),
            "compile and cuda_graph on do not combine; use cuda_graph auto or off with compile",
        ),
        (
            cfg.k_target == "k" or spec.agent == "farsighter",
            "k_target max is only supported by --algo "
            + " and ".join(a.name for a in algorithms.TABLE if a.agent == "farsighter"),
        ),
    ]


def _naf_checks(cfg: Config, spec: algorithms.Algorithm) -> list[tuple[bool, str]]:
    """The continuous agents' fields."""
    n = cfg.naf
    return [
        (0.0 < n.tau <= 1.0, f"naf.tau must be in (0, 1] (got {n.tau})"),
        (n.updates_per_step >= 1, "naf.updates_per_step must be >= 1"),
        (n.noise_std >= 0, f"naf.noise_std must be >= 0 (got {n.noise_std})"),
        (0.0 < n.ou_theta <= 1.0, f"naf.ou_theta must be in (0, 1] (got {n.ou_theta})"),
        (
            len(n.hidden_sizes) >= 1 and all(h > 0 for h in n.hidden_sizes),
            "naf.hidden_sizes must be one or more positive integers",
        ),
        (n.prior_std > 0, f"naf.prior_std must be > 0 (got {n.prior_std})"),
        (n.init_sigma > 0, f"naf.init_sigma must be > 0 (got {n.init_sigma})"),
        (n.noise_std_eps > 0, f"naf.noise_std_eps must be > 0 (got {n.noise_std_eps})"),
        (n.elbo_every >= 1, "naf.elbo_every must be >= 1"),
        (n.elbo_steps >= 0, "naf.elbo_steps must be >= 0"),
        (n.elbo_batch >= 1, "naf.elbo_batch must be >= 1"),
        (n.elbo_lr > 0 and n.elbo_rho_lr > 0, "naf.elbo_lr and naf.elbo_rho_lr must be > 0"),
        (n.kl_weight >= 0, "naf.kl_weight must be >= 0"),
        (n.mu_penalty >= 0, "naf.mu_penalty must be >= 0"),
        (0.0 <= n.her_ratio <= 1.0, f"naf.her_ratio must be in [0, 1] (got {n.her_ratio})"),
        (
            not n.her or spec.actions == "continuous",
            "naf.her needs a continuous agent: "
            + algorithms.accepted(algorithms.names_for("continuous")),
        ),
        (
            spec.actions != "continuous" or n.elbo_batch <= cfg.buffer_size,
            f"naf.elbo_batch ({n.elbo_batch}) must not exceed buffer_size ({cfg.buffer_size})",
        ),
    ]


# --------------------------------------------------------------------------------------------
# JSON round trip (the run directory stores the resolved config).
# --------------------------------------------------------------------------------------------


def config_to_dict(cfg: Config) -> dict[str, Any]:
    return dataclasses.asdict(cfg)


def config_from_dict(data: dict[str, Any]) -> Config:
    def build(cls: Any, values: dict[str, Any]) -> Any:
        kwargs: dict[str, Any] = {}
        for f in dataclasses.fields(cls):
            if f.name not in values:
                continue
            value = values[f.name]
            if (
                dataclasses.is_dataclass(f.default_factory)
                if callable(f.default_factory)
                else False
            ):
                value = build(f.default_factory, value)
            elif isinstance(value, list):
                value = tuple(value)
            kwargs[f.name] = value
        return cls(**kwargs)

    return build(Config, data)


def save_config(cfg: Config, path: Path) -> None:
    """Write atomically: a crash mid-write leaves the previous file intact."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(config_to_dict(cfg), indent=2) + "\n")
    os.replace(tmp, path)


def load_config(path: Path) -> Config:
    try:
        return config_from_dict(json.loads(path.read_text()))
    except (OSError, ValueError, TypeError) as exc:
        raise ConfigError(f"cannot read run config {path}: {exc}") from None
