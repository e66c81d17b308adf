"""The other sections of a run's configuration: Atari preprocessing, the NAF, OB2I and RND agent
families, and the runtime (re-exported by :mod:`farsighter.config.fields`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal


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
    Same preprocessing and step contract (tests/envs/test_envpool_vec.py); no-op and sticky-action
    draws come from each backend's own generators, so the same seed gives equally distributed
    but different starts. Evaluation always uses Gymnasium."""
    envpool_threads: int = 0
    """envpool worker threads (0: one per environment, up to the CPU count)."""
    max_frames_per_episode: int = 108_000
    """Emulator frames after which ALE truncates an episode, no-ops included (108,000 frames =
    30 minutes of play; ALE v5's max_num_frames_per_episode, Machado et al. 2018); training
    and evaluation."""

    def checks(self) -> list[tuple[bool, str]]:
        """(holds, what was wrong and what is accepted) for each field of this section."""
        return [
            (self.frame_skip >= 1, f"atari.frame_skip must be >= 1 (got {self.frame_skip})"),
            (self.frame_stack >= 1, f"atari.frame_stack must be >= 1 (got {self.frame_stack})"),
            (self.noop_max >= 0, f"atari.noop_max must be >= 0 (got {self.noop_max})"),
            (
                self.envpool_threads >= 0,
                f"atari.envpool_threads must be >= 0 (0: one per environment; got "
                f"{self.envpool_threads})",
            ),
            (
                0.0 <= self.repeat_action_probability <= 1.0,
                "atari.repeat_action_probability must be in [0, 1] (0.25: sticky actions, "
                f"Machado et al. 2018; got {self.repeat_action_probability})",
            ),
            (
                self.max_frames_per_episode >= 0,
                "atari.max_frames_per_episode must be >= 0 (0: no cap; got "
                f"{self.max_frames_per_episode})",
            ),
        ]


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

    def checks(self) -> list[tuple[bool, str]]:
        """(holds, what was wrong and what is accepted) for each field of this section."""
        return [
            (0.0 < self.tau <= 1.0, f"naf.tau must be in (0, 1] (got {self.tau})"),
            (self.updates_per_step >= 1, "naf.updates_per_step must be >= 1"),
            (self.noise_std >= 0, f"naf.noise_std must be >= 0 (got {self.noise_std})"),
            (0.0 < self.ou_theta <= 1.0, f"naf.ou_theta must be in (0, 1] (got {self.ou_theta})"),
            (
                len(self.hidden_sizes) >= 1 and all(h > 0 for h in self.hidden_sizes),
                "naf.hidden_sizes must be one or more positive integers",
            ),
            (self.prior_std > 0, f"naf.prior_std must be > 0 (got {self.prior_std})"),
            (self.init_sigma > 0, f"naf.init_sigma must be > 0 (got {self.init_sigma})"),
            (
                self.noise_std_eps > 0,
                f"naf.noise_std_eps must be > 0 (got {self.noise_std_eps})",
            ),
            (self.elbo_every >= 1, "naf.elbo_every must be >= 1"),
            (self.elbo_steps >= 0, "naf.elbo_steps must be >= 0"),
            (self.elbo_batch >= 1, "naf.elbo_batch must be >= 1"),
            (
                self.elbo_lr > 0 and self.elbo_rho_lr > 0,
                "naf.elbo_lr and naf.elbo_rho_lr must be > 0",
            ),
            (self.kl_weight >= 0, "naf.kl_weight must be >= 0"),
            (self.mu_penalty >= 0, "naf.mu_penalty must be >= 0"),
            (
                0.0 <= self.her_ratio <= 1.0,
                f"naf.her_ratio must be in [0, 1] (got {self.her_ratio})",
            ),
        ]


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

    def checks(self) -> list[tuple[bool, str]]:
        """(holds, what was wrong and what is accepted) for each field of this section."""
        return [
            (self.num_heads >= 2, f"ob2i.num_heads must be >= 2 (got {self.num_heads})"),
            (0.0 <= self.beta <= 1.0, f"ob2i.beta must be in [0, 1] (got {self.beta})"),
            (self.bonus_reward_weight >= 0, "ob2i.bonus_reward_weight must be >= 0"),
            (self.bonus_next_weight >= 0, "ob2i.bonus_next_weight must be >= 0"),
            (
                self.eval_policy in ("vote", "mean"),
                "ob2i.eval_policy must be 'vote' or 'mean'",
            ),
        ]


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

    def checks(self) -> list[tuple[bool, str]]:
        """(holds, what was wrong and what is accepted) for each field of this section."""
        return [
            (
                self.intrinsic_weight >= 0,
                f"rnd.intrinsic_weight must be >= 0 (got {self.intrinsic_weight})",
            ),
            (self.feature_dim >= 1, f"rnd.feature_dim must be >= 1 (got {self.feature_dim})"),
            (self.lr > 0, f"rnd.lr must be > 0 (got {self.lr})"),
            (self.obs_clip > 0, f"rnd.obs_clip must be > 0 (got {self.obs_clip})"),
        ]


