"""The Eq. 9 posterior from per-action sufficient statistics, as pure functions of tensors:
Cholesky factoring with jitter repair, the precision's factor, the mean and the square root of
the covariance (re-exported by :mod:`farsighter.ops.blr`, whose docstring states the model).

Tensor names carry shape suffixes: N samples, B rows (states / environments), A actions, D features.
"""

from __future__ import annotations

import math

import torch


def all_finite(x: torch.Tensor) -> bool:
    """Whether every entry is finite. x * 0 is 0 for a finite x and NaN for inf or NaN, so the sum
    is 0 exactly when all are (``isfinite().all()`` says the same at four times the cost on a
    640 x 640 float64)."""
    return bool((x * 0).sum() == 0)


def cholesky_jitter(
    m_XDD: torch.Tensor,
    initial_jitter: float = 1e-10,
    growth: float = 10.0,
    max_tries: int = 30,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Lower Cholesky factor of a (batch of) symmetric matrices, repaired with jitter if needed.

    The input is symmetrised, (M + M^T) / 2, because a precision or covariance built in floating
    point is only symmetric up to rounding (the BDQN authors symmetrise too). Each matrix whose
    factorisation fails gets ``jitter * I`` added, starting at ``initial_jitter * mean |diag|`` and
    multiplied by ``growth`` per try, until ``torch.linalg.cholesky_ex`` succeeds. No exception is
    raised for a matrix that jitter can fix; the caller decides whether to log the repair.

    Args:
        m_XDD: tensor of shape (..., D, D).
        initial_jitter: first jitter, relative to the mean absolute diagonal of each matrix.
        growth: factor by which the jitter grows per failed try.
        max_tries: tries after the plain attempt before giving up.

    Returns:
        (L_XDD, jitter_X): lower-triangular factors with L L^T = sym(M) + jitter I, and the absolute
        jitter added to each matrix (0 where none was needed).

    Raises:
        ValueError: the input is not square, holds NaN/inf, or cannot be repaired in ``max_tries``.
    """
    if m_XDD.dim() < 2 or m_XDD.shape[-1] != m_XDD.shape[-2]:
        raise ValueError(f"expected a (..., D, D) tensor, got shape {tuple(m_XDD.shape)}")
    if not all_finite(m_XDD):
        raise ValueError("cholesky_jitter: the matrix holds NaN or inf; jitter cannot repair that")
    sym_XDD = 0.5 * (m_XDD + m_XDD.transpose(-1, -2))
    batch_shape = sym_XDD.shape[:-2]
    dim = sym_XDD.shape[-1]
    sym_YDD = sym_XDD.reshape(-1, dim, dim)  # flatten the batch so failed matrices can be indexed
    jitter_Y = torch.zeros(sym_YDD.shape[0], dtype=sym_YDD.dtype, device=sym_YDD.device)
    l_YDD, info_Y = torch.linalg.cholesky_ex(sym_YDD)
    failed_Y = info_Y != 0
    if bool(failed_Y.any()):
        eye_DD = torch.eye(dim, dtype=sym_YDD.dtype, device=sym_YDD.device)
        scale_Y = sym_YDD.diagonal(dim1=-2, dim2=-1).abs().mean(-1)
        scale_Y = torch.where(scale_Y > 0, scale_Y, torch.ones_like(scale_Y))
        step_Y = initial_jitter * scale_Y
        for _ in range(max_tries):
            idx_F = failed_Y.nonzero().squeeze(-1)
            trial_FDD = sym_YDD[idx_F] + step_Y[idx_F, None, None] * eye_DD
            l_FDD, info_F = torch.linalg.cholesky_ex(trial_FDD)
            ok_F = info_F == 0
            ok_idx = idx_F[ok_F]
            l_YDD[ok_idx] = l_FDD[ok_F]
            jitter_Y[ok_idx] = step_Y[ok_idx]
            failed_Y[ok_idx] = False
            if not bool(failed_Y.any()):
                break
            step_Y = step_Y * growth
        else:
            raise ValueError(
                f"cholesky_jitter: {int(failed_Y.sum())} matrix(es) still not positive definite "
                f"after {max_tries} jitter increases (last jitter {float(step_Y.max()):.3g})"
            )
    return l_YDD.reshape(*batch_shape, dim, dim), jitter_Y.reshape(batch_shape)


def _check_stds(prior_std: float, noise_std: float) -> None:
    if not (prior_std > 0 and math.isfinite(prior_std)):
        raise ValueError(f"prior_std must be a finite number > 0, got {prior_std}")
    if not (noise_std > 0 and math.isfinite(noise_std)):
        raise ValueError(f"noise_std must be a finite number > 0, got {noise_std}")


def precision_factor(
    phiphiT_ADD: torch.Tensor, prior_std: float, noise_std: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """The lower Cholesky factor L of Eq. 9's precision P_a = Phi_a Phi_a^T / noise_std^2 +
    I / prior_std^2 (jitter-repaired), and the jitter added to each action's."""
    dim = phiphiT_ADD.shape[-1]
    eye_DD = torch.eye(dim, dtype=phiphiT_ADD.dtype, device=phiphiT_ADD.device)
    precision_ADD = phiphiT_ADD / noise_std**2 + eye_DD / prior_std**2  # Eq. 9, inverse of Cov_a
    return cholesky_jitter(precision_ADD)


def factor_mean(l_ADD: torch.Tensor, phiy_AD: torch.Tensor, noise_std: float) -> torch.Tensor:
    """Eq. 9's mean P_a^-1 Phi_a y_a / noise_std^2 from the precision's factor L."""
    return torch.cholesky_solve((phiy_AD / noise_std**2).unsqueeze(-1), l_ADD).squeeze(-1)


def blr_posterior_factor(
    phiphiT_ADD: torch.Tensor,
    phiy_AD: torch.Tensor,
    prior_std: float,
    noise_std: float,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Eq. 9 posterior as (mean, square root of the covariance, jitter), from sufficient statistics.

    The precision P_a = Phi_a Phi_a^T / noise_std^2 + I / prior_std^2 is factored as L L^T
    (jitter-repaired). Then Cov_a = P_a^-1 = L^-T L^-1, so U_a = L^-T (upper triangular) satisfies
    U_a U_a^T = Cov_a and is the sqrt(Cov_a) of Eq. 7; mean_a = P_a^-1 Phi_a y_a / noise_std^2.
    Cost O(d^3) per action, no data needed.

    Args:
        phiphiT_ADD: sum over samples of phi phi^T per action, shape (..., D, D).
        phiy_AD: sum over samples of phi * y per action, shape (..., D).
        prior_std: prior standard deviation sigma of each weight (zero-mean prior).
        noise_std: observation noise standard deviation sigma_eps.

    Returns:
        (mean_AD, sqrt_cov_ADD, jitter_A), in the dtype of the statistics.
    """
    _check_stds(prior_std, noise_std)
    l_ADD, jitter_A = precision_factor(phiphiT_ADD, prior_std, noise_std)
    mean_AD = factor_mean(l_ADD, phiy_AD, noise_std)
    eye_DD = torch.eye(l_ADD.shape[-1], dtype=l_ADD.dtype, device=l_ADD.device)
    # L^-1 by a triangular solve against I (cheaper and stabler than a general inverse).
    linv_ADD = torch.linalg.solve_triangular(l_ADD, eye_DD.expand_as(l_ADD), upper=False)
    sqrt_cov_ADD = linv_ADD.transpose(-1, -2)  # U = L^-T, U U^T = Cov_a
    return mean_AD, sqrt_cov_ADD, jitter_A


def blr_posterior(
    phiphiT_ADD: torch.Tensor,
    phiy_AD: torch.Tensor,
    prior_std: float,
    noise_std: float,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Posterior mean and covariance of Eq. 9 from the per-action sufficient statistics.

    Cov_a = (Phi_a Phi_a^T / noise_std^2 + I / prior_std^2)^-1 and
    mean_a = Cov_a Phi_a y_a / noise_std^2. An action without data gets the prior (mean 0,
    covariance prior_std^2 I). A precision that needs jitter is repaired silently; use
    ``blr_posterior_factor`` to see the jitter.

    Args:
        phiphiT_ADD: sum of phi phi^T per action, shape (..., D, D).
        phiy_AD: sum of phi * y per action, shape (..., D).
        prior_std: prior standard deviation sigma.
        noise_std: noise standard deviation sigma_eps.

    Returns:
        (mean_AD, cov_ADD) in the dtype of the statistics.
    """
    mean_AD, sqrt_cov_ADD, _ = blr_posterior_factor(phiphiT_ADD, phiy_AD, prior_std, noise_std)
    cov_ADD = sqrt_cov_ADD @ sqrt_cov_ADD.transpose(-1, -2)
    return mean_AD, 0.5 * (cov_ADD + cov_ADD.transpose(-1, -2))
