"""The posterior refitted to a replay by fitted Q-iteration (``blr.switch_restart = refit``).

At ``blr.optimism``'s switch every target the posterior's statistics hold carried the optimism.
Instead of restarting from the prior (and waiting for minibatches to bring the found reward back,
a few of its samples at a time), the posterior can be refitted to the transitions the run has:
the rows' features phi(s) weighed as the statistics weigh a step, and their targets, the
calibrated Bellman targets y = r^k + gamma^k max_a phi(s')^T w_a (the same features at s and
s'), taken under the fit's own mean and fitted again until they settle (fitted Q-iteration,
Ernst et al. 2005, on a ridge regression with fixed features). What the rewards confirm stays
(the found path, the learned penalties); what the optimism added goes.

A fit that overestimates is not kept: where a target passes the rows' ``ceiling`` (the largest
discounted reward sum their episodes showed from any step to any later one) by more than
:data:`REFIT_SLACK`, the refit gives up and leaves the posterior at its prior, the restart it
replaces. The max over loosely pinned values overestimates, and the iterations compound it
(Taxi-v4: targets up to 218 where no return exceeds 20); on deep sea and the drifting lock the
fixed point stays at the ceiling (the paid step's own reward).

The features do not change while it iterates, so Phi Phi^T and the Cholesky factor of the
precision are formed once; each iteration is one product for the targets, one per action for
Phi y and a triangular solve: O(n d |A|), against O(|A| d^3) for a refresh.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from farsighter.ops.blr import BLRHead, factor_mean, precision_factor

REFIT_ITERATIONS = 200
"""Most iterations: each carries a value back by one window (k steps, fewer where cut)."""

REFIT_TOLERANCE = 1e-4
"""Iterations stop when no target moved by more than this times max(1, the largest |target|)."""

REFIT_SLACK = 0.01
"""A target above the ceiling by more than this times max(1, |ceiling|) rejects the fit."""


@dataclass
class ReplayRows:
    """The k-step windows a refit fits: phi(s) (float64), the action, r^k, the bootstrap factor
    gamma^k (0 after a terminal) and phi(s') of each row."""

    phi_ND: torch.Tensor
    action_N: torch.Tensor
    returns_N: torch.Tensor
    bootstrap_N: torch.Tensor
    phi_next_ND: torch.Tensor
    ceiling: float = math.inf
    """The largest discounted reward sum the rows' episodes showed from any of their steps to
    any later one (what the rewards confirm): a fit with a target above it is rejected (inf:
    none, and the fit is rejected only where it diverges)."""

    def __len__(self) -> int:
        return int(self.action_N.shape[0])


@dataclass(frozen=True)
class RefitOutcome:
    """What :func:`refit` did."""

    iterations: int
    """Fitted Q-iterations made."""
    accepted: bool
    """Whether the posterior holds the fit (else it was left at its prior)."""
    largest: float
    """The largest target of the last iteration made (of the one that rejected the fit)."""


def bellman_targets(rows: ReplayRows, mean_AD: torch.Tensor) -> torch.Tensor:
    """y = r^k + gamma^k max_a phi(s')^T mean_a of every row (float64)."""
    q_NA = rows.phi_next_ND @ mean_AD.to(rows.phi_next_ND.dtype).T
    return rows.returns_N.double() + rows.bootstrap_N.double() * q_NA.max(dim=1).values.double()


def fit_limits(rows: ReplayRows) -> tuple[float, float]:
    """What a fit's targets may reach (:func:`fit_is_sound`): the rows' ``ceiling`` and its
    :data:`REFIT_SLACK` (above it the fit overestimates), and in magnitude what no fixed point
    of the rows reaches, their largest |return| over 1 - gamma^k's smallest (beyond it the fit
    diverges)."""
    ceiling = rows.ceiling + REFIT_SLACK * max(1.0, abs(rows.ceiling))
    bound = float(rows.returns_N.abs().max()) / max(1.0 - float(rows.bootstrap_N.max()), 1e-6)
    return ceiling, max(bound, 1.0) * 1.01


def fit_is_sound(y_N: torch.Tensor, limits: tuple[float, float]) -> bool:
    """Whether a fit's targets ``y_N`` may be kept: none above the first of :func:`fit_limits`,
    none beyond the second in magnitude, no NaN."""
    ceiling, bound = limits
    return float(y_N.max()) <= ceiling and float(y_N.abs().max()) <= bound


@torch.no_grad()
def refit(
    head: BLRHead,
    rows: ReplayRows,
    weight: float,
    count: float = 1.0,
    max_iterations: int = REFIT_ITERATIONS,
    tol: float = REFIT_TOLERANCE,
) -> RefitOutcome:
    """Replace the head's statistics by the rows' (each weighing ``weight`` and counting
    ``count`` rows, as the statistics count a step) with targets fitted by fitted Q-iteration
    from the head's current mean, then refresh.

    Each iteration takes the targets under the latest mean and solves for the next mean, which
    is the mean :meth:`BLRHead.refresh` gives from the same statistics (the precision's factor is
    formed once). It stops when the targets settle or after ``max_iterations``. Where a target
    fails :func:`fit_is_sound` (an overestimating or diverging fit) the head is restarted
    instead (:meth:`BLRHead.restart`): the fit is not kept, and the head is at its prior.
    """
    if weight <= 0:
        raise ValueError(f"weight must be > 0, got {weight}")
    head.reset_statistics()
    if len(rows) == 0:
        head.refresh()
        return RefitOutcome(0, True, -math.inf)
    a_N = rows.action_N.to(head.device, torch.long)
    order_N = torch.argsort(a_N, stable=True)  # each action's rows in one slice, in their order
    a_N = a_N[order_N]
    rows = ReplayRows(
        rows.phi_ND[order_N].to(head.device, head.stats_dtype),
        a_N,
        rows.returns_N[order_N],
        rows.bootstrap_N[order_N],
        rows.phi_next_ND[order_N],
        rows.ceiling,
    )
    ends = torch.bincount(a_N, minlength=head.num_actions).cumsum(0).tolist()
    spans = [slice(lo, hi) for lo, hi in zip([0, *ends[:-1]], ends, strict=True)]
    y_N = bellman_targets(rows, head.mean_AD).to(head.stats_dtype)
    root = weight**0.5
    head.accumulate(rows.phi_ND * root, a_N, y_N * root)
    head.count_A.mul_(count)  # (the residual scale divides the weighted sums by the count)
    l_ADD, _ = precision_factor(head.phiphiT_ADD, head.prior_std, head.noise_std)
    limits = fit_limits(rows)
    iterations, largest = 0, float(y_N.max())
    while iterations < max_iterations:
        mean_AD = factor_mean(l_ADD, head.phiy_AD, head.noise_std)
        new_N = bellman_targets(rows, mean_AD).to(head.stats_dtype)
        iterations, largest = iterations + 1, float(new_N.max())
        if not fit_is_sound(new_N, limits):
            head.restart()
            return RefitOutcome(iterations, False, largest)
        moved = float((new_N - y_N).abs().max())
        y_N = new_N
        for a, span in enumerate(spans):  # Phi_a y_a and y_a^T y_a of the new targets
            head.phiy_AD[a] = (rows.phi_ND[span].T @ y_N[span]) * weight
            head.yy_A[a] = y_N[span].square().sum() * weight
        if moved <= tol * max(1.0, float(y_N.abs().max())):
            break
    head.refresh()
    return RefitOutcome(iterations, True, largest)
