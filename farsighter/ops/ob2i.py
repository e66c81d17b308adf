"""OB2I's formulas (Bai et al. 2021, section 3), as the authors' code computes them; the agent is
:mod:`farsighter.agents.ob2i`.

Symbols as in the paper (equation numbers not repeated).

* UCB-bonus, the std of the bootstrapped Q-estimates (OB2I's B^k):
      B(s, a) = sqrt( (1/K) sum_k (Q_k(s, a) - mean_j Q_j(s, a))^2 )
* For a sampled episode s_0, a_0, r_0, ..., s_T (the episodic backward update of EBU, Lee et al.
  2019, Algorithm 2), with Q~[t] = Q_target(s_{t+1}, .) for every head (T x K x A values):
      immediate bonus   rb_t     = alpha_1 * B_online(s_t, a_t)            (/ running std if set)
      next bonus        nb_{t,k} = alpha_2 * B_target(s_{t+1}, a'_{t,k}) / sigma_nb
                                   * 1[a'_{t,k} != a_{t+1}],  a'_{t,k} = argmax_a Q~_k[t, a]
  where sigma_nb is a running std of the unnormalised next-state bonuses (OB2I's B~ term of the
  target); the indicator (authors' code) drops the next-state bonus where a head's greedy action
  is the action taken next, whose Q~ already holds the propagated target (which carries bonus).
* Backward, t = T-1, ..., 0 (OB2I's optimistic target y^k_t and its backward induction):
      y_{t,k} = r_t + rb_t                                          if t = T-1 and s_T terminal
      y_{t,k} = r_t + rb_t + gamma * (max_a Q~_k[t, a] + nb_{t,k})   otherwise
      Q~_k[t-1, a_t] <- beta * y_{t,k} + (1 - beta) * Q~_k[t-1, a_t]   (t >= 1: Q~[t-1] is at s_t)
  A time-limit truncation bootstraps from the real last state s_T, as everywhere in this library.
"""

from __future__ import annotations

import numpy as np
import torch


def ucb_bonus(q_BKA: torch.Tensor) -> torch.Tensor:
    """OB2I's UCB-bonus B(s, a): the (population) std of Q over the heads, (B, K, A) -> (B, A)."""
    return q_BKA.std(dim=1, unbiased=False)


def next_state_bonus(
    q_next_TKA: np.ndarray, taken_next_T: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Unnormalised next-state bonus B_target(s_{t+1}, a'_{t,k}) at each head's greedy action
    a'_{t,k} = argmax_a Q~_k(s_{t+1}, a), and the indicator 1[a'_{t,k} != a_{t+1}] (authors' code;
    ``taken_next_T[t]`` is a_{t+1}, or -1 after the last step). Both (T, K)."""
    a_star_TK = q_next_TKA.argmax(axis=2)
    bonus_TK = np.take_along_axis(q_next_TKA.std(axis=1), a_star_TK, axis=1)
    return bonus_TK, a_star_TK != taken_next_T[:, None]


def backward_targets(
    rewards_T: np.ndarray,
    actions_T: np.ndarray,
    q_next_TKA: np.ndarray,
    bonus_next_TK: np.ndarray,
    terminated: bool,
    gamma: float,
    beta: float,
) -> np.ndarray:
    """Targets y (T, K) of one episode by backward induction (EBU with OB2I's optimistic target).

    ``rewards_T`` already include the immediate bonus; ``q_next_TKA[t]`` is Q_target(s_{t+1}, .)
    per head and is not modified; ``bonus_next_TK`` is the weighted next-state bonus.
    """
    q_TKA = np.array(q_next_TKA, dtype=np.float64)  # a copy: the recursion overwrites it
    length = len(rewards_T)
    y_TK = np.empty(q_TKA.shape[:2], dtype=np.float64)
    for t in range(length - 1, -1, -1):
        if t == length - 1 and terminated:
            y_TK[t] = rewards_T[t]  # a terminal end gets no bootstrap
        else:
            y_TK[t] = rewards_T[t] + gamma * (q_TKA[t].max(axis=1) + bonus_next_TK[t])
        if t > 0:  # diffuse y_t into Q~(s_t, a_t), which bootstraps y_{t-1}
            a = int(actions_T[t])
            q_TKA[t - 1, :, a] = beta * y_TK[t] + (1.0 - beta) * q_TKA[t - 1, :, a]
    return y_TK.astype(np.float32)