@dataclass(frozen=True)
class RuntimeConfig:
    """How a run is computed, apart from what it learns: the device, the arithmetic and the
    fast paths of the update and of the loop. On the command line these keep their plain names
    (``--device``, ``--torch-threads``, ...). Every setting but ``precision`` and
    ``overlap_env`` may change on ``--resume``; those two change what is learned (bf16
    rounding; updates that see the replay one vector step older)."""

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
    it (ddqn, kddqn, bdqn, farsighter, rnd, krnd) and keeps one branch (not with
    ``blr.optimism until-reward``, the general preset's: its switch changes the update mid-run);
    on: insist (refused for the others, for until-reward, and on CPU); off: eager. The updates
    are the same either way. Off when compile is on."""
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
    ddqn, kddqn, bdqn, farsighter, rnd and krnd (farsighter.agents.learner): fused
    element-wise work, on CPU in C++. The first update compiles (about 20 s on a 2-core CPU; a
    few seconds once the kernels are in Inductor's disk cache), and a CPU needs a C++ compiler.
    The math is the same; the float rounding differs from eager. Measured and tested on CPU;
    docs/design.md gives its speed."""
    torch_threads: int = 0
    """CPU threads for torch (0: torch's default)."""
    capture_video: bool = False
    """Record the first episode of each periodic evaluation (``eval_every``, and the final one)
    as RUN_DIR/videos/eval-step-<step>.mp4, through Gymnasium's RecordVideo: the evaluation
    environment renders rgb_array frames, which costs time on every step of that episode, and
    holds them in memory until it ends. Needs moviepy (pip install 'farsighter[video]'). What
    is learned does not change."""
    track: bool = False
    """Log the run to Weights & Biases as well (CleanRL's ``--track``): every scalar written to
    TensorBoard, with the same tags against a ``global_step`` axis, the resolved config, and with
    capture_video each evaluation's video. W&B's files go to RUN_DIR/wandb (``WANDB_MODE=offline``
    keeps them there, for a later ``wandb sync``); a resume continues the same W&B run. Needs
    wandb (pip install 'farsighter[track]'). What is learned does not change."""
    wandb_project: str = "farsighter"
    """W&B project of a tracked run (``track``)."""
    wandb_entity: str = ""
    """W&B entity (user or team) of a tracked run; empty: W&B's default entity."""

    def checks(self) -> list[tuple[bool, str]]:
        """(holds, what was wrong and what is accepted) for each field of this section (which
        agents allow a CUDA graph or compile: farsighter.config.checks)."""
        device_ok = self.device in ("auto", "cpu", "cuda") or self.device.startswith("cuda:")
        return [
            (self.torch_threads >= 0, "torch_threads must be >= 0"),
            (
                self.precision in ("fp32", "bf16"),
                f"precision must be fp32 or bf16 (got {self.precision!r})",
            ),
            (device_ok, f"unknown device '{self.device}'; accepted: auto, cpu, cuda, cuda:N"),
            (
                self.cuda_graph in ("auto", "on", "off"),
                f"cuda_graph must be auto, on or off (got {self.cuda_graph!r})",
            ),
            (
                self.overlap_env in ("auto", "on", "off"),
                f"overlap_env must be auto, on or off (got {self.overlap_env!r})",
            ),
            (
                self.gpu_replay in ("auto", "off"),
                f"gpu_replay must be auto or off (got {self.gpu_replay!r})",
            ),
            (
                self.cuda_graph != "on" or self.device != "cpu",
                "cuda_graph on needs a CUDA device (device cpu given); use auto or off",
            ),
            (
                not (self.compile and self.cuda_graph == "on"),
                "compile and cuda_graph on do not combine; use cuda_graph auto or off with compile",
            ),
        ]
