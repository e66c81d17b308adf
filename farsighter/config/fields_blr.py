"""The BLR head's and adaptive k's sections of a run's configuration (re-exported by
:mod:`farsighter.config.fields`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal


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
    deep sea, the chain) runs as without it, bit for bit. Session 45's general preset
    set uniform-timeout. Our extension."""
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
    repeated illegal pickups (final evaluation -736 to -911 against -200). refit-zero (session
    45's general preset's): refit, but where the fit is dropped the rows stay
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
    DoorKey-5x5 with it: 0/3 (docs/design.md). Session 45's general preset set False (with
    ``switch_restart`` refit-zero and ``cut_delay`` 3). Our extension."""
    cut_delay: float = 3.0
    """With ``Config.k_target = cut`` (now or after the switch): cut a window only where the action
    taken costs more than this many steps of delay, its mean Q below the greedy action's by
    more than cut_delay (1 - gamma) |Q_greedy| (a step's delay costs (1 - gamma) V). In a room
    a wrong turn costs a step or two, which at gamma = 0.99 is a gap of about 0.01 V, below
    what the values resolve, and cutting there shrinks every window to a step; a move that
    ends the episode short of the reward (the chain's) costs all of V and is cut at once. 0:
    wherever the draw and the mean differ (Watkins). 3, part of the cut as the general preset's
    Farsighter takes it: selection IQM 0.99 [0.97, 1.00] against 0.91 [0.87, 0.94] at 0
    (docs/results/suite/comparisons/cut-target). Acts only with the cut. Our extension."""
    advantage_learning: float = 0.0
    """With ``optimism = until-reward``, after its switch: alpha of the advantage-learning
    operator (Baird 1999; Bellemare et al. 2016, "Increasing the Action Gap"), every target
    y of (s, a) lowered by alpha (max_b Q_target(s, b) - Q_target(s, a)), the target network's
    gap between the greedy action and the one taken. At a fixed point the gaps between actions
    grow by 1 / (1 - alpha), the greedy action's value unchanged. Where a wasted step costs
    (1 - gamma) V (a turn, a pick up that changes nothing, a walk into a wall: about 0.01 V at
    gamma = 0.99), a gap below what the values resolve, the posterior mean's greedy policy can
    repeat such a step to the time limit while the draws, which move, get through. 0: off;
    with ``optimism = always`` there is no switch, so it never acts. Session 45's general
    preset set 0.9. Our extension, from the paper's operator."""
    target_noise_scale: float = 1.0
    """With target = sample or sample-greedy: a factor on the draw added to the next state's value
    (1: the posterior's own width). The draw's upward bias (the largest of the actions' draws,
    the larger of two drawn targets) adds up over the bootstraps to a bonus for every step that
    does not end the episode, about that bias / (1 - gamma), in proportion to this factor; the
    rewards do not scale with it. So a factor below 1 weighs what the task pays more against
    that bonus (a goal that ends the episode: MiniGrid, FrozenLake) while the frontier's wider
    draws keep their lead over the states the run knows. The general preset's Farsighter: 1
    (session 53's 0.5 dropped: selection IQM 1.00 [0.99, 1.00] against 0.99 [0.98, 1.00], the
    mean 0.98 against 0.94; docs/results/suite/comparisons/target-width). Our extension."""
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
    0: the learned features alone (the paper). The general preset's Farsighter: 32, widened to
    the observation up to 1,024 (``random_features_max``), fitting no value
    (``random_features_fit`` False), both this mechanism's defaults. Our extension, not the
    paper's."""
    random_features_max: int = 1024
    """When above ``random_features``: the random layer widens to the observation's number of
    entries, up to this width. A layer narrower than its input has fewer directions than a
    one-hot observation has states, so once a run has visited about that many states new ones
    stop looking new to the posterior (docs/design.md, "Why a fixed random layer runs out at
    depth"); the cost is O(width^2) a row and O(width^3) a refresh. 0: ``random_features``
    whatever the observation. Acts only with ``random_features`` above 0. Our extension."""
    random_features_fit: bool = False
    """Whether the posterior mean fits the random features too. True: one regression over the
    learned and the random features, so the random ones also fit values, state by state (a
    goal's value then reaches no state the run has not taken it from). False: their block of
    the posterior fits no target and shares no covariance with the learned features
    (``BLRHead``'s ``fit_dim``): the values are the learned features' alone, and the random
    block only widens the draws, by up to the prior's width where an observation is new and
    narrowing where the run has been: uncertainty about states, which the learned features,
    shared across states, do not hold (the default: comparisons/random-features-uncertainty
    against random-features-wide). Acts only with ``random_features`` above 0. Our extension."""
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
