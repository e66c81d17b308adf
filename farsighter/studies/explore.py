"""The exploration suite: how the episodes an agent needs to solve a task grow with its size.

Task families with a size knob (:data:`FAMILIES`: the combination-lock chain, MiniGrid DoorKey,
KeyCorridor and MultiRoom, bsuite's deep sea, deterministic and stochastic, MountainCar and
Acrobot), every agent with one config for all of them (the library's ``auto`` preset and the
agent's own overrides: no per-task tuning), several seeds each (:mod:`farsighter.studies.runner`
runs the agent x task x seed grid, resumes an interrupted study and loads the saved runs). Per run
it measures from the saved metrics.csv and eval.csv whether and when a greedy evaluation first
reached the family's threshold (stochastic deep sea: from success.csv and eval_success.csv, the
fraction of evaluation episodes that took the treasure, whose noise-free flag the environment
reports, rather than the noisy return); on deep sea it also records every episode's bad flag
(bad_episodes.csv, :class:`BadEpisodeLog`) and applies bsuite's own criterion
(:func:`bsuite_solution`). Per family and agent it fits the growth of the episodes to solve
against the size, polynomial and exponential, with a bootstrap interval on the polynomial
exponent. Everything is drawn from saved files, so ``--plot-only`` redraws it.
"""

from __future__ import annotations

import csv
import dataclasses
import shlex
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np

from farsighter.config import Config
from farsighter.config.presets import PREVIOUS_GENERAL_FARSIGHTER
from farsighter.envs.chain import SOLVED_RETURN, chain_id, drift_chain_id
from farsighter.envs.deep_sea import deep_sea_id
from farsighter.errors import FarsighterError
from farsighter.plots import figure, finish_axes, markdown_table
from farsighter.rundir import EVAL_SUCCESS_FILE, SUCCESS_FILE
from farsighter.studies import runner
from farsighter.studies.claims import fmt
from farsighter.studies.runner import Agent, Runs, StudyArgs, Task

BSUITE_NUM_EPISODES = 10_000
"""Episodes of a bsuite deep sea run (its sweep's NUM_EPISODES); its analysis looks no further."""
BSUITE_FORGIVENESS = 100
"""bsuite's score: a size is solved if its solution episode is below 2^N + this."""


@dataclass(frozen=True)
class BsuiteCriterion:
    """bsuite's deep sea analysis (``bsuite/experiments/deep_sea/analysis.py`` and
    ``deep_sea_stochastic/analysis.py``): a run is solved at the first episode where the running
    fraction of bad episodes (bad episodes so far / episodes so far) is below ``threshold``,
    among the episodes from ``min_episode`` on; the size counts as solved ("beats dithering")
    when that episode is below 2^N + :data:`BSUITE_FORGIVENESS`."""

    threshold: float
    min_episode: int = 1


@dataclass(frozen=True)
class Family:
    """Tasks of one kind at growing sizes, and how a run on them is measured."""

    size: str
    """What the size is (the figures' x axis)."""
    sizes: tuple[int, ...]
    env_ids: tuple[str, ...]
    """The environment id of each size."""
    budgets: tuple[int, ...]
    """Environment steps of a run at each size."""
    threshold: float | tuple[float, ...]
    """Solved: a greedy evaluation's :attr:`measured_by` (its mean return, or its success rate)
    is at least this: one value for every size, or one per size (:meth:`threshold_at`)."""
    solved: str
    """What reaching the threshold means (the report)."""
    goal: float
    """A training episode whose :attr:`measured_by` (its return, or its 0/1 success) is above
    this reached the reward (first-reward column)."""
    eval_every: int | tuple[int, ...]
    """Steps between greedy evaluations: one value for every size, or one per size
    (:meth:`eval_every_at`)."""
    eval_episodes: int
    bsuite: BsuiteCriterion | None = None
    """bsuite's own criterion (deep sea): its runs record bad_episodes.csv."""
    measured_by: Literal["return", "success"] = "return"
    """What :attr:`threshold` and :attr:`goal` apply to. "return": a greedy evaluation's mean
    return (eval.csv) and a training episode's return (metrics.csv). "success": the fraction of
    a greedy evaluation's episodes that ended with ``info["is_success"]`` (eval_success.csv) and a
    training episode's success flag (success.csv), where the return is too noisy to tell
    (stochastic deep sea)."""

    def __post_init__(self) -> None:
        if self.measured_by not in ("return", "success"):
            raise ValueError(f"measured_by must be 'return' or 'success', not {self.measured_by!r}")
        n = len(self.sizes)
        per_size = [self.env_ids, self.budgets]
        per_size += [v for v in (self.threshold, self.eval_every) if isinstance(v, tuple)]
        if any(len(v) != n for v in per_size):
            raise ValueError(f"a family needs one env id, budget (and so on) per size ({n})")

    def task(self, size: int) -> Task:
        i = self.sizes.index(size)
        return self.env_ids[i], self.budgets[i]

    def threshold_at(self, size: int) -> float:
        """The threshold of the tasks of this size."""
        t = self.threshold
        return t[self.sizes.index(size)] if isinstance(t, tuple) else t

    def eval_every_at(self, size: int) -> int:
        """Steps between the evaluations of a run at this size."""
        e = self.eval_every
        return e[self.sizes.index(size)] if isinstance(e, tuple) else e

    def rule_at(self, size: int) -> str:
        """The greedy criterion at this size, in words (the report's task table)."""
        what = "success rate" if self.measured_by == "success" else "mean return"
        return f"{what} >= {fmt(self.threshold_at(size))}"


CHAIN_SIZES = (5, 10, 20, 30, 50)
DRIFT_CHAIN_SIZES = (6, 10, 14, 20)
_MINIGRID_SOLVED = (
    "MiniGrid pays 1 - 0.9 t/T for reaching the goal at step t of its step limit T and 0 "
    "otherwise, so a mean of 0.5 needs the goal reached in more than half of the evaluation "
    "episodes"
)


def _minigrid(
    size: str, sizes: tuple[int, ...], ids: tuple[str, ...], budgets: tuple[int, ...]
) -> Family:
    """A MiniGrid family: solved at a mean return of 0.5, 10 evaluation episodes every 10k
    steps; a training episode with any reward reached the goal."""
    return Family(size, sizes, ids, budgets, 0.5, _MINIGRID_SOLVED, 0.0, 10_000, 10)


DEEP_SEA_MAX_EPISODES = 3_000
"""The most training episodes of a deep sea run (bsuite runs 10,000): the one place to change
every deep sea budget (:func:`episodes_budget`)."""
DEEP_SEA_SIZES = (6, 8, 10, 12, 14, 17, 20, 24, 30)
DEEP_SEA_STOCHASTIC_SIZES = (6, 10, 14, 20)
DEEP_SEA_STOCHASTIC_EVAL_EPISODES = 20


DEEP_SEA_MIN_EPISODES = 1_000
"""The fewest training episodes of a deep sea run (:func:`episodes_budget`)."""


def episodes_budget(size: int) -> int:
    """Training episodes of a deep sea run of side N: 2^N + 100 (bsuite's bound: a run that
    solves later does not beat dithering), at least :data:`DEEP_SEA_MIN_EPISODES` and at most
    :data:`DEEP_SEA_MAX_EPISODES`. The floor gives the small sizes (2^N + 100 is 164 at N = 6)
    time for the greedy criterion; it changes no bsuite verdict, since bsuite itself runs 10,000
    episodes at every size and counts a solve only before episode 2^N + 100."""
    return min(max(2**size + BSUITE_FORGIVENESS, DEEP_SEA_MIN_EPISODES), DEEP_SEA_MAX_EPISODES)


def budget_steps(size: int) -> int:
    """Environment steps of a deep sea run of side N: every episode lasts exactly N steps."""
    return size * episodes_budget(size)


def deep_sea_success_probability(size: int, stochastic: bool = False) -> float:
    """The probability that the optimal policy takes the treasure in deep sea of side N: 1, and
    in the stochastic version (1 - 1/N)^(N - 1), as the N - 1 right moves before the last must
    each succeed (probability 1 - 1/N) and the last row's right action pays regardless."""
    return (1 - 1 / size) ** (size - 1) if stochastic else 1.0


def deep_sea_optimal_return(size: int, stochastic: bool = False) -> float:
    """bsuite's optimal expected return of deep sea of side N (``DeepSea._optimal_return``):
    the reward 1 times :func:`deep_sea_success_probability`, less the move cost 0.01."""
    return deep_sea_success_probability(size, stochastic) - 0.01


