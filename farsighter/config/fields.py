"""The fields of a run's configuration: frozen dataclasses with a docstring per field (tyro turns
those into ``--help`` text), one per agent family beside the run's own."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Literal

import tyro

KTarget = Literal["k", "max", "max-mean", "cut"]
"""The values of ``Config.k_target``."""


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
    data_weight: float = 1.0
    """Incremental mode: multiplies the weight each minibatch row gets in the statistics,
    train_every / batch_size, with which a transition counts about once over its time in the
    replay (1). Above 1 the mean follows the data faster against the prior (a rarely seen
    reward is learned from fewer samples) and the posterior narrows faster where the run has
    been, while its width where the run has not been (the prior's) stays as it is. Our
    extension."""
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
    a fixed greedy policy walks; farsighter.exploration.revisit). Our extension, not the paper's."""
    redraw_every: int = 1
    """T for ``redraw=every``."""
    revisit_action: Literal["draw", "uniform", "uniform-unpaid", "uniform-timeout"] = "draw"
    """What Thompson acting does at an observation its episode has already visited (compared
    exactly, as ``redraw = revisit`` does; farsighter.exploration.revisit). draw: the draw's
    action, as everywhere. uniform: an action uniformly at random. uniform-unpaid: the same in
    an episode whose environment's previous episode paid no positive reward (so before a run's
    first positive reward, and after it while its episodes still fail), the draw's action
    after one that paid. uniform-timeout: the same in an episode whose environment's previous
    episode ran to its time limit (a loop shows as an episode that never ends on its own),
    the draw's action after one that ended before it. The optimism lifts every value to about
    its bias / (1 - gamma) before a first reward, and the values then order the actions by
    more than the draws spread, so a held or narrow draw acts like a fixed policy: a return to
    a visited state in a deterministic task is a loop that the same draw walks again (MiniGrid
    DoorKey-6x6: turning left and right in one cell, or a pick up that changes nothing, to the
    time limit). The random action breaks the loop where a redraw from a narrow posterior
    repeats it. A task whose observations never repeat within an episode (continuous states,
    deep sea, the chain) runs as without it, bit for bit. The general preset's Farsighter:
    uniform-timeout (session 42). Our extension."""
    target: Literal["mean", "thompson", "sample", "sample-greedy"] = "mean"
    """Value of the next state in the Q-loss target. mean: argmax and value under the posterior
    mean (Eq. 8). thompson: argmax under the latest acting Thompson draw, one weight set for the
    whole minibatch (the BDQN authors' code). sample: a fresh posterior draw per target row is
    added to both the online and the target Q of s' (argmax and value), so uncertainty about
    the next state raises the target: optimism propagates back along the chain of bootstraps,
    as in randomised value functions (Osband et al. 2019); our extension, not the paper's. With
    gamma = 1 that optimism is not discounted along loops (on the bridge maze, with the general
    posterior, Farsighter failed 2 of 2 seeds that the maze preset solves: docs/results/explore
    at commit 38d9854).
    sample-greedy: the draw added to the target Q alone, the argmax under the mean, so the
    target takes the draw of the mean's greedy action (zero-mean noise) rather than the largest
    of the actions' draws, whose positive mean a one-step bootstrap adds up over 1 / (1 - gamma)
    steps (DoorKey: docs/design.md)."""
    optimism: Literal["always", "until-reward"] = "always"
    """always: the targets' optimism (``target`` and ``Config.k_target`` as set) for the whole
    run. until-reward: as set until the run's first positive reward, then calibrated targets
    for good, the posterior mean and the k-step target alone (``target = mean``, ``k_target =
    calibrated_k_target``, the general preset's cut): the upward bias that carries a lock that
    pays only at its end (the chain, deep sea) is a bonus for not ending the episode, which on
    a task whose reward ends it (a MiniGrid goal, FrozenLake) makes reaching the reward the
    worst action (docs/design.md, the plainest MiniGrid room). Before the switch a run is the
    run without it, bit for bit. The switch is part of the checkpoint; each seed of a seed
    batch switches on its own; a run with it is never captured as a CUDA graph (with
    ``runtime.compile`` its step compiles, and compiles again at the switch). Our extension."""
    calibrated_k_target: Literal["k", "cut"] = "k"
    """With ``optimism = until-reward`` (or ``Config.k_target = cut``): the k-step target after
    the switch. k: the plain k-step return, which follows the behaviour, so a lock whose path
    the draws leave is forgotten once its target is no longer lifted (the chain L = 30: solved
    5/5, held 1/5, docs/results/explore/until-reward at commit 38d9854). cut: the return stopped
    before the first exploratory action (``Config.k_target = cut``; the run records which
    actions were from its start). Our extension."""
    switch_restart: Literal["none", "prior", "zero-targets", "refit", "refit-zero"] = "none"
    """With ``optimism = until-reward`` and ``mode = incremental``: what the posterior keeps of
    the optimistic targets at the switch. Its running statistics never forget, and every target
    they hold from before the switch carried the optimism (a bonus for every step that does not
    end the episode), which calibrated targets would otherwise work off at gamma per bootstrap.
    none: all of it (the field's default). prior: nothing, the posterior restarts from its
    prior (statistics zeroed, sigma_eps and the prior sigma as configured, mean 0 at the
    prior's width) and the targets' mean with it. zero-targets: the rows but not their targets
    (the sums of y set to 0, as if every earlier target had been 0), so the mean restarts at 0
    and the width stays what the rows made it. refit (the general preset's in session 39):
    from the prior, the posterior refitted to the latest 50,000 rows of the replay (each
    weighing a step's ``data_weight``) with the calibrated targets iterated to their fixed
    point (fitted Q-iteration, at most 200 iterations), and the targets' mean with it; the fit
    is not kept, and the restart from the prior stands, where a target passes the largest
    discounted reward sum the replay's episodes showed from a step to a later one (an
    overestimating fit) or where the switch comes before the first update. The learned
    features and the replay are kept in every case. Measured (docs/design.md "What the switch
    keeps", "The drifting lock", "The posterior refitted at the switch"): on the drifting lock
    (a wrong move one state back) the kept values rank the wrong move with the right one
    (L = 10: 0/5 with none, 5/5 with prior or refit); the prior alone drops the found path too,
    which deep sea pays for by bsuite's criterion (N = 20: prior 3/5, none 4/5, refit 4/5);
    refit takes the found path at once; on Taxi its fit overestimates (targets up to 46.7
    where no reward sum exceeds 20) and is dropped, as the unchecked fit's greedy policy
    repeated illegal pickups (final evaluation -736 to -911 against -200). refit-zero (the
    general preset's, for Farsighter): refit, but where the fit is dropped the rows stay
    without their targets (``zero-targets``) instead of the restart from the prior: MiniGrid
    DoorKey-5x5 (its fit rejected) 2/5 with ``stay_optimism`` False and ``cut_delay`` 3, 0/5
    with refit (docs/design.md "The refit where it is sound, the targets zeroed where it is
    not"). Our extension."""
    stay_optimism: bool = True
    """With ``target = sample`` or ``sample-greedy``: whether a target whose window ends where it
    began (s_{t+n} equal to s_t, as after an action that does not move the agent: MiniGrid's
    pick up, drop, toggle and done where they change nothing, a walk into FrozenLake's wall)
    takes the draw at s' too. True: every target does. False: those take the posterior mean's
    value, no draw. A value that bootstraps on its own state adds the draw's upward bias once
    per bootstrap, over 1 / (1 - gamma) of them, so staying put becomes the best action and a
    held draw repeats it (DoorKey-5x5: docs/design.md); posterior sampling over a whole value
    function pays no such bonus for a self-loop. On a task whose every step moves the agent or
    ends the episode (the chain, tested; deep sea) a run is the run with True bit for bit.
    DoorKey-5x5 with it: 0/3 (docs/design.md). The general preset's Farsighter: False (with
    ``switch_restart`` refit-zero and ``cut_delay`` 3, session 40). Our extension."""
    rearm_episodes: int = 0
    """With ``optimism = until-reward``: after this many episodes in a row that paid no positive
    reward since the switch, the targets' optimism again, until the next positive reward
    switches once more. 0: never (the optimism ends at the first reward for good). Meant for a
    reward found before the values know its way (MiniGrid DoorKey-5x5: one goal, then none in
    95k steps under calibrated targets), to be looked for again with the optimism that found
    it; measured there with n = 10, it did not find it again either (docs/design.md). Our
    extension."""
    cut_margin: float = 0.0
    """With ``Config.k_target = cut`` (now or after the switch): how sure the posterior must be
    that an action other than the mean's greedy one was worse before a window is cut there: its
    mean Q below the greedy action's by more than this many predictive sds of the difference,
    sqrt(var_taken + var_greedy). 0: wherever the two differ (Watkins). Where the actions'
    values nearly tie (a MiniGrid room, where the draws choose among moves a hundredth apart)
    every draw differs from the mean somewhere and the windows shrink to one step; a margin
    keeps the k-step return there and cuts where a move is clearly wrong (the chain's). Our
    extension."""
    cut_delay: float = 0.0
    """With ``Config.k_target = cut`` (now or after the switch): cut a window only where the action
    taken costs more than this many steps of delay, its mean Q below the greedy action's by
    more than cut_delay (1 - gamma) |Q_greedy| (a step's delay costs (1 - gamma) V). In a room
    a wrong turn costs a step or two, which at gamma = 0.99 is a gap of about 0.01 V, below
    what the values resolve, and cutting there shrinks every window to a step; a move that
    ends the episode short of the reward (the chain's) costs all of V and is cut at once. 0:
    wherever the draw and the mean differ (with ``cut_margin`` 0, Watkins). The general
    preset's Farsighter: 3 (session 40; the chain L = 30 held 5/5 with it). Our extension."""
    advantage_learning: float = 0.0
    """With ``optimism = until-reward``, after its switch: alpha of the advantage-learning
    operator (Baird 1999; Bellemare et al. 2016, "Increasing the Action Gap"), every target
    y of (s, a) lowered by alpha (max_b Q_target(s, b) - Q_target(s, a)), the target network's
    gap between the greedy action and the one taken. At a fixed point the gaps between actions
    grow by 1 / (1 - alpha), the greedy action's value unchanged. Where a wasted step costs
    (1 - gamma) V (a turn, a pick up that changes nothing, a walk into a wall: about 0.01 V at
    gamma = 0.99), a gap below what the values resolve, the posterior mean's greedy policy can
    repeat such a step to the time limit while the draws, which move, get through. 0: off;
    with ``optimism = always`` there is no switch, so it never acts. The general preset's
    Farsighter: 0.9 (session 41). Our extension, from the paper's operator."""
    target_noise_scale: float = 1.0
    """With target = sample or sample-greedy: a factor on the draw added to the next state's value
    (1: the posterior's own width). The draw's upward bias (the largest of the actions' draws,
    the larger of two drawn targets) adds up over the bootstraps to a bonus for every step that
    does not end the episode, about that bias / (1 - gamma), in proportion to this factor; the
    rewards do not scale with it. So a factor below 1 weighs what the task pays more against
    that bonus (a goal that ends the episode: MiniGrid, FrozenLake) while the frontier's wider
    draws keep their lead over the states the run knows. Our extension."""
    act_width: Literal["posterior", "action-gap"] = "posterior"
    """Width of the acting draws (Thompson's, Eq. 7). posterior: the posterior's own.
    action-gap: widened, at every refresh, by the mean over recent minibatch states of the
    largest minus the smallest posterior-mean Q over the prior sigma, when that is above 1
    (``farsighter.ops.blr.action_gap_scale``). The prior's width is sized to the residual noise;
    where the learned values set actions further apart than that (an action that costs -10
    almost everywhere, Taxi's pickup) no draw reaches across the gap and Thompson never tries
    the action where it pays. The targets' draws keep the posterior's width (widening them
    compounds through the bootstraps; with ``target = thompson`` the loss reuses the acting
    draw, widened), and a task whose action gaps stay within the prior's width acts as it did,
    bit for bit. Our extension."""
    center_sample: bool = False
    """With target = sample: subtract from every bootstrapped target of a minibatch the
    minibatch's mean optimism (the draws' sum of y - y_mean over the sum of the bootstrap
    factors, times the row's factor), so that a next state's draw raises its target by how much
    more uncertain it is than the minibatch's next states are on average. The raw draw adds a
    bonus at every step that does not end the episode, which on a task whose goal ends it
    (FrozenLake) pulls the greedy policy away from the goal; centred, optimism stays where the
    run has been least and the states it knows carry none. Our extension."""
    random_features: int = 0
    """Width of fixed random ReLU features of the observation appended to the learned features
    the posterior is over (``farsighter.networks.RandomFeatureTorso``): with them the
    posterior's uncertainty narrows where the run has been and stays wide elsewhere. Flat
    observations only: image torsos keep the learned features alone (a run says so on stderr).
    0: the learned features alone (the paper). Our extension, not the paper's."""
    random_features_max: int = 0
    """When above ``random_features``: the random layer widens to the observation's number of
    entries, up to this width. A layer narrower than its input has fewer directions than a
    one-hot observation has states, so once a run has visited about that many states new ones
    stop looking new to the posterior (docs/design.md, "Why a fixed random layer runs out at
    depth"); the cost is O(width^2) a row and O(width^3) a refresh. 0: ``random_features``
    whatever the observation. Our extension."""
    random_features_kind: Literal["relu", "fourier"] = "relu"
    """The random features' map: relu, psi(s) = relu(W s + b) / sqrt(width) with W, b standard
    normal; fourier, psi(s) = sqrt(2 / width) cos(W s + b) with W ~ N(0, 1 / 0.25) and b uniform
    on [0, 2 pi) (random Fourier features of a Gaussian kernel of lengthscale 0.5), whose
    features of two distinct one-hot states share almost nothing, so a layer of a given width
    keeps new states looking new for longer (docs/design.md, "Why a fixed random layer runs
    out at depth")."""
    posterior_sampling: Literal["recent", "uniform"] = "recent"
    """Batch-mode refresh tuples: the latest D transitions (Table 1's 'most recent'), or D starts
    drawn uniformly from the whole buffer with replacement (the BDQN authors' code)."""
    posterior_target: Literal["double", "max"] = "double"
    """Regression targets of a refresh: Eq. 8's double-Q target (argmax under the online features
    and posterior mean, value under the target network and target mean), or the plain
    max_a phi_target(s')^T mean_target_a (the BDQN authors' code)."""

    @property
    def switches_update(self) -> bool:
        """Whether the update changes its branch mid-run (``optimism = until-reward``'s switch):
        such a run is compiled where asked but never captured as a CUDA graph."""
        return self.optimism != "always"

    def checks(self) -> list[tuple[bool, str]]:
        """(holds, what was wrong and what is accepted) for each field of this section."""
        return [
            (self.prior_std > 0, f"blr.prior_std must be > 0 (got {self.prior_std})"),
            (self.noise_std > 0, f"blr.noise_std must be > 0 (got {self.noise_std})"),
            (self.cov_scale > 0, f"blr.cov_scale must be > 0 (got {self.cov_scale})"),
            (0 < self.forgetting <= 1, "blr.forgetting must be in (0, 1]"),
            (self.data_weight > 0, f"blr.data_weight must be > 0 (got {self.data_weight})"),
            (
                self.rearm_episodes >= 0,
                f"blr.rearm_episodes must be >= 0 (got {self.rearm_episodes})",
            ),
            (
                self.cut_margin >= 0 and math.isfinite(self.cut_margin),
                f"blr.cut_margin must be a finite number >= 0 (got {self.cut_margin})",
            ),
            (
                self.cut_delay >= 0 and math.isfinite(self.cut_delay),
                f"blr.cut_delay must be a finite number >= 0 (got {self.cut_delay})",
            ),
            (
                0 <= self.advantage_learning < 1,
                f"blr.advantage_learning must be in [0, 1) (got {self.advantage_learning})",
            ),
            (
                self.target_noise_scale >= 0 and math.isfinite(self.target_noise_scale),
                f"blr.target_noise_scale must be a finite number >= 0 (got "
                f"{self.target_noise_scale})",
            ),
            (self.posterior_every >= 1, "blr.posterior_every must be >= 1"),
            (self.posterior_samples >= 1, "blr.posterior_samples must be >= 1"),
            (self.redraw_every >= 1, "blr.redraw_every must be >= 1"),
            (
                self.random_features >= 0,
                f"blr.random_features must be >= 0 (0: none; got {self.random_features})",
            ),
            (
                self.random_features_max >= 0,
                "blr.random_features_max must be >= 0 (0: no widening; got "
                f"{self.random_features_max})",
            ),
        ]

    def random_feature_width(self, obs_entries: int) -> int:
        """The random layer's width on flat observations of ``obs_entries`` entries:
        ``random_features``, widened to ``obs_entries`` up to ``random_features_max``; 0 when
        there are no random features."""
        if not self.random_features:
            return 0
        return max(self.random_features, min(obs_entries, self.random_features_max))


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

    def checks(self) -> list[tuple[bool, str]]:
        """(holds, what was wrong and what is accepted) for each field of this section."""
        return [
            (
                1 <= self.k_min <= self.k_max,
                "adaptive_k bounds must satisfy 1 <= k_min <= k_max",
            ),
        ]


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
        return [
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
