"""Normalized Advantage Function math (Gu et al. 2016; the paper's Sec. 3.3, Eq. 4).

    Q(s, a) = V(s | theta^V) + A(s, a | theta^A)
    A(s, a) = -1/2 (a - mu(s))^T P(s) (a - mu(s)),   P(s) = L(s) L(s)^T

with L lower-triangular and its diagonal exponentiated, so P is positive definite and
argmax_a Q(s, a) = mu(s). The architecture (appendix 9.1.2, SPEC 2.2): a 64-32 MLP
representation phi(s), linear V and L heads on top of it (:class:`NAFHead`), and a mu-layer
(Bayesian in ``bnaf`` / ``farsighter-naf``, see :mod:`farsighter.ops.bayes_layer`) whose output is
tanh-squashed to [-1, 1] and scaled to the action bounds with :func:`scale_action`.

Shape suffixes: B batch, A action dimension, M = A (A + 1) / 2 entries of L, D representation.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

__all__ = [
    "DEFAULT_LOG_DIAG_BOUNDS",
    "NAFHead",
    "naf_advantage",
    "naf_q",
    "naf_td_target",
    "lower_triangular",
    "num_tril_entries",
    "scale_action",
    "soft_clamp",
    "unscale_action",
]

# Bounds on the pre-exponential diagonal of L. exp(5) = 148 caps the curvature of the
# advantage from the diagonal at P_ii <= exp(10) ~ 2.2e4 (exp(12) at most with the soft
# shoulder; no overflow of A or its gradient), and exp(-5) keeps P clearly positive definite in
# float32 (exp(-12) at the very least). The bounds are SOFT
# (:func:`soft_clamp`): a hard clamp gives an entry outside the range no gradient at all, and
# on Pendulum-v1 a single large step that pushed every state's diagonal below the floor left P
# stuck at exp(-10) for the rest of the run (farsighter-naf, our runs). Pass ``None`` to disable.
DEFAULT_LOG_DIAG_BOUNDS: tuple[float, float] = (-5.0, 5.0)


def num_tril_entries(action_dim: int) -> int:
    """Number of free entries of an A x A lower-triangular matrix: A (A + 1) / 2."""
    return action_dim * (action_dim + 1) // 2


def soft_clamp(x: Tensor, low: float, high: float, margin: float = 1.0) -> Tensor:
    """The identity on [low, high], with soft shoulders outside that never lose the gradient.

    Outside the range the value is ``low - margin * tanh((low - x) / margin)`` (below) or
    ``high + margin * tanh((x - high) / margin)`` (above): continuous with slope 1 at the
    bounds, bounded in (low - margin, high + margin), and its gradient sech^2(d / margin) at a
    distance d past a bound decays but is never exactly 0 in the range that matters (unlike a
    hard clamp, which gives an entry past the bound no gradient at all).
    """
    below = low - margin * torch.tanh((low - x) / margin)
    above = high + margin * torch.tanh((x - high) / margin)
    return torch.where(x < low, below, torch.where(x > high, above, x))


def lower_triangular(
    entries_BM: Tensor,
    action_dim: int,
    log_diag_bounds: tuple[float, float] | None = DEFAULT_LOG_DIAG_BOUNDS,
) -> Tensor:
    """Build L (Eq. 4) from M = A (A + 1) / 2 unconstrained entries per row.

    The entries fill the lower triangle in row-major order, i.e. the order of
    ``torch.tril_indices(A, A)``: (0,0), (1,0), (1,1), (2,0), (2,1), (2,2), ... The diagonal
    entries are exponentiated ("the diagonal terms are exponentiated", Sec. 3.3) after a soft
    clamp to ``log_diag_bounds`` for numerical safety (see :data:`DEFAULT_LOG_DIAG_BOUNDS`); the
    off-diagonal entries are used as they are. Diagonal and off-diagonal entries are written
    separately, so no exp is ever taken of an off-diagonal value (no inf/NaN gradients).

    Args:
        entries_BM: tensor of shape (..., M).
        action_dim: A.
        log_diag_bounds: (low, high) soft clamp of the diagonal before exp, or None for none.

    Returns:
        L of shape (..., A, A), zero above the diagonal, strictly positive diagonal.
    """
    m = num_tril_entries(action_dim)
    if entries_BM.shape[-1] != m:
        raise ValueError(
            f"expected {m} entries for action_dim={action_dim}, got {entries_BM.shape[-1]}"
        )
    rows_M, cols_M = torch.tril_indices(action_dim, action_dim, device=entries_BM.device)
    is_diag_M = rows_M == cols_M
    diag_pos_A = torch.nonzero(is_diag_M).squeeze(-1)
    off_pos = torch.nonzero(~is_diag_M).squeeze(-1)

    log_diag_BA = entries_BM[..., diag_pos_A]
    if log_diag_bounds is not None:
        log_diag_BA = soft_clamp(log_diag_BA, log_diag_bounds[0], log_diag_bounds[1])

    l_BAA = entries_BM.new_zeros(*entries_BM.shape[:-1], action_dim, action_dim)
    l_BAA[..., rows_M[off_pos], cols_M[off_pos]] = entries_BM[..., off_pos]
    arange_A = torch.arange(action_dim, device=entries_BM.device)
    l_BAA[..., arange_A, arange_A] = torch.exp(log_diag_BA)
    return l_BAA


def naf_advantage(mu_BA: Tensor, l_BAA: Tensor, action_BA: Tensor) -> Tensor:
    """NAF advantage -1/2 (a - mu)^T P (a - mu) with P = L L^T, shape (...,).

    Computed as -1/2 ||L^T (a - mu)||^2, which is non-positive by construction and never
    forms P explicitly.
    """
    diff_BA = action_BA - mu_BA
    lt_diff_BA = torch.einsum("...ij,...i->...j", l_BAA, diff_BA)  # (L^T d)_j = sum_i L_ij d_i
    return -0.5 * (lt_diff_BA * lt_diff_BA).sum(dim=-1)


def naf_q(v_B: Tensor, mu_BA: Tensor, l_BAA: Tensor, action_BA: Tensor) -> Tensor:
    """Q(s, a) = V(s) + A(s, a) of Eq. 4, shape (...,)."""
    return v_B + naf_advantage(mu_BA, l_BAA, action_BA)


def naf_td_target(reward_B: Tensor, discount_B: Tensor, v_next_B: Tensor) -> Tensor:
    """TD target y = r + discount * V'(s').

    Since max_a' Q'(s', a') = V'(s') for NAF, the target only needs the target network's V at
    the bootstrap state.

    Args:
        reward_B: the (possibly k-step, already discounted-summed) reward.
        discount_B: the full bootstrap factor, i.e. ``gamma^n * (1 - terminated)`` where n is
            the number of environment steps actually taken (n = 1 for one-step targets, k for
            k-step returns, fewer when a time-limit truncation ends the window); 0 at terminal
            states gives ``y = r``.
        v_next_B: V(s') from the target network. This function does not detach it: compute
            it under ``torch.no_grad()`` (or detach) as usual for a TD target.
    """
    return reward_B + discount_B * v_next_B


def scale_action(u_BA: Tensor, low_A: Tensor | float, high_A: Tensor | float) -> Tensor:
    """Map u in [-1, 1] (e.g. a tanh output) affinely to [low, high]. Bounds must be finite."""
    low = torch.as_tensor(low_A, dtype=u_BA.dtype, device=u_BA.device)
    high = torch.as_tensor(high_A, dtype=u_BA.dtype, device=u_BA.device)
    return low + 0.5 * (u_BA + 1.0) * (high - low)


def unscale_action(a_BA: Tensor, low_A: Tensor | float, high_A: Tensor | float) -> Tensor:
    """Inverse of :func:`scale_action`: map a in [low, high] to [-1, 1]."""
    low = torch.as_tensor(low_A, dtype=a_BA.dtype, device=a_BA.device)
    high = torch.as_tensor(high_A, dtype=a_BA.dtype, device=a_BA.device)
    return 2.0 * (a_BA - low) / (high - low) - 1.0


class NAFHead(nn.Module):
    """V and L streams of NAF on top of a representation phi(s) (appendix 9.1.2).

    Both are single linear layers: V: D -> 1, L: D -> A (A + 1) / 2 entries turned into a
    lower-triangular matrix by :func:`lower_triangular`. The mu stream is not part of this head
    (in the agents it is a :class:`~farsighter.ops.bayes_layer.BayesianLinear` or ``nn.Linear``
    followed by tanh and :func:`scale_action`). Q is then
    ``naf_q(v_B, mu_BA, l_BAA, action_BA)``.

    Args:
        rep_dim: D, the size of phi (32 for the paper's 64-32 MLP).
        action_dim: A.
        log_diag_bounds: clamp of L's pre-exponential diagonal, see :func:`lower_triangular`.
    """

    def __init__(
        self,
        rep_dim: int,
        action_dim: int,
        *,
        log_diag_bounds: tuple[float, float] | None = DEFAULT_LOG_DIAG_BOUNDS,
    ) -> None:
        super().__init__()
        self.rep_dim = rep_dim
        self.action_dim = action_dim
        self.log_diag_bounds = log_diag_bounds
        self.v = nn.Linear(rep_dim, 1)
        self.l_entries = nn.Linear(rep_dim, num_tril_entries(action_dim))

    def forward(self, phi_BD: Tensor) -> tuple[Tensor, Tensor]:
        """Return ``(v_B, l_BAA)`` for a representation of shape (..., D)."""
        v_B = self.v(phi_BD).squeeze(-1)
        l_BAA = lower_triangular(self.l_entries(phi_BD), self.action_dim, self.log_diag_bounds)
        return v_B, l_BAA