def _deep_sea(stochastic: bool) -> Family:
    """bsuite's deep sea at :data:`DEEP_SEA_SIZES` (stochastic: :data:`DEEP_SEA_STOCHASTIC_SIZES`)
    with :func:`budget_steps`; bsuite's criterion beside the greedy one."""
    sizes = DEEP_SEA_STOCHASTIC_SIZES if stochastic else DEEP_SEA_SIZES
    ids = tuple(deep_sea_id(n, stochastic) for n in sizes)
    budgets = tuple(budget_steps(n) for n in sizes)
    if not stochastic:
        return Family(
            "grid side N",
            sizes,
            ids,
            budgets,
            threshold=0.5,
            solved="the only return above 0 is 0.99 (the reward 1 less the move cost 0.01): the "
            "greedy episode went right at every step; one evaluation episode (the task is "
            "deterministic) every max(100, 5 N) steps",
            goal=0.5,
            eval_every=tuple(max(100, 5 * n) for n in sizes),  # one episode of N steps: cheap
            eval_episodes=1,
            bsuite=BsuiteCriterion(threshold=0.9),
        )
    return Family(
        "grid side N",
        sizes,
        ids,
        budgets,
        threshold=tuple(0.5 * deep_sea_success_probability(n, stochastic=True) for n in sizes),
        solved="the success rate of a greedy evaluation (the fraction of its "
        f"{DEEP_SEA_STOCHASTIC_EVAL_EPISODES} episodes that took the treasure's +1, every 50 N "
        "steps, so 50 training episodes) is at least half of the optimal policy's success "
        "probability (1 - 1/N)^(N - 1) (the N - 1 right moves before the last each succeed with "
        "probability 1 - 1/N; the last row's right action pays regardless): 0.201 at N = 6 (5 "
        "of 20 episodes), 0.194 at N = 10 and 0.189 at N = 20 (4 of 20), which the optimal "
        "policy meets in about 95% (N = 6) and 97-98% (N >= 10) of evaluations. Whether an "
        "episode took the treasure is noise-free (the environment's is_success, from bsuite's "
        "denoised return), so a policy that never reaches it never passes, whereas the mean "
        "return, with the N(0, 1) noise of the two bottom corners (a standard deviation of 0.22 "
        "for a mean of 20), passes half of the optimal return in about 1 evaluation of 5 from "
        "the bottom-left corner alone. *First reward*: the first training "
        "episode that took the treasure (success.csv)",
        goal=0.5,  # a training episode's success is 0 or 1
        eval_every=tuple(50 * n for n in sizes),
        eval_episodes=DEEP_SEA_STOCHASTIC_EVAL_EPISODES,
        bsuite=BsuiteCriterion(threshold=0.8, min_episode=100),
        measured_by="success",
    )


FAMILIES: dict[str, Family] = {
    "chain": Family(
        size="chain length L",
        sizes=CHAIN_SIZES,
        env_ids=tuple(chain_id(n) for n in CHAIN_SIZES),
        budgets=tuple(max(10_000, 1_000 * n) for n in CHAIN_SIZES),
        threshold=SOLVED_RETURN,
        solved="the greedy episode reached the end of the chain (return 0.99; every other "
        "return is at most 0)",
        goal=SOLVED_RETURN,
        eval_every=100,  # one deterministic episode of at most L + 1 steps: cheap
        eval_episodes=1,
    ),
    # issue #25's first report: the chain's lock, where a wrong move drifts one state back and
    # the episode goes on to a time limit of L steps (deep sea's budget: every episode but a
    # success lasts L steps)
    "driftchain": Family(
        size="chain length L",
        sizes=DRIFT_CHAIN_SIZES,
        env_ids=tuple(drift_chain_id(n) for n in DRIFT_CHAIN_SIZES),
        budgets=tuple(budget_steps(n) for n in DRIFT_CHAIN_SIZES),
        threshold=SOLVED_RETURN,
        solved="the greedy episode reached the end of the chain, L right moves in a row (return "
        "0.99; every other return is at most 0)",
        goal=SOLVED_RETURN,
        eval_every=tuple(max(100, 5 * n) for n in DRIFT_CHAIN_SIZES),  # one episode of L steps
        eval_episodes=1,
    ),
    "doorkey": _minigrid(
        "grid side",
        (5, 6, 8),
        tuple(f"MiniGrid-DoorKey-{n}x{n}-v0" for n in (5, 6, 8)),
        (100_000, 250_000, 1_000_000),
    ),
    # the plainest MiniGrid room, no key and no door: the goal in the far corner; a random walk
    # reaches it at 5 x 5, so a run that never does has stopped exploring
    "empty": _minigrid(
        "grid side",
        (5, 8, 16),
        tuple(f"MiniGrid-Empty-{n}x{n}-v0" for n in (5, 8, 16)),
        (50_000, 100_000, 300_000),
    ),
    "keycorridor": _minigrid(
        "rows R",
        (1, 2, 3),
        tuple(f"MiniGrid-KeyCorridorS3R{n}-v0" for n in (1, 2, 3)),
        (100_000, 300_000, 1_000_000),
    ),
    "multiroom": _minigrid(
        "rooms N",
        (2, 4, 6),
        ("MiniGrid-MultiRoom-N2-S4-v0", "MiniGrid-MultiRoom-N4-S5-v0", "MiniGrid-MultiRoom-N6-v0"),
        (100_000, 1_000_000, 2_000_000),
    ),
    "mountaincar": Family(
        size="size (one)",
        sizes=(1,),
        env_ids=("MountainCar-v0",),
        budgets=(200_000,),
        threshold=-199.0,
        solved="the reward is -1 a step until the flag and an episode ends at 200 steps, so one "
        "that never reaches the flag returns -200: a mean of -199 or more means the car reached "
        "the flag in the evaluation episodes, on average at least one step before the 200-step "
        "limit",
        goal=-200.0,
        eval_every=5_000,
        eval_episodes=5,
    ),
    "acrobot": Family(
        size="size (one)",
        sizes=(1,),
        env_ids=("Acrobot-v1",),
        budgets=(100_000,),
        threshold=-100.0,  # Gymnasium's reward_threshold for Acrobot-v1
        solved="the reward is -1 a step until the tip swings over the line (0 at that step) and "
        "an episode ends at 500 steps, so one that never swings over returns -500: a mean of "
        "-100 or more (Gymnasium's reward_threshold for Acrobot-v1) means the evaluation "
        "episodes swung the tip over within about 100 steps on average",
        goal=-500.0,
        eval_every=5_000,
        eval_episodes=5,
    ),
    "frozenlake": Family(
        size="lake side",
        sizes=(4, 8),
        env_ids=("FrozenLake-v1", "FrozenLake8x8-v1"),
        budgets=(50_000, 200_000),
        threshold=0.5,
        solved="the lake is slippery (a move goes to either side of the one chosen with "
        "probability 2/3) and only reaching the goal pays (1); a greedy evaluation's mean return "
        "is the fraction of its 20 episodes that reached the goal, and 0.5 asks for half of "
        "them: the best policy reaches it within the time limit with probability 0.744 (4 x 4, "
        "100 steps) and 0.913 (8 x 8, 200 steps) by value iteration on the environment's own "
        "transition table, and so passes in 99% of evaluations at 4 x 4",
        goal=0.0,
        eval_every=5_000,
        eval_episodes=20,
    ),
    "deepsea": _deep_sea(stochastic=False),
    "deepsea-stochastic": _deep_sea(stochastic=True),
}

TASKS: dict[str, tuple[str, int]] = {
    env: (name, size)
    for name, family in FAMILIES.items()
    for size, env in zip(family.sizes, family.env_ids, strict=True)
}
"""Environment id -> (family, size)."""

# One config per agent for every task and size: the `auto` preset and these overrides only.
_ALWAYS = {"blr.optimism": "always"}
"""Pinned by the agents that compare kinds of target for the whole run (the general preset's
Farsighter switches to the posterior mean's cut target at its first positive reward since
docs/results/explore/until-reward-cut at commit 38d9854; the studies there that name them were
made before, with the targets for the whole run)."""
_KEPT = {"blr.switch_restart": "none"}
"""Pinned by the agents measured when the posterior kept its optimistic targets at the switch
(the general preset restarts it from its prior since session 37), so that their names still
say what their results in docs/results/explore (at commit 38d9854) are."""
_S39 = {
    "blr.switch_restart": "refit",
    "blr.stay_optimism": True,
    "blr.cut_delay": 0.0,
    "blr.advantage_learning": 0.0,
    "blr.revisit_action": "draw",
}
"""The general preset's Farsighter of session 39, before the rows kept without their targets
where the refit is rejected, no draw for staying put and the cut past 3 steps of delay became
its defaults (session 40), and advantage learning after the switch (session 41): pinned by the
agents that vary one of those pieces, so that they stay apart from the default."""

