"""The exploration study's task families: tasks of one kind at growing sizes, their step budgets,
how a run on them is judged solved, and bsuite's own deep sea criterion.

:data:`FAMILIES`: the combination-lock chain and its drifting version, MiniGrid Empty, DoorKey,
KeyCorridor and MultiRoom, MountainCar, Acrobot, FrozenLake, and bsuite's deep sea, deterministic
and stochastic; :data:`TASKS` maps each environment id back to its family and size.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from farsighter.envs.chain import SOLVED_RETURN, chain_id, drift_chain_id
from farsighter.envs.deep_sea import deep_sea_id
from farsighter.studies.claims import fmt
from farsighter.studies.runner import Task

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
