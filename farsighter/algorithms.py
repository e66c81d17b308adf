"""The algorithm table: every algorithm the library trains, in one place.

The CLI's choices, the error messages, config resolution and validation, the action-space check
and agent construction all read this table; nothing else lists algorithms. It imports nothing
heavy (no torch, no gymnasium), so the CLI and the config can use it cheaply.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

from farsighter.errors import ConfigError


@dataclass(frozen=True)
class Algorithm:
    """One algorithm: its agent, the actions it handles and the values that define it."""

    name: str
    """The ``--algo`` name."""
    summary: str
    """One line: what it is and where the paper describes it."""
    agent: str
    """Module of ``farsighter.agents`` whose ``AGENT`` class trains it."""
    actions: Literal["discrete", "continuous"]
    """Action spaces it handles: Discrete, or Box."""
    defaults: Mapping[str, Any] = field(default_factory=dict)
    """Config values that define the algorithm (dotted keys for nested fields). They apply after
    a preset (a preset's generic schedule does not replace them) and before the user's flags."""
    bayesian: bool = False
    """Explores by Thompson draws from a posterior over weights (BLR head or Bayesian layer)."""
    adaptive_k: bool = False
    """Supports adaptive k (Algorithm 1 line 7)."""
    episodic: bool = False
    """Learns from whole episodes (episodic backward update): k = 1, no stride, no recent window."""
    fast_step: bool = False
    """The learner may capture its update as a CUDA graph or compile it
    (:mod:`farsighter.agents.learner`); OB2I's minibatches change size with each episode's tail
    (a graph or a compilation per size) and NAF's update was never measured so: both run
    eagerly."""
    seed_batch: str = ""
    """Module of ``farsighter.agents`` whose ``SEED_AGENTS`` trains several seeds of it as one
    computation (:mod:`farsighter.seeds`): the agent's own module where the agent is written over
    the seed axis; '' where its seeds train one at a time."""


TABLE: tuple[Algorithm, ...] = (
    Algorithm(
        "ddqn",
        "double DQN with epsilon-greedy exploration (section 3.2)",
        agent="ddqn",
        seed_batch="ddqn",
        actions="discrete",
        fast_step=True,
    ),
    Algorithm(
        "kddqn",
        "double DQN with k-step returns (section 5.2 baselines)",
        agent="ddqn",
        seed_batch="ddqn",
        actions="discrete",
        fast_step=True,
        defaults={"k": 3},
    ),
    Algorithm(
        "bdqn",
        "Thompson sampling on a Bayesian linear regression Q-head, 1-step (section 4.2)",
        bayesian=True,
        agent="farsighter",
        seed_batch="farsighter",
        actions="discrete",
        fast_step=True,
        # A new weight draw every T^sample = 1,000 steps as in Azizzadenesheli et al. (2018);
        # the bdqn preset (the authors' code) and --blr.redraw change it.
        defaults={"k": 1, "blr.redraw": "every", "blr.redraw_every": 1_000},
    ),
    Algorithm(
        "farsighter",
        "Thompson draw every step over k-step returns from recent transitions (Algorithms 1-2)",
        bayesian=True,
        agent="farsighter",
        seed_batch="farsighter",
        actions="discrete",
        fast_step=True,
        # Fresh draw every step (Algorithm 2), k-step returns, minibatches from the latest N
        # transitions (Algorithm 1 line 4). k = 10 is the smallest k of Figure 4.
        defaults={"k": 10, "blr.redraw": "step", "sample_recent": True},
        adaptive_k=True,
    ),
    Algorithm(
        "ob2i",
        "bootstrapped heads with UCB bonus and episodic backward update (Bai et al. 2021)",
        agent="ob2i",
        actions="discrete",
        # Epsilon annealed 1.0 -> 0.1 around the head drawn per episode (authors' code:
        # --exploration-final-eps 0.1, SPEC 2.3); the presets' 0.01 / 0.02 are for DQN.
        defaults={"eps_end": 0.1},
        episodic=True,
    ),
    Algorithm(
        "rnd",
        "double DQN with a random-network-distillation bonus (appendix 9.1.1)",
        agent="rnd",
        seed_batch="rnd",
        actions="discrete",
        fast_step=True,
    ),
    Algorithm(
        "krnd",
        "RND with k-step returns, TD(K)+RND (appendix 9.1.1)",
        agent="rnd",
        seed_batch="rnd",
        actions="discrete",
        fast_step=True,
        defaults={"k": 3},
    ),
    # The continuous agents' TD loss is the squared error of Gu et al. (2016) / Algorithm 3 line 9.
    Algorithm(
        "naf",
        "normalized advantage functions with action noise (section 3.3)",
        agent="naf",
        actions="continuous",
        defaults={"k": 1, "loss": "mse"},
    ),
    Algorithm(
        "knaf",
        "NAF with k-step returns (section 5.2 baselines)",
        agent="naf",
        actions="continuous",
        # k = 5 as D4PG's n-step returns (Barth-Maron et al. 2018); the paper gives no k here.
        defaults={"k": 5, "loss": "mse"},
    ),
    Algorithm(
        "bnaf",
        "NAF with a Bayesian mu-layer sampled every step, 1-step (section 4.3, Algorithm 3)",
        bayesian=True,
        agent="naf",
        actions="continuous",
        # The Bayesian agents explore only through the mu-layer's weight draws, which tanh
        # saturation silences, so they keep its pre-tanh output small (NAFConfig.mu_penalty).
        defaults={"k": 1, "loss": "mse", "naf.mu_penalty": 0.1},
    ),
    Algorithm(
        "farsighter-naf",
        "Bayesian NAF with k-step returns, weights drawn every step (sections 4.3-4.4)",
        bayesian=True,
        agent="naf",
        actions="continuous",
        defaults={"k": 5, "loss": "mse", "naf.mu_penalty": 0.1},
        adaptive_k=True,
    ),
)

ALGORITHMS: dict[str, Algorithm] = {a.name: a for a in TABLE}
NAMES: tuple[str, ...] = tuple(ALGORITHMS)
"""Every ``--algo`` name, in table order."""


def names_for(actions: Literal["discrete", "continuous"]) -> tuple[str, ...]:
    """The algorithms for one kind of action space, in table order."""
    return tuple(a.name for a in TABLE if a.actions == actions)


def seed_batched() -> tuple[str, ...]:
    """The algorithms whose seeds train as one computation (:attr:`Algorithm.seed_batch`)."""
    return tuple(a.name for a in TABLE if a.seed_batch)


def accepted(names: tuple[str, ...] = NAMES) -> str:
    return ", ".join(names)


def get(name: str) -> Algorithm:
    """The table row of ``name``; an unknown name raises ConfigError listing the accepted ones."""
    if name not in ALGORITHMS:
        raise ConfigError(f"unknown algorithm '{name}'; accepted: {accepted()}")
    return ALGORITHMS[name]
