"""Epsilon-greedy exploration (DQN; the DDQN, RND and OB2I baselines): a uniform action with
probability epsilon, annealed linearly from ``eps_start`` to ``eps_end`` over
``eps_decay_steps`` environment steps, else the greedy action the agent gives.

The object holds only epsilon; its random numbers come from the generator it is handed (the
agent's, which the agent saves), so the draws are those of a run from before it existed."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from farsighter.config import Config


def linear_schedule(start: float, end: float, duration: int, step: int) -> float:
    """Linear interpolation from ``start`` to ``end`` over ``duration`` steps, then constant."""
    if duration <= 0:
        return end
    frac = min(max(step / duration, 0.0), 1.0)
    return start + frac * (end - start)


def epsilon_draw(rng: np.random.Generator, num_actions: int) -> tuple[float, int]:
    """One environment's coin and random action, as scalars (:func:`epsilon_draws` for n = 1)."""
    return rng.random(), int(rng.integers(0, num_actions))


def epsilon_draws(
    rng: np.random.Generator, num_actions: int, n: int
) -> tuple[np.ndarray, np.ndarray]:
    """``rng.random(n)``, then ``rng.integers(0, num_actions, size=n)``: the coins and random
    actions of epsilon-greedy. For one environment they are drawn as scalars, the same numbers
    and the same generator state after (``tests/training/test_training.py``) at a fifth of the cost
    (numpy's array path costs about 15 microseconds a call)."""
    if n == 1:
        coin, action = epsilon_draw(rng, num_actions)
        return np.array([coin]), np.array([action], dtype=np.int64)
    return rng.random(n), np.asarray(rng.integers(0, num_actions, size=n))


def epsilon_greedy(
    rng: np.random.Generator,
    epsilon: float,
    num_actions: int,
    greedy: Callable[[], np.ndarray],
    n: int,
) -> np.ndarray:
    """Epsilon-greedy actions for ``n`` environments; ``greedy()`` (the forward pass) is only
    called when some environment acts greedily. One environment takes scalars (the same draws,
    the same actions, a fifth of the array path's cost)."""
    if n == 1:
        coin, action = epsilon_draw(rng, num_actions)
        if coin < epsilon:
            return np.array([action], dtype=np.int64)
        return np.array(greedy(), dtype=np.int64)
    coins_E, random_actions_E = epsilon_draws(rng, num_actions, n)
    random_E = coins_E < epsilon
    if random_E.all():
        return random_actions_E
    return np.where(random_E, random_actions_E, greedy())


class EpsilonGreedy:
    """Epsilon-greedy with DQN's linear annealing (module docstring)."""

    def __init__(self, cfg: Config, num_actions: int, rng: np.random.Generator) -> None:
        self.cfg = cfg
        self.num_actions = num_actions
        self.rng = rng
        self.epsilon = cfg.eps_start

    def __call__(self, global_step: int, greedy: Callable[[], np.ndarray], n: int) -> np.ndarray:
        """Actions of ``n`` environments at ``global_step``; ``greedy()`` gives the greedy ones."""
        cfg = self.cfg
        self.epsilon = linear_schedule(cfg.eps_start, cfg.eps_end, cfg.eps_decay_steps, global_step)
        return epsilon_greedy(self.rng, self.epsilon, self.num_actions, greedy, n)


class EpisodeHeads(EpsilonGreedy):
    """OB2I's exploration (bootstrapped DQN's): each environment acts on one head of the
    ensemble, drawn uniformly when its episode starts, epsilon-greedy on that head's Q."""

    def __init__(
        self, cfg: Config, num_actions: int, num_heads: int, rng: np.random.Generator
    ) -> None:
        super().__init__(cfg, num_actions, rng)
        self.num_heads = num_heads
        self.head_E = rng.integers(0, num_heads, size=cfg.num_envs)

    def heads(self, n: int) -> np.ndarray:
        """The heads of ``n`` environments: the episodes' own, or fresh ones for a batch of
        another size (evaluation environments)."""
        return (
            self.head_E if n == len(self.head_E) else self.rng.integers(0, self.num_heads, size=n)
        )

    def ended(self, ended_E: np.ndarray) -> None:
        """A new head for each environment whose episode ended."""
        if ended_E.any():
            self.head_E[ended_E] = self.rng.integers(0, self.num_heads, size=int(ended_E.sum()))