AGENTS: tuple[Agent, ...] = (
    Agent("DDQN", "ddqn"),
    Agent("k-DDQN", "kddqn"),
    Agent("BDQN", "bdqn"),
    # the library's default: a draw held for k steps since docs/results/explore/redraw-* (at
    # commit 38d9854, as every docs/results/explore path here); a draw per step (Algorithm 2)
    # before it, back to the DoorKey runs; per episode when docs/results/explore/report.md (the
    # chain) was made, so there "Farsighter" is per episode
    Agent("Farsighter", "farsighter"),
    Agent("Farsighter (redraw step)", "farsighter", {"blr.redraw": "step"}),
    Agent("Farsighter (redraw k)", "farsighter", {"blr.redraw": "k"}),
    Agent("Farsighter (redraw episode)", "farsighter", {"blr.redraw": "episode"}),
    # held while the episode reaches new states, redrawn when it returns to one
    Agent("Farsighter (redraw revisit)", "farsighter", {"blr.redraw": "revisit"}),
    # the plain k-step target, against the default's max with the one-step target (whose upward
    # bias the stochastic deep sea tests)
    Agent("Farsighter (k-step target)", "farsighter", {"k_target": "k", **_ALWAYS}),
    # the posterior mean at the next state, against the default's posterior draw there (whose
    # optimism is a bonus at every step that does not end the episode)
    Agent("Farsighter (mean target)", "farsighter", {"blr.target": "mean", **_ALWAYS}),
    Agent(
        "Farsighter (mean, k-step target)",
        "farsighter",
        {"blr.target": "mean", "k_target": "k", **_ALWAYS},
    ),
    # the posterior over the learned features and 512 fixed random features of the observation,
    # so that its uncertainty is about states (farsighter.networks.RandomFeatureTorso): the
    # default since docs/results/explore/random-features* at commit 38d9854; over the learned
    # features alone before it (every study there made before those)
    Agent("Farsighter (random features)", "farsighter", {"blr.random_features": 512}),
    Agent("Farsighter (learned features)", "farsighter", {"blr.random_features": 0}),
    # the sampled target's optimism centred in each minibatch (blr.center_sample), against the
    # default's raw draw, whose bonus at every step that does not end the episode FrozenLake shows
    Agent("Farsighter (centred draw)", "farsighter", {"blr.center_sample": True, **_ALWAYS}),
    # a prior three times the noise floor (bsuite's bootstrapped DQN scales its prior functions
    # by 3), against the default's prior equal to it: wider uncertainty where the run has not
    # been, against the same shrinkage where it has
    Agent("Farsighter (prior 3)", "farsighter", {"blr.prior_std": 3.0}),
    Agent("Farsighter (prior 10)", "farsighter", {"blr.prior_std": 10.0}),
    Agent("OB2I", "ob2i"),
    Agent("RND", "rnd"),
    # random Fourier features in place of the random ReLU features: the same width, but two
    # distinct one-hot states' features share almost nothing (benchmarks/feature_novelty.py)
    Agent("Farsighter (Fourier features)", "farsighter", {"blr.random_features_kind": "fourier"}),
    # each minibatch row weighs 100 times train_every / batch_size in the posterior's statistics:
    # its mean follows a rarely seen reward from a few samples where the default's needs the
    # row's whole time in the replay, while its width where the run has not been stays the
    # prior's (benchmarks/deepsea_frontier.py --set blr.data_weight=100): the default since
    # docs/results/explore/dataweight-* at commit 38d9854; 1 before it (every study there made
    # before)
    Agent("Farsighter (data weight 100)", "farsighter", {"blr.data_weight": 100.0}),
    Agent("Farsighter (data weight 1)", "farsighter", {"blr.data_weight": 1.0}),
    # the random layer 512 wide whatever the observation, against the default's, widened to the
    # observation's entries up to 1,024 (blr.random_features_max; deep sea N = 30: 900)
    Agent("Farsighter (fixed width)", "farsighter", {"blr.random_features_max": 0}),
    # the k-step or the one-step target chosen by their values under the posterior mean, with
    # the chosen one's draw, against the default's larger of the two drawn targets (whose
    # upward bias, compounded by bootstrapping, lifts Q on DoorKey-5x5 to about 15 where no
    # return exceeds 1: benchmarks/value_calibration.py)
    Agent("Farsighter (max by mean)", "farsighter", {"k_target": "max-mean", **_ALWAYS}),
    # the target's draw of the action greedy under the mean (zero-mean noise), against the
    # default's largest of the actions' draws (blr.target sample-greedy)
    Agent(
        "Farsighter (greedy-action draw)", "farsighter", {"blr.target": "sample-greedy", **_ALWAYS}
    ),
    # both upward biases of the default's target out: the greedy action's draw and the k-step
    # target alone (DoorKey-5x5: Q at the start 0.10, where the default's is 14.4)
    Agent(
        "Farsighter (greedy-action draw, k-step target)",
        "farsighter",
        {"blr.target": "sample-greedy", "k_target": "k", **_ALWAYS},
    ),
    # no draw chooses: the greedy action's draw, and the k-step or the one-step target by their
    # means (the optimality-tightening max kept, the larger of two drawn targets' bias out)
    Agent(
        "Farsighter (greedy-action draw, max by mean)",
        "farsighter",
        {"blr.target": "sample-greedy", "k_target": "max-mean", **_ALWAYS},
    ),
    # the default's optimism until the run's first positive reward, then the posterior mean's
    # k-step target (blr.optimism until-reward): the bias for the locks that pay only at their
    # end, none once the task has paid (MiniGrid Empty-5x5 and DoorKey-5x5: docs/design.md)
    Agent(
        "Farsighter (optimism until reward)",
        "farsighter",
        {"blr.optimism": "until-reward", "blr.calibrated_k_target": "k", **_KEPT},
    ),
    # the k-step target cut before the first exploratory action (Watkins), against the default's
    # larger of the k-step and the one-step target (whose upward bias is a bonus for not ending
    # the episode); alone, with the posterior mean's targets, and after the first reward
    Agent("Farsighter (cut)", "farsighter", {"k_target": "cut", **_ALWAYS}),
    Agent(
        "Farsighter (mean, cut)", "farsighter", {"blr.target": "mean", "k_target": "cut", **_ALWAYS}
    ),
    Agent(
        "Farsighter (cut, optimism until reward)",
        "farsighter",
        {"k_target": "cut", "blr.optimism": "until-reward"},
    ),
    # the default's targets until the first positive reward, then the mean's target cut there,
    # the posterior keeping what it had summed: the defaults from
    # docs/results/explore/until-reward-cut (at commit 38d9854) to session 36 (the targets
    # kept at the switch)
    Agent(
        "Farsighter (optimism until reward, then cut)",
        "farsighter",
        {"blr.optimism": "until-reward", "blr.calibrated_k_target": "cut", **_S39, **_KEPT},
    ),
    # the cut only where the posterior is sure the action taken was worse (blr.cut_margin)
    Agent("Farsighter (cut margin 1)", "farsighter", {"blr.cut_margin": 1.0, **_S39, **_KEPT}),
    # the posterior restarted from its prior at the switch (blr.switch_restart prior): its mean
    # fit to the calibrated targets alone, its width the prior's again where the run has not been
    # since; or its targets zeroed (zero-targets): the mean from 0, the width kept. The first was
    # the default in sessions 37 and 38
    Agent("Farsighter (switch restart)", "farsighter", {**_S39, "blr.switch_restart": "prior"}),
    Agent(
        "Farsighter (switch restart, k-step)",
        "farsighter",
        {**_S39, "blr.switch_restart": "prior", "blr.calibrated_k_target": "k"},
    ),
    Agent(
        "Farsighter (switch restart, cut margin 1)",
        "farsighter",
        {**_S39, "blr.switch_restart": "prior", "blr.cut_margin": 1.0},
    ),
    Agent(
        "Farsighter (zero targets)", "farsighter", {**_S39, "blr.switch_restart": "zero-targets"}
    ),
    # or refitted to the replay by fitted Q-iteration (blr.switch_restart refit): the values the
    # rewards confirm (the found path, the learned penalties) without the optimism's, a fit that
    # passes the largest reward sum the replay showed dropped (session 38): session 39's
    # default, pinned (docs/design.md "The posterior refitted at the switch")
    Agent("Farsighter (refit at switch)", "farsighter", {**_S39}),
    Agent(
        "Farsighter (zero targets, cut margin 1)",
        "farsighter",
        {**_S39, "blr.switch_restart": "zero-targets", "blr.cut_margin": 1.0},
    ),
    # the cut only where the action taken costs more than 3 steps of delay (blr.cut_delay)
    Agent(
        "Farsighter (zero targets, cut delay 3)",
        "farsighter",
        {**_S39, "blr.switch_restart": "zero-targets", "blr.cut_delay": 3.0},
    ),
    # the same delay rule with the optimistic targets kept at the switch (no restart)
    Agent("Farsighter (cut delay 3)", "farsighter", {**_S39, "blr.cut_delay": 3.0, **_KEPT}),
    # the optimism taken up again after 10 episodes in a row unpaid since the switch
    # (blr.rearm_episodes), with the default cut and with the cut past 3 steps of delay
    Agent("Farsighter (rearm 10)", "farsighter", {**_S39, "blr.rearm_episodes": 10}),
    Agent(
        "Farsighter (rearm 10, cut delay 3)",
        "farsighter",
        {**_S39, "blr.rearm_episodes": 10, "blr.cut_delay": 3.0},
    ),
    # no draw in a target whose window ends where it began (blr.stay_optimism False): no
    # optimism for staying put
    Agent("Farsighter (no optimism in place)", "farsighter", {**_S39, "blr.stay_optimism": False}),
    # and the draw redrawn when the episode returns to an observation it saw (blr.redraw
    # revisit), so a held draw does not repeat an action that leaves the agent where it is
    Agent(
        "Farsighter (no optimism in place, redraw revisit)",
        "farsighter",
        {**_S39, "blr.stay_optimism": False, "blr.redraw": "revisit"},
    ),
    # and with the targets zeroed at the switch and the cut past 3 steps of delay
    Agent(
        "Farsighter (no optimism in place, zero targets, cut delay 3)",
        "farsighter",
        {"blr.stay_optimism": False, "blr.switch_restart": "zero-targets", "blr.cut_delay": 3.0},
    ),
    # the same with the refit at the switch, the rows kept without their targets where the
    # fit is dropped (blr.switch_restart refit-zero): the found path kept where the fit is
    # sound (deep sea), the rooms' inflated values zeroed where it overestimates (DoorKey); the
    # default of session 40 (pinned: without advantage learning, the default since session 41)
    Agent(
        "Farsighter (no optimism in place, refit or zero targets, cut delay 3)",
        "farsighter",
        {
            "blr.stay_optimism": False,
            "blr.switch_restart": "refit-zero",
            "blr.cut_delay": 3.0,
            "blr.advantage_learning": 0.0,
            "blr.revisit_action": "draw",
        },
    ),
    # the acting draws at the posterior's own width (the default before the draws were widened
    # to the action gaps, blr.act_width action-gap)
    Agent("Farsighter (posterior width)", "farsighter", {"blr.act_width": "posterior"}),
    # the calibrated targets under the advantage-learning operator, alpha 0.9 (Bellemare et al.
    # 2016): the gaps between the greedy action and a wasted step widened tenfold, so that the
    # posterior mean's greedy policy does not repeat a step that changes nothing (DoorKey); the
    # default since session 41 (session 41's default: the draw's action at every revisit)
    Agent(
        "Farsighter (advantage learning 0.9)",
        "farsighter",
        {"blr.advantage_learning": 0.9, "blr.revisit_action": "draw"},
    ),
    # a uniformly random action where the episode is back at an observation it visited: the
    # loops a held or narrow draw walks before the first reward (DoorKey-6x6) are broken
    Agent("Farsighter (uniform at revisits)", "farsighter", {"blr.revisit_action": "uniform"}),
    # the same in an episode after one that paid no positive reward (the draws alone after a
    # paid one: a run that reaches its goal acts as before)
    Agent(
        "Farsighter (uniform at revisits after unpaid episodes)",
        "farsighter",
        {"blr.revisit_action": "uniform-unpaid"},
    ),
    # the same in an episode after one that ran to its time limit (a loop never ends an
    # episode; a fall into a hole or a goal does); the default since session 42, the same
    # config as "Farsighter"
    Agent(
        "Farsighter (uniform at revisits after time limits)",
        "farsighter",
        {"blr.revisit_action": "uniform-timeout"},
    ),
)
# Every named Farsighter variant was measured as a change of the general preset's Farsighter of
# session 45 (docs/results/explore at commit 38d9854), and is kept as that change: its base is
# that default (PREVIOUS_GENERAL_FARSIGHTER), so a label still names the config its results were
# made with.
# "Farsighter" alone is the library's default.
AGENTS = tuple(
    Agent(a.label, a.algo, {**PREVIOUS_GENERAL_FARSIGHTER, **a.overrides})
    if a.label.startswith("Farsighter (")
    else a
    for a in AGENTS
)
COLORS = {a.label: f"C{i}" for i, a in enumerate(AGENTS)}
_NAMED_ONLY = (
    "Farsighter (redraw k)",
    "Farsighter (mean target)",
    "Farsighter (mean, k-step target)",
    "Farsighter (random features)",
    "Farsighter (learned features)",
    "Farsighter (centred draw)",
    "Farsighter (prior 3)",
    "Farsighter (prior 10)",
    "Farsighter (Fourier features)",
    "Farsighter (data weight 100)",
    "Farsighter (data weight 1)",
    "Farsighter (fixed width)",
    "Farsighter (max by mean)",
    "Farsighter (greedy-action draw)",
    "Farsighter (greedy-action draw, k-step target)",
    "Farsighter (greedy-action draw, max by mean)",
    "Farsighter (optimism until reward)",
    "Farsighter (cut)",
    "Farsighter (mean, cut)",
    "Farsighter (cut, optimism until reward)",
    "Farsighter (optimism until reward, then cut)",
    "Farsighter (cut margin 1)",
    "Farsighter (switch restart)",
    "Farsighter (switch restart, k-step)",
    "Farsighter (switch restart, cut margin 1)",
    "Farsighter (zero targets)",
    "Farsighter (zero targets, cut margin 1)",
    "Farsighter (zero targets, cut delay 3)",
    "Farsighter (cut delay 3)",
    "Farsighter (rearm 10)",
    "Farsighter (rearm 10, cut delay 3)",
    "Farsighter (no optimism in place)",
    "Farsighter (no optimism in place, redraw revisit)",
    "Farsighter (no optimism in place, zero targets, cut delay 3)",
    "Farsighter (no optimism in place, refit or zero targets, cut delay 3)",
    "Farsighter (posterior width)",
    "Farsighter (refit at switch)",
    "Farsighter (advantage learning 0.9)",
    "Farsighter (uniform at revisits)",
    "Farsighter (uniform at revisits after unpaid episodes)",
    "Farsighter (uniform at revisits after time limits)",
)
DEFAULT_AGENTS = tuple(a.label for a in AGENTS if a.label not in _NAMED_ONLY)
"""The default list: every agent once but those run only when named. "Farsighter (redraw k)" and
"Farsighter (random features)", "Farsighter (data weight 100)" and "Farsighter (optimism until
reward, then cut)" build the same config as "Farsighter" now that a draw held for k steps, the
random features, the data weight 100 and the switch at the first reward are the defaults (the
saved studies under docs/results/explore at commit 38d9854 name them); the two mean-target
variants belong to the comparison of the targets (docs/results/explore/targets at 38d9854), and
"Farsighter (learned features)" to that of the features."""


