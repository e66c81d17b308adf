"""Bayesian linear regression (BLR) head: per-action posterior (Eq. 9), Thompson sampling (Eq. 7).

Q(s, a) = phi(s)^T w_a with a Gaussian posterior over each w_a in R^d (paper section 4.2, SPEC 2.1):

    Cov_a  = (Phi_a Phi_a^T / noise_std^2 + I / prior_std^2)^-1            (Eq. 9)
    mean_a = Cov_a Phi_a y_a / noise_std^2                                   (Eq. 9)
    w_a    = mean_a + sqrt(Cov_a) z,  z ~ N(0, I)                            (Eq. 7)

``prior_std`` is the paper's sigma (Table 1: 0.1) and ``noise_std`` its sigma_eps (Table 1: 1); both
are standard deviations so the formula above reads literally like SPEC 2.1.

Only the sufficient statistics Phi_a Phi_a^T (``phiphiT_ADD``) and Phi_a y_a (``phiy_AD``) are
kept, so the head works in batch mode (``fit``: reset, accumulate, refresh, as in the paper) and in
an incremental mode (``accumulate`` + ``refresh``, optionally with exponential forgetting) whose
refresh costs O(|A| d^3) and never rescans the replay buffer (SPEC 2.1).

With ``scale="residual"`` the noise sigma_eps follows the data instead of a constant: at each
refresh it is the root mean squared residual of the regression under the posterior mean (kept
from a third statistic, sum y^2), never below the configured ``noise_std``, and the prior sigma
keeps the configured ratio prior_std / noise_std to it. The values of a task with returns of
order 100 then get posterior spreads of that order without anyone setting sigma by hand.

The pieces: :mod:`~farsighter.ops.blr_posterior` (the posterior from the statistics, pure
functions of tensors), :mod:`~farsighter.ops.blr_head` (:class:`BLRHead`, and the residual
variance its refresh reads), and here the Thompson draws made ahead and the head's read-outs for
acting and adaptive k; all are re-exported from this module.

Tensor names carry shape suffixes: N samples, B rows (states / environments), A actions, D features.
"""

from __future__ import annotations

import math
from typing import Any

import torch

from farsighter.ops.blr_head import SCALES, BLRHead, residual_variance
from farsighter.ops.blr_posterior import (  # noqa: F401  (re-exported)
    all_finite,
    blr_posterior,
    blr_posterior_factor,
    cholesky_jitter,
    factor_mean,
    precision_factor,
)

__all__ = [
    "DRAW_BLOCK",
    "SCALES",
    "BLRHead",
    "ThompsonDraws",
    "blr_posterior",
    "blr_posterior_factor",
    "cholesky_jitter",
    "greedy_predictive_variance",
    "residual_variance",
]

DRAW_BLOCK = 256
"""Weight draws :class:`ThompsonDraws` makes at a time (with A = 18 actions and d = 512 a block
holds 9 MiB of float32)."""


class ThompsonDraws:
    """Fresh Thompson draws of every action's weights (Eq. 7), made ahead of time in blocks.

    Drawing w = mean_a + sqrt(cov_scale) U_a z for one state reads every U_a (A d^2 floats: 4 MiB
    with 4 actions and d = 512, 18 MiB with 18) for one matrix-vector product per step, which
    memory bandwidth, not arithmetic, bounds. Here ``block`` draws are made with one batched GEMM
    (:meth:`BLRHead.sample_weights`) and handed out in order, each once, so a step costs a
    (E, A, D) slice and one small product. Each draw is an independent draw of the posterior
    that is current when it is taken: the block is discarded, unused, when the head's
    posterior changes (``BLRHead.version``: a refresh, ``set_mean``, a load). The same seed
    gives the same draws; only the order in which the generator's numbers are used differs
    from drawing step by step.
    """

    def __init__(self, head: BLRHead, block: int = DRAW_BLOCK) -> None:
        if block < 1:
            raise ValueError(f"block must be >= 1, got {block}")
        self.head = head
        self.block = int(block)
        self.w_NAD: torch.Tensor | None = None
        self.next = 0
        self.version = -1  # the head's version the block was drawn under

    def take(self, n: int, generator: torch.Generator | None = None) -> torch.Tensor:
        """The next ``n`` draws, shape (n, A, D), float32 (a view: read it, do not write it)."""
        if n < 1:
            raise ValueError(f"n must be >= 1, got {n}")
        w = self.w_NAD
        if w is None or self.version != self.head.version or self.next + n > w.shape[0]:
            # a whole number of takes of n per block, at least one
            w = self.w_NAD = self.head.sample_weights(max(1, self.block // n) * n, generator)
            self.next, self.version = 0, self.head.version
        out = w[self.next : self.next + n]
        self.next += n
        return out

    def state_dict(self) -> dict[str, Any]:
        # only the draws not taken yet
        rest = None if self.w_NAD is None else self.w_NAD[self.next :].clone()
        return {"w_NAD": rest, "version": self.version}

    def load_state_dict(self, state: dict[str, Any] | None) -> None:
        """Restore :meth:`state_dict`; ``None`` (nothing saved) starts with no draws made."""
        if state is None:
            self.w_NAD, self.next, self.version = None, 0, -1
            return
        rest = state["w_NAD"]
        self.w_NAD = None if rest is None else rest.to(self.head.device, copy=True)
        self.next, self.version = 0, int(state["version"])


@torch.no_grad()
def action_gap_scale(head: BLRHead, phi_BD: torch.Tensor) -> float:
    """``blr.act_width = action-gap``'s factor on the acting draws' width: the mean over the rows
    of the largest minus the smallest posterior-mean Q, over the prior sigma, and at least 1.

    A draw at a state the run has not been to spreads about the prior sigma (sigma_eps under
    ``scale = residual``), which is sized to the residual noise. Where the learned values set
    actions further apart than that (a penalised action: Taxi's -10 pickup) no draw reaches
    across the gap, and Thompson never tries the action where it would pay. Widened to the gap,
    the prior over an untried action's value spans the values the actions take."""
    if phi_BD.shape[0] == 0:
        return 1.0
    q_BA = head.q_mean(phi_BD)
    gap = float((q_BA.max(dim=1).values - q_BA.min(dim=1).values).mean())
    return max(1.0, gap / head.prior_std) if math.isfinite(gap) else 1.0


@torch.no_grad()
def greedy_predictive_variance(head: BLRHead, phi_BD: torch.Tensor) -> float:
    """Q-variance for adaptive k (Alg. 1 line 7, SPEC 2.1).

    The mean over rows of cov_scale * phi^T Cov_a phi at the greedy action a = argmax_a q_mean.
    """
    if phi_BD.shape[0] == 0:
        raise ValueError("greedy_predictive_variance needs at least one row of features")
    greedy_B = head.q_mean(phi_BD).argmax(dim=1)
    return float(head.predictive_var_action(phi_BD, greedy_B).mean())
