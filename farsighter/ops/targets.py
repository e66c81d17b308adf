"""TD targets as pure functions: k-step returns (Algorithm 2) and the double-Q target (Eq. 2, 8)."""

from __future__ import annotations

import numpy as np
import torch


def nstep_returns(
    rewards_BK: np.ndarray,
    terminated_BK: np.ndarray,
    truncated_BK: np.ndarray,
    gamma: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """k-step discounted returns over windows of one-step transitions.

    Row b holds the k transitions that follow a start state; column j is the (j+1)-th step. The
    sum r^k = sum_j gamma^j r_j (Algorithm 2 line 5) stops at the first step that ends the
    episode. Returns ``(returns_B, steps_B, bootstrap_B)`` where ``steps`` is the number of
    transitions actually summed (n <= k) and ``bootstrap`` the factor of the bootstrap value
    Q(s_{t+n}): gamma^n, or 0 when the episode terminated inside the window (a terminal state gets
    no bootstrap; a time-limit truncation bootstraps from the last state with gamma^n).
    """
    done_BK = np.logical_or(terminated_BK, truncated_BK)
    b, k = rewards_BK.shape
    # alive[j]: no episode end among steps 0..j-1, i.e. step j is still part of the window.
    ended_before_BK = np.zeros((b, k), dtype=bool)
    if k > 1:
        ended_before_BK[:, 1:] = np.cumsum(done_BK[:, :-1], axis=1) > 0
    alive_BK = ~ended_before_BK
    discounts_K = gamma ** np.arange(k, dtype=np.float64)
    returns_B = (rewards_BK.astype(np.float64) * discounts_K * alive_BK).sum(axis=1)
    steps_B = alive_BK.sum(axis=1)
    last_B = steps_B - 1
    rows_B = np.arange(b)
    terminal_B = terminated_BK[rows_B, last_B] & alive_BK[rows_B, last_B]
    bootstrap_B = np.where(terminal_B, 0.0, gamma ** steps_B.astype(np.float64))
    return returns_B.astype(np.float32), steps_B.astype(np.int64), bootstrap_B.astype(np.float32)


def double_q_target(
    returns_B: torch.Tensor,
    bootstrap_B: torch.Tensor,
    q_next_online_BA: torch.Tensor,
    q_next_target_BA: torch.Tensor,
) -> torch.Tensor:
    """Double-Q target of Eq. 2 (and Eq. 8 with k-step returns, section 4.4).

    y = r^k + gamma^k Q_target(s', argmax_a' Q_online(s', a')): the online network selects the
    action and the target network evaluates it. ``bootstrap`` already holds gamma^n or 0.
    """
    a_star_B = q_next_online_BA.argmax(dim=1, keepdim=True)
    q_eval_B = q_next_target_BA.gather(1, a_star_B).squeeze(1)
    return returns_B + bootstrap_B * q_eval_B
