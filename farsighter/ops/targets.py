"""TD targets as pure functions: k-step returns (Algorithm 2) and the double-Q target (Eq. 2, 8)."""

from __future__ import annotations

import functools

import numpy as np
import torch


def nstep_returns(
    rewards_BK: np.ndarray,
    terminated_BK: np.ndarray,
    truncated_BK: np.ndarray,
    gamma: float,
    cut_BK: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """k-step discounted returns over windows of one-step transitions.

    Row b holds the k transitions that follow a start state; column j is the (j+1)-th step. The
    sum r^k = sum_j gamma^j r_j (Algorithm 2 line 5) stops at the first step that ends the
    episode. Returns ``(returns_B, steps_B, bootstrap_B)`` where ``steps`` is the number of
    transitions actually summed (n <= k) and ``bootstrap`` the factor of the bootstrap value
    Q(s_{t+n}): gamma^n, or 0 when the episode terminated inside the window (a terminal state gets
    no bootstrap; a time-limit truncation bootstraps from the last state with gamma^n).

    ``cut_BK`` (``Config.k_target = cut``): where the step's action was exploratory (not the
    greedy action of the policy being learned). The window then stops before the first such
    step j >= 1 and bootstraps from s_{t+j} with gamma^j: the return follows the greedy policy
    as far as the behaviour did, never a choice it would not make (Watkins's Q(lambda) cut,
    Sutton and Barto 2018 section 12.10). The first step's own action is the one Q(s_t, a_t)
    values, so it never cuts.
    """
    b, k = rewards_BK.shape
    if k == 1:  # one step: the reward itself, bootstrapped unless it terminated
        terminal_B = np.asarray(terminated_BK)[:, 0]
        return (
            rewards_BK[:, 0].astype(np.float32),
            np.ones(b, dtype=np.int64),
            np.where(terminal_B, 0.0, gamma).astype(np.float32),
        )
    ends_BK = np.logical_or(terminated_BK, truncated_BK)
    if cut_BK is not None:  # an exploratory step j ends the window after step j - 1
        ends_BK[:, :-1] |= np.asarray(cut_BK, dtype=bool)[:, 1:]
    steps_B = window_steps(ends_BK)
    # alive[j]: no episode end among steps 0..j-1, i.e. step j is still part of the window.
    alive_BK = np.arange(k) < steps_B[:, None]
    returns_B = (rewards_BK.astype(np.float64) * _discounts(gamma, k) * alive_BK).sum(axis=1)
    terminal_B = terminated_BK[np.arange(b), steps_B - 1]  # the window's last step
    bootstrap_B = np.where(terminal_B, 0.0, gamma ** steps_B.astype(np.float64))
    return returns_B.astype(np.float32), steps_B, bootstrap_B.astype(np.float32)


def window_steps(done_BK: np.ndarray) -> np.ndarray:
    """The steps of each window of k transitions that belong to it, (B,) int64: up to and
    including the first that ends the episode, k if none does (the k-th step's own end does not
    shorten the window)."""
    b, k = done_BK.shape
    if k == 1:
        return np.ones(b, dtype=np.int64)
    ends_BK = done_BK[:, :-1]
    first_B = ends_BK.argmax(axis=1)  # the first end among steps 0..k-2 (0 where none)
    return np.where(ends_BK[np.arange(b), first_B], first_B + 1, k).astype(np.int64)


@functools.lru_cache(maxsize=64)
def _discounts(gamma: float, k: int) -> np.ndarray:
    """gamma^j for j < k (cached: read-only)."""
    out = gamma ** np.arange(k, dtype=np.float64)
    out.flags.writeable = False
    return out


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


def centered_optimism(
    y_B: torch.Tensor, y_mean_B: torch.Tensor, bootstrap_B: torch.Tensor
) -> torch.Tensor:
    """Sampled targets ``y_B`` with the minibatch's mean optimism taken out:
    y - bootstrap * sum(y - y_mean) / sum(bootstrap), so that the optimism of the rows,
    sum(result - y_mean), is zero, each bootstrapped row keeps its optimism relative to the
    minibatch's, and a row that bootstraps nothing (bootstrap 0) is unchanged.
    ``y_mean_B``: the same targets under the posterior mean (no draw). No host sync (it runs in
    the update, captured as a CUDA graph on GPU): where no row bootstraps, every row's optimism
    and factor are 0, so the floored denominator changes nothing."""
    total = bootstrap_B.sum().clamp_min(torch.finfo(bootstrap_B.dtype).tiny)
    return y_B - bootstrap_B * ((y_B - y_mean_B).sum() / total)


def advantage_learning(
    y_B: torch.Tensor, q_target_BA: torch.Tensor, actions_B: torch.Tensor, alpha: float
) -> torch.Tensor:
    """The advantage-learning operator on targets (Baird 1999; Bellemare et al. 2016): the target
    ``y_B`` of (s, a) lowered by ``alpha`` times the target network's gap at s between the
    greedy action and the one taken, y - alpha (max_b Q_target(s, b) - Q_target(s, a)).
    ``q_target_BA``: Q_target(s, .) of each row's start state s; the greedy action's target is
    unchanged, every other action's lowered, so the fixed point's gaps grow by 1 / (1 - alpha)."""
    gap_B = q_target_BA.max(dim=1).values - q_target_BA.gather(1, actions_B[:, None])[:, 0]
    return y_B - alpha * gap_B