@dataclass(frozen=True)
class StudyConfig:
    """What a study runs; saved as study.json."""

    families: tuple[str, ...] = tuple(FAMILIES)
    sizes: tuple[int, ...] = ()  # empty: every size of each family
    seeds: tuple[int, ...] = (1, 2, 3, 4, 5)
    steps: int = 0  # 0: each task's own budget; otherwise a cap on every budget
    episodes: int = 0  # deep sea runs: 0, episodes_budget(N); otherwise this many episodes
    workers: int = 0  # 0: one per core
    agents: tuple[str, ...] = DEFAULT_AGENTS


QUICK = StudyConfig(
    families=("chain",), sizes=(5, 10, 20), seeds=(1, 2, 3), agents=("DDQN", "BDQN", "Farsighter")
)


@dataclass(frozen=True)
class Args(StudyArgs):
    """The flags of ``farsighter explore``: the shared ones and the suite's."""

    steps: Annotated[int | None, runner.study_flag("N")] = None
    """Cap on every task's step budget (0: each task's own budget)."""
    episodes: Annotated[int | None, runner.study_flag("N")] = None
    """Deep sea runs (both families) train for N episodes (0: 2^N + 100, at least 1,000 and at
    most 3,000); bsuite itself runs 10,000, so --episodes 10000 scores bsuite's criterion over
    bsuite's whole run. --steps still caps."""
    families: Annotated[tuple[str, ...] | None, runner.study_flag("NAME [NAME ...]")] = None
    """Task families: chain, driftchain, doorkey, keycorridor, multiroom, mountaincar, acrobot,
    frozenlake, deepsea, deepsea-stochastic."""
    sizes: Annotated[tuple[int, ...] | None, runner.study_flag("N [N ...]")] = None
    """Only these sizes of the chosen families (none given: every size)."""


def tasks(study: StudyConfig) -> tuple[Task, ...]:
    """(environment id, step budget) of every task of the study, family by family."""
    out = []
    for name in study.families:
        family = FAMILIES[name]
        for size in family.sizes:
            if not study.sizes or size in study.sizes:
                env, budget = family.task(size)
                if family.bsuite and study.episodes:  # deep sea: every episode lasts N steps
                    budget = size * study.episodes
                out.append((env, min(budget, study.steps) if study.steps else budget))
    return tuple(out)


def run_config(agent: Agent, study: StudyConfig, seed: int, run_dir: Path, task: Task) -> Config:
    """The library's default for the task (``auto``) and the agent's overrides; the family's
    evaluation settings and no replay in the final checkpoint (measurement, not tuning)."""
    env, steps = task
    name, size = TASKS[env]
    family, every = FAMILIES[name], FAMILIES[name].eval_every_at(size)
    return runner.run_config(
        agent,
        env,
        "auto",
        seed,
        steps,
        run_dir,
        eval_every=every,
        eval_episodes=family.eval_episodes,
        checkpoint_every=0,
        save_replay=False,  # a MiniGrid run's replay is gigabytes; the study never resumes one
        log_every=max(every, 1_000),
    )


def _sizes(names: Sequence[str]) -> str:
    return "; ".join(f"{n}: {' '.join(map(str, FAMILIES[n].sizes))}" for n in names)


def _check(study: StudyConfig) -> None:
    accepted = ", ".join(FAMILIES)
    unknown = [f for f in study.families if f not in FAMILIES]
    if unknown:
        raise FarsighterError(f"unknown explore family(ies) {unknown}; accepted: {accepted}")
    if not study.families:
        raise FarsighterError(f"--families must name at least one of: {accepted}")
    if len(set(study.families)) != len(study.families):
        raise FarsighterError("--families name a family twice")
    if study.steps < 0:
        raise FarsighterError(f"--steps must be >= 0 (0: each task's budget; got {study.steps})")
    if study.episodes < 0:
        raise FarsighterError(
            f"--episodes must be >= 0 (0: each deep sea size's own; got {study.episodes})"
        )
    chosen = {s for f in study.families for s in FAMILIES[f].sizes}
    stray = [s for s in study.sizes if s not in chosen]
    if stray:
        raise FarsighterError(
            f"--sizes {' '.join(map(str, stray))} is no size of the chosen families "
            f"({_sizes(study.families)})"
        )
    for name in study.families:
        if study.sizes and not set(study.sizes) & set(FAMILIES[name].sizes):
            raise FarsighterError(f"--sizes leave family {name} without a task ({_sizes([name])})")
    for env, steps in tasks(study):
        name, size = TASKS[env]
        if FAMILIES[name].bsuite and steps < size:
            raise FarsighterError(
                f"--steps {steps} leaves {env} without an episode (each lasts {size} steps)"
            )
    from farsighter.config import make_config
    from farsighter.envs import make_env

    for env, _ in tasks(study):  # a missing extra (minigrid, bsuite) fails here, before any run
        make_env(make_config("ddqn", env), seed=0).close()


# ------------------------------------------------------------------------------------------------
# Measures: per run, then per family x size x agent, then the growth per family x agent.
# ------------------------------------------------------------------------------------------------


def measure(
    run: dict[str, Any],
    threshold: float,
    goal: float,
    measured_by: Literal["return", "success"] = "return",
) -> dict[str, Any]:
    """One run's measures from its metrics.csv and eval.csv (NaN where a run never got there);
    ``measured_by="success"`` (:attr:`Family.measured_by`): from eval_success.csv and success.csv
    instead, the evaluations' success rates and the training episodes' success flags.

    solved: some evaluation's mean return (success rate) reached ``threshold``;
    episodes_to_solve and steps_to_solve: the training episodes finished and the step at the
    first such evaluation; held: the final evaluation is at the threshold;
    episodes_to_first_reward: the first training episode whose return (success) is above
    ``goal``; episodes: training episodes in all.
    """
    m, e = run["metrics"] or {}, run["eval"] or {}
    ep_steps = m.get("global_step", np.array([]))
    returns = m.get("episodic_return", np.array([]))
    ev_steps = e.get("global_step", np.array([]))
    ev = e.get("eval_return_mean", np.array([]))
    episode = np.arange(1.0, len(returns) + 1)
    reached = returns
    if measured_by == "success":
        if len(ev) and run.get("eval_success") is None:
            where = f" ({run['task']}, seed {run['seed']})" if "task" in run else ""
            raise FarsighterError(
                f"a run{where} has evaluations but no eval_success.csv: its environment reported "
                "no info['is_success'] (a deep sea run recorded before the adapter did); run it "
                "again"
            )
        e, s = run.get("eval_success") or {}, run.get("success") or {}
        ev_steps = e.get("global_step", np.array([]))
        ev = e.get("eval_success_rate", np.array([]))
        episode = s.get("episode", np.array([]))
        reached = s.get("success", np.array([]))
    hit = np.flatnonzero(ev >= threshold)
    first = float(ev_steps[hit[0]]) if len(hit) else float("nan")
    reward = np.flatnonzero(reached > goal)
    return {
        "solved": bool(len(hit)),
        "episodes_to_solve": float(np.sum(ep_steps <= first)) if len(hit) else float("nan"),
        "steps_to_solve": first,
        "held": bool(len(ev) and ev[-1] >= threshold),
        "episodes_to_first_reward": float(episode[reward[0]]) if len(reward) else float("nan"),
        "episodes": len(returns),
    }


def bsuite_solution(
    bad: Sequence[bool] | np.ndarray,
    threshold: float,
    min_episode: int = 1,
    max_episode: int = BSUITE_NUM_EPISODES,
) -> int | None:
    """bsuite's deep sea ``find_solution`` for one run: the first episode (counted from 1)
    between ``min_episode`` and ``max_episode`` where the running fraction of bad episodes, all
    bad episodes up to it (the earlier ones included) over its number, is below ``threshold``;
    None if there is none. bsuite logs (and so checks) only at logarithmically spaced episodes
    (1-10, 12, 14, 17, 20, 25, ...); this checks every episode, so it can find an episode a
    little earlier than bsuite's table would."""
    b = np.asarray(bad, dtype=float)
    episode = np.arange(1, len(b) + 1)
    below = (np.cumsum(b) / episode < threshold) & (episode >= min_episode)
    hit = np.flatnonzero(below & (episode <= max_episode))
    return int(episode[hit[0]]) if len(hit) else None


def beats_dithering(episode: int | None, size: int) -> bool:
    """bsuite's deep sea score of one run at side N: solved, at an episode below 2^N + 100."""
    return episode is not None and episode < 2**size + BSUITE_FORGIVENESS


def bsuite_measure(
    run: dict[str, Any], size: int, criterion: BsuiteCriterion | None
) -> dict[str, Any]:
    """bsuite's criterion on one run's bad_episodes.csv: bsuite_solved (beats dithering; None
    where the family has no bsuite criterion or the run recorded no bad flags) and
    bsuite_episode (:func:`bsuite_solution`'s episode; NaN where none)."""
    flags = run.get("bad_episodes")
    if criterion is None or flags is None:
        return {"bsuite_solved": None, "bsuite_episode": float("nan")}
    episode = bsuite_solution(flags.get("bad", []), criterion.threshold, criterion.min_episode)
    return {
        "bsuite_solved": beats_dithering(episode, size),
        "bsuite_episode": float("nan") if episode is None else float(episode),
    }


BAD_EPISODES_FILE = "bad_episodes.csv"


def ended_bad_flags(info: dict[str, Any]) -> list[bool] | None:
    """The bad flags (``info["bad_episode"]``) of the episodes that ended at this vector step,
    in environment order; None where the environments report no such flag. The loop's vector
    environment resets an ended episode in the same step (Gymnasium's SAME_STEP autoreset), so
    the ended episode's info is ``info["final_info"]``; without it (NEXT_STEP) it is ``info``
    itself. Either way ``_episode`` marks the environments whose episode ended."""
    src = info["final_info"] if "final_info" in info else info
    if "bad_episode" not in src and "bad_episode" not in info:
        return None
    ended = src.get("_episode")
    if ended is None or "bad_episode" not in src:
        return []
    return [bool(src["bad_episode"][i]) for i in np.flatnonzero(ended)]


class BadEpisodeLog:
    """Read-only callback: the bad flag of every training episode, written to
    bad_episodes.csv (global_step, episode, bad) at the end of a run whose environment reports
    ``bad_episode`` (deep sea); other runs write nothing."""

    def __init__(self) -> None:
        self.rows: list[dict[str, int]] = []
        self.reported = False

    def on_step(self, global_step: int, info: dict[str, Any], agent: Any) -> None:
        flags = ended_bad_flags(info)
        if flags is None:
            return
        self.reported = True
        for bad in flags:
            row = {"global_step": global_step, "episode": len(self.rows) + 1, "bad": int(bad)}
            self.rows.append(row)

    def on_finish(self, run_dir: Path, agent: Any) -> None:
        if not self.reported:
            return
        with (run_dir / BAD_EPISODES_FILE).open("w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=["global_step", "episode", "bad"])
            writer.writeheader()
            writer.writerows(self.rows)


def _bad_episode_log(study: StudyConfig) -> BadEpisodeLog:
    return BadEpisodeLog()


def censored_median(values: Sequence[float], censored: Sequence[bool]) -> tuple[float, bool]:
    """The median of ``values`` where a censored value is a lower bound (the run ended first),
    and whether the median is itself only a lower bound (raising the censored values would
    raise it)."""
    v, c = np.asarray(values, dtype=float), np.asarray(censored, dtype=bool)
    median = float(np.median(v))
    return median, float(np.median(np.where(c, np.inf, v))) != median


def per_run(runs: Runs) -> list[dict[str, Any]]:
    """One row per finished run: where it ran, its :func:`measure` and its
    :func:`bsuite_measure`."""
    rows = []
    for label, items in runs.items():
        for run in items:
            name, size = TASKS[run["task"]]
            family = FAMILIES[name]
            rows.append(
                {
                    "family": name,
                    "size": size,
                    "env": run["task"],
                    "agent": label,
                    "seed": run["seed"],
                    "budget": run["steps"],
                    **measure(run, family.threshold_at(size), family.goal, family.measured_by),
                    **bsuite_measure(run, size, family.bsuite),
                }
            )
    return rows


@dataclass(frozen=True)
class SolveMeasure:
    """One way to count the episodes a run took to solve, and its columns in the table."""

    name: str
    text: str
    """What it counts (the report)."""
    solved: str
    """Table column: seeds solved."""
    median: str
    """Table column: the censored median episode."""
    censored: str
    """Table column: whether that median is only a lower bound."""


SOLVE_MEASURES = {
    "greedy": SolveMeasure(
        "greedy",
        "training episodes to the first greedy evaluation at the threshold",
        "seeds_solved",
        "median_episodes_to_solve",
        "episodes_censored",
    ),
    "bsuite": SolveMeasure(
        "bsuite",
        "bsuite's episode to solve (bad-episode fraction)",
        "seeds_bsuite_solved",
        "median_bsuite_episode",
        "bsuite_censored",
    ),
}


def measures_of(family: str) -> tuple[str, ...]:
    """The solve measures of a family: greedy, and bsuite's where it has a criterion."""
    return ("greedy", "bsuite") if FAMILIES[family].bsuite else ("greedy",)


def primary_measure(family: str) -> str:
    """The measure the claims use: bsuite's for deep sea, the greedy one elsewhere."""
    return measures_of(family)[-1]


def seed_values(rs: Sequence[dict[str, Any]], measure: str) -> tuple[list[float], list[bool]]:
    """Per run of ``rs`` (:func:`per_run` rows), the episode it solved at by ``measure`` or,
    unsolved, its episodes in all (a lower bound), and whether it is such a bound. bsuite's
    measure leaves out the runs without bad flags."""
    if measure == "greedy":
        solved = [bool(r["solved"]) for r in rs]
        key = "episodes_to_solve"
    else:
        rs = [r for r in rs if r["bsuite_solved"] is not None]
        solved = [bool(r["bsuite_solved"]) for r in rs]
        key = "bsuite_episode"
    values = [
        float(r[key]) if ok else float(r["episodes"]) for r, ok in zip(rs, solved, strict=True)
    ]
    return values, [not ok for ok in solved]


def _cells(rows: list[dict[str, Any]]) -> dict[tuple[str, int, str], list[dict[str, Any]]]:
    """Rows by (family, size, agent): families and agents in their order in ``rows``, sizes
    ascending."""
    families = list(dict.fromkeys(r["family"] for r in rows))
    agents = list(dict.fromkeys(r["agent"] for r in rows))
    cells: dict[tuple[str, int, str], list[dict[str, Any]]] = {}
    for r in sorted(
        rows, key=lambda r: (families.index(r["family"]), r["size"], agents.index(r["agent"]))
    ):
        cells.setdefault((r["family"], r["size"], r["agent"]), []).append(r)
    return cells


def summarise(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per family x size x agent (families and agents in their order in ``rows``, sizes
    ascending): seeds solved and held, and the median episodes and steps to solve with unsolved
    seeds censored at the run's end; on deep sea, the seeds that beat dithering by bsuite's
    criterion and the median of bsuite's episode to solve, censored likewise (NaN, None
    elsewhere)."""
    table = []
    for (family, size, agent), rs in _cells(rows).items():
        unsolved = [not r["solved"] for r in rs]
        episodes, _ = seed_values(rs, "greedy")
        steps = [r["budget"] if not r["solved"] else r["steps_to_solve"] for r in rs]
        no_reward = [not np.isfinite(r["episodes_to_first_reward"]) for r in rs]
        first = [
            r["episodes"] if c else r["episodes_to_first_reward"]
            for r, c in zip(rs, no_reward, strict=True)
        ]
        med_ep, ep_cens = censored_median(episodes, unsolved)
        med_st, st_cens = censored_median(steps, unsolved)
        med_fr, fr_cens = censored_median(first, no_reward)
        bs_values, bs_unsolved = seed_values(rs, "bsuite")
        med_bs, bs_cens = (
            censored_median(bs_values, bs_unsolved) if bs_values else (float("nan"), None)
        )
        table.append(
            {
                "family": family,
                "size": size,
                "env": rs[0]["env"],
                "budget": rs[0]["budget"],
                "agent": agent,
                "seeds": len(rs),
                "seeds_solved": sum(r["solved"] for r in rs),
                "seeds_held": sum(r["held"] for r in rs),
                "median_episodes_to_solve": med_ep,
                "episodes_censored": ep_cens,
                "median_steps_to_solve": med_st,
                "steps_censored": st_cens,
                "median_episodes_to_first_reward": med_fr,
                "first_reward_censored": fr_cens,
                "seeds_bsuite": len(bs_values) if bs_values else None,
                "seeds_bsuite_solved": bs_unsolved.count(False) if bs_values else None,
                "median_bsuite_episode": med_bs,
                "bsuite_censored": bs_cens,
            }
        )
    return table


def _line(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Least-squares slope of y on x, and R^2 (NaN where y does not vary)."""
    slope, intercept = np.polyfit(x, y, 1)
    ss_res = float(np.sum((y - (slope * x + intercept)) ** 2))
    ss_tot = float(np.sum((y - y.mean()) ** 2))
    return float(slope), 1.0 - ss_res / ss_tot if ss_tot > 1e-12 else float("nan")


MIN_SIZES = 3


def fit_growth(sizes: Sequence[float], episodes: Sequence[float]) -> dict[str, Any]:
    """Episodes against size: polynomial, log(episodes) = p log(size) + c, and exponential,
    log(episodes) = r size + c, by least squares, each with its R^2, and which fits better
    (higher R^2). Fewer than :data:`MIN_SIZES` sizes: "not enough sizes". Episodes below 1 count
    as 1."""
    x, y = np.asarray(sizes, dtype=float), np.log(np.maximum(np.asarray(episodes, float), 1.0))
    nan = float("nan")
    if len(x) < MIN_SIZES:
        return {
            "n_sizes": len(x),
            "p": nan,
            "r2_poly": nan,
            "r": nan,
            "r2_exp": nan,
            "better": "not enough sizes",
        }
    p, r2_poly = _line(np.log(x), y)
    r, r2_exp = _line(x, y)
    better = "polynomial" if r2_poly > r2_exp else "exponential" if r2_exp > r2_poly else "neither"
    return {
        "n_sizes": len(x),
        "p": p,
        "r2_poly": r2_poly,
        "r": r,
        "r2_exp": r2_exp,
        "better": better,
    }


BOOTSTRAP_RESAMPLES = 1_000
BOOTSTRAP_SEED = 0


def bootstrap_exponent(
    sizes: Sequence[float],
    samples: Sequence[Sequence[float]],
    resamples: int = BOOTSTRAP_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> tuple[float, float]:
    """A 95% percentile-bootstrap interval on the polynomial exponent p of :func:`fit_growth`:
    ``resamples`` times, each size's per-seed values (``samples``, censored ones at their lower
    bound) are drawn again with replacement within that size, their median taken (so the
    censored median) and p refitted by least squares; the 2.5 and 97.5 percentiles of the p's.
    Fewer than :data:`MIN_SIZES` sizes: (NaN, NaN)."""
    if len(sizes) < MIN_SIZES:
        return float("nan"), float("nan")
    rng = np.random.default_rng(seed)
    log_y = np.empty((resamples, len(sizes)))
    for j, values in enumerate(samples):
        v = np.asarray(values, dtype=float)
        draws = v[rng.integers(len(v), size=(resamples, len(v)))]
        log_y[:, j] = np.log(np.maximum(np.median(draws, axis=1), 1.0))
    x = np.log(np.asarray(sizes, dtype=float))
    x = x - x.mean()
    p = (log_y - log_y.mean(axis=1, keepdims=True)) @ x / (x @ x)
    lo, hi = np.percentile(p, [2.5, 97.5])
    return float(lo), float(hi)


def growth(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per family x agent x solve measure (:func:`measures_of`), from the :func:`per_run` rows:
    :func:`fit_growth` of the censored median episodes to solve over the sizes where at least
    one seed solved, how many of those medians are lower bounds, and :func:`bootstrap_exponent`'s
    interval on p (p_lo, p_hi)."""
    cells = _cells(rows)
    out = []
    for family, agent in dict.fromkeys((f, a) for f, _, a in cells):
        for measure in measures_of(family):
            sizes, medians, samples, censored = [], [], [], 0
            for (f, size, a), rs in cells.items():
                if (f, a) != (family, agent):
                    continue
                values, unsolved = seed_values(rs, measure)
                if all(unsolved):  # no seed solved (or no data)
                    continue
                median, lower_bound = censored_median(values, unsolved)
                sizes.append(size)
                medians.append(median)
                samples.append(values)
                censored += lower_bound
            fit = fit_growth(sizes, medians)
            lo, hi = bootstrap_exponent(sizes, samples)
            out.append(
                {
                    "family": family,
                    "agent": agent,
                    "measure": measure,
                    "n_sizes": fit["n_sizes"],
                    "censored_medians": censored,
                    "p": fit["p"],
                    "p_lo": lo,
                    "p_hi": hi,
                    "r2_poly": fit["r2_poly"],
                    "r": fit["r"],
                    "r2_exp": fit["r2_exp"],
                    "better": fit["better"],
                }
            )
    return out


# ------------------------------------------------------------------------------------------------
# Outputs: tables, figures and report, from the saved files only.
# ------------------------------------------------------------------------------------------------


def write_outputs(out: Path, study: dict[str, Any], runs: Runs) -> None:
    """runs.csv (per run), table.csv (per family x size x agent), growth.csv (per family x
    agent x solve measure), table.md, one figure per family and report.md."""
    rows = per_run(runs)
    table = summarise(rows)
    fits = growth(rows)
    for name, data in (("runs", rows), ("table", table), ("growth", fits)):
        with (out / f"{name}.csv").open("w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=list(data[0]))
            writer.writeheader()
            writer.writerows(data)
    (out / "table.md").write_text(_markdown_table(table) + "\n" + _markdown_growth(fits))
    for family in dict.fromkeys(r["family"] for r in table):
        _plot(family, table, fits, out / "figures" / f"{family}.png")
    _write_report(out, study, table, fits)


def _median(value: float, censored: bool) -> str:
    return (">" if censored else "") + fmt(float(value))


def _bsuite_cells(r: dict[str, Any]) -> list[str]:
    """The table's bsuite columns of one row ("n/a" off deep sea or without bad flags)."""
    if r["seeds_bsuite"] is None:
        return ["n/a", "n/a"]
    return [
        f"{r['seeds_bsuite_solved']}/{r['seeds_bsuite']}",
        _median(r["median_bsuite_episode"], r["bsuite_censored"]),
    ]


def _markdown_table(table: list[dict[str, Any]]) -> str:
    head = [
        "family",
        "size",
        "budget",
        "agent",
        "solved",
        "held",
        "median episodes to solve",
        "median steps to solve",
        "median episodes to first reward",
        "bsuite solved",
        "median bsuite episode",
    ]
    cells = [
        [
            r["family"],
            str(r["size"]),
            f"{r['budget']:,}",
            r["agent"],
            f"{r['seeds_solved']}/{r['seeds']}",
            f"{r['seeds_held']}/{r['seeds']}",
            _median(r["median_episodes_to_solve"], r["episodes_censored"]),
            _median(r["median_steps_to_solve"], r["steps_censored"]),
            _median(r["median_episodes_to_first_reward"], r["first_reward_censored"]),
            *_bsuite_cells(r),
        ]
        for r in table
    ]
    return markdown_table(head, cells)


def _fitted(fit: dict[str, Any]) -> bool:
    return bool(fit["better"] != "not enough sizes")


def _fit_text(fit: dict[str, Any], key: str) -> str:
    r2 = fit["r2_poly" if key == "p" else "r2_exp"]
    return f"{key} = {fmt(fit[key])} (R² {fmt(r2)})"


def _interval(fit: dict[str, Any]) -> str:
    return f"[{fmt(fit['p_lo'])}, {fmt(fit['p_hi'])}]"


def _markdown_growth(fits: list[dict[str, Any]]) -> str:
    head = [
        "family",
        "agent",
        "measure",
        "sizes fitted",
        "lower-bound medians",
        "polynomial exponent p",
        "p: 95% bootstrap interval",
        "exponential rate r",
        "fits better",
    ]
    cells = []
    for f in fits:
        p, ci, r = (
            (_fit_text(f, "p"), _interval(f), _fit_text(f, "r")) if _fitted(f) else ("", "", "")
        )
        cells.append(
            [
                f["family"],
                f["agent"],
                f["measure"],
                str(f["n_sizes"]),
                str(f["censored_medians"]),
                p,
                ci,
                r,
                f["better"],
            ]
        )
    return markdown_table(head, cells)


def _plot(family: str, table: list[dict[str, Any]], fits: list[dict[str, Any]], file: Path) -> None:
    """Seeds solved against size (bsuite's dashed), then per solve measure the median episodes
    to solve with the polynomial fit."""
    from matplotlib.ticker import NullLocator

    fam = FAMILIES[family]
    measures = measures_of(family)
    rows = [r for r in table if r["family"] == family]
    width = 5.5 * (1 + len(measures))
    with figure(file, 1, 1 + len(measures), figsize=(width, 4.2)) as (_, axes):
        ax0, panels = axes[0], axes[1:]
        for agent in dict.fromkeys(r["agent"] for r in rows):
            mine = [r for r in rows if r["agent"] == agent]
            color = COLORS.get(agent)
            x = np.array([r["size"] for r in mine], dtype=float)
            ax0.plot(
                x, [r["seeds_solved"] / r["seeds"] for r in mine], "o-", color=color, label=agent
            )
            if fam.bsuite and all(r["seeds_bsuite"] for r in mine):
                frac = [r["seeds_bsuite_solved"] / r["seeds_bsuite"] for r in mine]
                ax0.plot(x, frac, "s--", color=color, mfc="none", label=f"{agent} (bsuite)")
            for ax, measure in zip(panels, measures, strict=True):
                m = SOLVE_MEASURES[measure]
                fit = next(
                    f
                    for f in fits
                    if (f["family"], f["agent"], f["measure"]) == (family, agent, measure)
                )
                _plot_medians(ax, [r for r in mine if r[m.solved]], m, fit, agent, color)
        ax0.set_ylim(-0.05, 1.05)
        finish_axes(ax0, fam.size, "fraction of seeds solved", f"{family}: solved")
        sizes = sorted({r["size"] for r in rows})
        for ax in axes:  # ticks at the sizes run
            if ax is not ax0:
                ax.set_xscale("log")
                ax.set_yscale("log")
            ax.set_xticks(sizes, [str(s) for s in sizes])
            ax.xaxis.set_minor_locator(NullLocator())
        for ax, measure in zip(panels, measures, strict=True):
            ax.set_xlabel(fam.size)
            ax.set_ylabel(f"median {SOLVE_MEASURES[measure].name} episodes to solve")
            ax.set_title(
                f"{family}: {SOLVE_MEASURES[measure].name} episodes to solve (open: lower "
                "bound),\npolynomial fit dashed",
                fontsize=10,
            )
            if ax.get_legend_handles_labels()[0]:  # nothing to list where no seed solved
                ax.legend(fontsize=8)
            ax.grid(alpha=0.3)


def _plot_medians(
    ax: Any,
    solved: list[dict[str, Any]],
    m: SolveMeasure,
    fit: dict[str, Any],
    agent: str,
    color: Any,
) -> None:
    """One agent's medians of measure ``m`` at the sizes some seed solved (a censored median, a
    lower bound, is an open marker) and its polynomial fit."""
    for r in solved:
        face = "none" if r[m.censored] else color
        ax.plot(r["size"], r[m.median], "o", color=color, mfc=face)
    if _fitted(fit):
        xs = np.array([r["size"] for r in solved], dtype=float)
        ys = np.log([max(r[m.median], 1.0) for r in solved])
        c = np.mean(ys - fit["p"] * np.log(xs))
        grid = np.geomspace(xs.min(), xs.max(), 50)
        label = f"{agent}: p = {fit['p']:.2g} [{fit['p_lo']:.2g}, {fit['p_hi']:.2g}]"
        ax.plot(grid, np.exp(c) * grid ** fit["p"], "--", color=color, lw=1, label=label)
    elif solved:
        ax.plot([], [], "o", color=color, label=agent)


_TEXT_HEAD = (
    "Each agent runs with one config on every task and size: the library's default for the task "
    "(`preset=auto`) and its own overrides, nothing tuned per task. A run **solved** a task when "
    "some greedy evaluation's mean return (stochastic deep sea: its success rate, the fraction of "
    "its episodes that took the treasure) reached the family's threshold; *episodes to solve* "
    "counts the training episodes finished at the first such evaluation (*steps to solve* "
    "likewise), so its resolution is the evaluation interval. *Held*: the final evaluation is at "
    "the threshold. *First reward*: the first training episode whose return shows the reward was "
    "reached (stochastic deep sea: the first that took the treasure). An unsolved seed counts as "
    "its run's total (episodes, steps): a censored value, so a median marked `>` is a lower bound."
)
_BSUITE_NOTE = (
    "Deep sea is also scored as bsuite scores it (`bsuite/experiments/deep_sea/analysis.py`), "
    "from every training episode's bad flag (the agent left the diagonal by a wrong move; "
    "`bad_episodes.csv` of each run): a run is solved at the first episode where the bad episodes "
    "so far number less than 0.9 of the episodes so far (stochastic deep sea: 0.8, and only from "
    "episode 100 on), and *bsuite solved* counts the seeds solved so before episode 2^N + 100, "
    "the seeds that beat dithering. *Median bsuite episode*: that episode, an unsolved seed "
    "counting as its run's episodes (a lower bound). {budgets} bsuite checks only the episodes it "
    "logs (1-10, 12, 14, 17, 20, 25, ...); here every episode counts, so an episode can read a "
    "little earlier. At small N luck passes the criterion: one episode on the diagonal among the "
    "first 9 brings the fraction below 0.9, which a random policy does with probability about "
    "9/2^N (0.13 at N = 6, 0.009 at N = 10; bsuite's sweep starts at N = 10)."
)
_BSUITE_BUDGETS = (
    "The budgets are 2^N + 100 episodes, at "
    f"least {DEEP_SEA_MIN_EPISODES:,} and at most {DEEP_SEA_MAX_EPISODES:,}: at N = 6 and 8 the "
    "runs go on past episode 2^N + 100, which changes no bsuite verdict (bsuite itself runs "
    "10,000 episodes at every size and counts a solve only before 2^N + 100) and gives the "
    "greedy criterion time; from N = 12 on a seed must beat dithering within "
    f"{DEEP_SEA_MAX_EPISODES:,} episodes."
)


def _bsuite_note(episodes: int) -> str:
    """The report's note on bsuite's criterion, with the deep sea budgets of the study
    (``--episodes``, or each size's own)."""
    if not episodes:
        return _BSUITE_NOTE.format(budgets=_BSUITE_BUDGETS)
    budgets = (
        f"Every deep sea run here is {episodes:,} episodes (`--episodes`; bsuite itself runs "
        "10,000 at every size and counts a solve only before 2^N + 100)."
    )
    return _BSUITE_NOTE.format(budgets=budgets)


_GROWTH_NOTE = (
    "Growth of the median episodes to solve against the size, over the sizes where at least one "
    "seed solved (at least 3 such sizes, else *not enough sizes*): least-squares fits of "
    "log(episodes) on log(size) (polynomial, exponent p) and on size (exponential, rate r), with "
    "their R²; the one with the higher R² fits better. *Measure*: greedy, the training episodes "
    "to the first greedy evaluation at the threshold; bsuite (deep sea), bsuite's episode to "
    "solve. The 95% interval on p is a percentile bootstrap: each size's seeds drawn again with "
    f"replacement, {BOOTSTRAP_RESAMPLES:,} times (seed {BOOTSTRAP_SEED}), the censored medians "
    "recomputed and p refitted; with few seeds it is coarse. The medians include censored seeds, "
    "so an agent that fails at a size enters the fit with a lower bound there (counted in "
    "*lower-bound medians*), and its true growth is at least as steep. With three sizes both fits "
    "can have a high R²: read the two together."
)


def command(study: dict[str, Any], out: Path) -> str:
    """The command line that runs the study saved in ``study`` (a study.json) into ``out``."""
    settings = runner.settings_of(STUDY, study)
    line = ["farsighter", "explore"]
    if dataclasses.replace(settings, workers=0) == QUICK:
        line.append("--quick")
    else:
        for name in ("families", "sizes", "seeds", "steps", "episodes", "agents"):
            value = getattr(settings, name)
            if value != getattr(StudyConfig(), name):
                values = value if isinstance(value, tuple) else (value,)
                line += [f"--{name}", *map(str, values)]
    return shlex.join([*line, "--out", str(out)])


def _claims(table: list[dict[str, Any]], fits: list[dict[str, Any]]) -> list[str]:
    """Per family, on its :func:`primary_measure`: does Farsighter's growth look polynomial where
    DDQN's looks exponential (or DDQN fails where Farsighter solves)? Then, plainly, whether
    each one's growth is polynomial. Last, the agent that solved the most (family, size)."""
    lines = []
    fit = {(f["family"], f["agent"], f["measure"]): f for f in fits}
    for family in dict.fromkeys(r["family"] for r in table):
        rows = [r for r in table if r["family"] == family]
        measure = SOLVE_MEASURES[primary_measure(family)]
        head = f"- **{family}**: "
        if not {"Farsighter", "DDQN"} <= {r["agent"] for r in rows}:
            lines.append(head + "not tested: needs both the Farsighter and the DDQN agent.")
            continue
        f, d = fit[family, "Farsighter", measure.name], fit[family, "DDQN", measure.name]
        by = {(r["agent"], r["size"]): r for r in rows}
        sizes = sorted({r["size"] for r in rows})
        if len(sizes) < MIN_SIZES:
            lines.append(head + f"not tested: {len(sizes)} size(s) in this study (needs 3).")
            continue
        solved = measure.solved
        fails = [s for s in sizes if by["Farsighter", s][solved] and not by["DDQN", s][solved]]
        fails_text = (
            "DDQN solves no seed at size(s) "
            + ", ".join(
                f"{s} (Farsighter {by['Farsighter', s][solved]}/"
                f"{by['Farsighter', s]['seeds' if measure.name == 'greedy' else 'seeds_bsuite']})"
                for s in fails
            )
            if fails
            else "DDQN solves a seed at every size where Farsighter does"
        )
        f_poly = f["better"] == "polynomial"
        d_exp = d["better"] == "exponential"
        evidence = (
            f"Fitted: {measure.text}. Farsighter: {_fit_desc(f)}; DDQN: {_fit_desc(d)}; "
            f"{fails_text}"
        )
        if f_poly and (d_exp or fails):
            ddqn = "DDQN's grow exponentially" if d_exp else "DDQN fails at sizes Farsighter solves"
            lines.append(
                head + f"shown: Farsighter's episodes to solve grow polynomially while {ddqn}. "
                f"{evidence}."
            )
        else:
            if not _fitted(f):
                why = f"Farsighter solves a seed at fewer than {MIN_SIZES} sizes"
            elif not f_poly:
                why = "Farsighter's growth does not fit a polynomial better than an exponential"
            else:
                why = "DDQN's growth does not fit an exponential better and DDQN solves a seed "
                why += "wherever Farsighter does"
            lines.append(head + f"not shown: {why}. {evidence}.")
        lines += [
            f"  - {_verdict(agent, fit[family, agent, measure.name])}"
            for agent in ("Farsighter", "DDQN")
        ]
    lines.append(_most_solved(table))
    return lines


def _verdict(agent: str, fit: dict[str, Any]) -> str:
    """Plainly: is ``agent``'s growth polynomial by this fit?"""
    bounds = fit["censored_medians"]
    caveat = (
        f"; {bounds} of its {fit['n_sizes']} medians are lower bounds, so it grows at least this "
        "fast"
        if bounds
        else ""
    )
    if not _fitted(fit):
        return (
            f"{agent}: growth not measured: a seed solved at {fit['n_sizes']} size(s), "
            f"{MIN_SIZES} needed."
        )
    p = f"p = {fmt(fit['p'])}, 95% bootstrap interval {_interval(fit)}"
    if fit["better"] == "polynomial":
        return f"{agent}: growth is polynomial (a polynomial fits better; {p}){caveat}."
    if fit["better"] == "exponential":
        return (
            f"{agent}: growth is not polynomial (an exponential fits better: "
            f"{_fit_text(fit, 'r')} against {_fit_text(fit, 'p')}){caveat}."
        )
    return f"{agent}: neither a polynomial nor an exponential fits better ({p}){caveat}."


def _fit_desc(fit: dict[str, Any]) -> str:
    if not _fitted(fit):
        return f"not enough sizes ({fit['n_sizes']} solved by a seed)"
    return (
        f"{_fit_text(fit, 'p')}, p's 95% interval {_interval(fit)}, {_fit_text(fit, 'r')}, "
        f"{fit['better']} fits better"
    )


def _most_solved(table: list[dict[str, Any]]) -> str:
    """The agent(s) with the most (family, size) pairs solved by more than half of the seeds."""
    count: dict[str, int] = {}
    for r in table:
        count[r["agent"]] = count.get(r["agent"], 0) + int(2 * r["seeds_solved"] > r["seeds"])
    top = max(count.values())
    leaders = [a for a, n in count.items() if n == top]
    tally = ", ".join(f"{a} {n}" for a, n in sorted(count.items(), key=lambda kv: -kv[1]))
    pairs = len({(r["family"], r["size"]) for r in table})
    if top == 0:
        return f"- No agent solved any of the {pairs} (family, size) pairs in most of its seeds."
    return (
        f"- Most (family, size) pairs solved by more than half of the seeds: "
        f"{' and '.join(f'**{a}**' for a in leaders)} with {top} of {pairs} ({tally})."
    )


def _write_report(
    out: Path, study: dict[str, Any], table: list[dict[str, Any]], fits: list[dict[str, Any]]
) -> None:
    families = list(dict.fromkeys(r["family"] for r in table))
    lines = [
        "# Exploration suite",
        "",
        f"Made by `{command(study, out)}`. Agents: {', '.join(study['agents'])}; seeds "
        f"{list(study['seeds'])}.",
        "",
        _TEXT_HEAD,
        "",
        "## Tasks and budgets",
        "",
    ]
    tasks = [
        [
            r["family"],
            str(r["size"]),
            f"`{r['env']}`",
            f"{r['budget']:,}",
            f"{FAMILIES[r['family']].eval_episodes} episode(s) every "
            f"{FAMILIES[r['family']].eval_every_at(r['size']):,} steps",
            FAMILIES[r["family"]].rule_at(r["size"]),
        ]
        for r in dict((r["env"], r) for r in table).values()
    ]
    head = ["family", "size", "environment", "budget (steps)", "evaluation", "solved at"]
    lines += markdown_table(head, tasks).splitlines()
    lines += [""]
    lines += [f"- {name}: {FAMILIES[name].solved}." for name in families]
    if any(FAMILIES[name].bsuite for name in families):
        lines += ["", _bsuite_note(int(study.get("episodes", 0)))]
    lines += [
        "",
        "## Table",
        "",
        _markdown_table(table),
        "## Growth with size",
        "",
        _GROWTH_NOTE,
        "",
        _markdown_growth(fits),
        "## Claims",
        "",
        "Farsighter (the default agent) against DDQN: shown where Farsighter's growth fits a "
        "polynomial better while DDQN's fits an exponential better, or DDQN solves no seed at a "
        "size where Farsighter solves one. On deep sea the claim fits bsuite's episode to solve "
        "and counts the seeds that beat dithering (the growth table gives the greedy fit too); "
        "elsewhere it fits the greedy episodes to solve. Under each family, plainly, whether "
        "Farsighter's and DDQN's growth is polynomial.",
        "",
        *_claims(table, fits),
        "",
        "## Figures",
        "",
    ]
    for name in families:
        lines += [f"![{name}](figures/{name}.png)", ""]
    lines += [f"Redraw from the saved runs with `farsighter explore --plot-only {out}`.", ""]
    (out / "report.md").write_text("\n".join(lines))


STUDY = runner.Study(
    kind="explore",
    description="The exploration suite: task families with a size knob (chain, MiniGrid "
    "DoorKey, KeyCorridor, MultiRoom, bsuite's deep sea and its stochastic version, "
    "MountainCar, Acrobot), every agent with one config; how the episodes to solve grow with "
    "the size (deep sea also by bsuite's bad-episode criterion). --quick (the chain at L = 5, "
    "10, 20) takes a few minutes on 2 cores.",
    agents=AGENTS,
    full=StudyConfig(),
    quick=QUICK,
    run_config=run_config,
    write_outputs=write_outputs,
    # the last three: runs whose environment reports is_success (success.csv, eval_success.csv)
    # or bad_episode (deep sea)
    run_files=("metrics.csv", "eval.csv", SUCCESS_FILE, EVAL_SUCCESS_FILE, BAD_EPISODES_FILE),
    args=Args,
    callback=_bad_episode_log,
    check=_check,
    tasks=tasks,
)


def main(argv: Sequence[str]) -> int:
    """``farsighter explore ARGV``."""
    return runner.main(STUDY, argv)
