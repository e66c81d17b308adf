"""The :class:`BLRHead`: per-action sufficient statistics, the cached posterior, Thompson draws
and predictive variances, and its checkpoint (re-exported by :mod:`farsighter.ops.blr`, whose
docstring states the model and the ``residual`` scale).

Tensor names carry shape suffixes: N samples, B rows (states / environments), A actions, D features.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import torch

from farsighter.errors import Diverged
from farsighter.ops.blr_posterior import _check_stds, all_finite, blr_posterior_factor

SCALES = ("fixed", "residual")

# Largest number of float elements a (rows, A, D) temporary may hold in q_sample / predictive_var;
# bigger batches are processed in row blocks so memory stays bounded (16 MiB of float32).
_MAX_BLOCK_ELEMS = 1 << 22


class BLRHead:
    """Per-action Bayesian linear regression on features phi (Eq. 9), Thompson sampling (Eq. 7).

    Holds the sufficient statistics ``phiphiT_ADD`` (sum phi phi^T) and ``phiy_AD`` (sum phi y) per
    action in ``stats_dtype`` (float64 by default, since sums over 1e5 samples lose precision in
    float32), and caches the posterior mean and square-root covariance in float32 on ``device`` for
    acting. Before the first ``refresh`` the posterior is the prior: mean 0 (or what ``set_mean``
    gave) and covariance prior_std^2 I.

    Args:
        num_actions: |A|.
        dim: feature dimension d.
        prior_std: prior standard deviation sigma (SPEC/Table 1 default 0.1).
        noise_std: observation noise standard deviation sigma_eps (default 1).
        cov_scale: multiplies the covariance used for sampling and predictive variance (the BDQN
            authors' code multiplies the stored covariance by the prior variance; SPEC calls it
            the covariance scale). 1 gives the literal Eq. 9 posterior.
        forgetting: in (0, 1]; every ``accumulate`` first multiplies the existing statistics by it
            (exponential forgetting of old features / targets). 1 = no forgetting.
        scale: ``fixed`` keeps prior_std and noise_std; ``residual`` re-estimates sigma_eps at
            every refresh as max(noise_std, RMS residual) and sets the prior sigma to
            sigma_eps * prior_std / noise_std (see the :mod:`farsighter.ops.blr` docstring).
        device: where statistics and caches live.
        stats_dtype: dtype of the sufficient statistics and of the exact posterior.
        fit_dim: the features regressed on the targets, the first ``fit_dim`` (None: all). The
            rest form a block of their own, fitted to 0 and with no cross terms: its mean stays
            0 (after the first refresh) and its covariance narrows only where rows were added.
    """

    def __init__(
        self,
        *,
        num_actions: int,
        dim: int,
        prior_std: float = 0.1,
        noise_std: float = 1.0,
        cov_scale: float = 1.0,
        forgetting: float = 1.0,
        scale: str = "fixed",
        device: str | torch.device = "cpu",
        stats_dtype: torch.dtype = torch.float64,
        fit_dim: int | None = None,
    ) -> None:
        if num_actions < 1:
            raise ValueError(f"num_actions must be >= 1, got {num_actions}")
        if dim < 1:
            raise ValueError(f"dim must be >= 1, got {dim}")
        if fit_dim is not None and not 1 <= fit_dim <= dim:
            raise ValueError(f"fit_dim must be in [1, {dim}], got {fit_dim}")
        _check_stds(prior_std, noise_std)
        if not (cov_scale >= 0 and math.isfinite(cov_scale)):
            raise ValueError(f"cov_scale must be a finite number >= 0, got {cov_scale}")
        if not (0 < forgetting <= 1):
            raise ValueError(f"forgetting must be in (0, 1], got {forgetting}")
        if not stats_dtype.is_floating_point:
            raise ValueError(f"stats_dtype must be a floating dtype, got {stats_dtype}")
        if scale not in SCALES:
            raise ValueError(f"scale must be one of {', '.join(SCALES)}, got {scale!r}")
        self.scale = scale
        # The configured values: constants (fixed) or the floor and the prior ratio (residual).
        self.noise_floor = float(noise_std)
        self.prior_ratio = float(prior_std) / float(noise_std)
        self.num_actions = int(num_actions)
        self.dim = int(dim)
        # The features past fit_dim fit no target: their block of the statistics gets no
        # y and no cross terms with the first fit_dim, so their mean stays 0 and their
        # covariance is their own (uncertainty about where the run has been, not values).
        self.fit_dim = self.dim if fit_dim is None else int(fit_dim)
        self.prior_std = float(prior_std)
        self.noise_std = float(noise_std)
        self.cov_scale = float(cov_scale)
        # A factor on the width of the acting draws alone (sample_weights; blr.act_width): the
        # targets' draws and the predictive variances keep the posterior's own width.
        self.act_scale: float = 1.0
        self.forgetting = float(forgetting)
        self.device = torch.device(device)
        self.stats_dtype = stats_dtype
        # Number of per-action precisions that needed jitter so far, and the largest jitter of the
        # latest refresh (0 if none); the agent logs these.
        self.jitter_events: int = 0
        self.last_jitter: float = 0.0
        self.num_refreshes: int = 0
        # Counts every change of the acting posterior (mean, square root or scale): draws made
        # ahead of time (ThompsonDraws) are valid while it stays the same.
        self.version: int = 0

        a, d = self.num_actions, self.dim
        self.phiphiT_ADD = torch.zeros(a, d, d, dtype=stats_dtype, device=self.device)
        self.phiy_AD = torch.zeros(a, d, dtype=stats_dtype, device=self.device)
        self.count_A = torch.zeros(
            a, dtype=stats_dtype, device=self.device
        )  # (forgetting-weighted)
        self.yy_A = torch.zeros(a, dtype=stats_dtype, device=self.device)  # sum y^2
        # Exact posterior (stats dtype); starts at the prior N(0, prior_std^2 I).
        self._mean_AD = torch.zeros(a, d, dtype=stats_dtype, device=self.device)
        eye_DD = torch.eye(d, dtype=stats_dtype, device=self.device)
        self._sqrt_cov_ADD = (self.prior_std * eye_DD).expand(a, d, d).clone()
        self._rebuild_cache()

    # ----------------------------------------------------------------------------------------------
    # statistics and posterior updates
    # ----------------------------------------------------------------------------------------------
    def reset_statistics(self) -> None:
        """Zero the sufficient statistics (the posterior itself changes at the next ``refresh``)."""
        self.phiphiT_ADD.zero_()
        self.phiy_AD.zero_()
        self.count_A.zero_()
        self.yy_A.zero_()

    def restart(self) -> None:
        """Back to the prior: the statistics zeroed, the configured sigma_eps and prior sigma
        (which ``scale = residual`` moves), and the posterior refreshed from them (mean 0, the
        prior's width)."""
        self.reset_statistics()
        self.noise_std, self.prior_std = self.noise_floor, self.prior_ratio * self.noise_floor
        self.refresh()

    def forget_targets(self) -> None:
        """Keep the rows, drop their targets: the sums of y and y^2 zeroed, as if every target
        had been 0, and the posterior refreshed (mean 0, the width the rows made it)."""
        self.phiy_AD.zero_()
        self.yy_A.zero_()
        self.refresh()

    @torch.no_grad()
    def accumulate(
        self,
        phi_ND: torch.Tensor,
        action_N: torch.Tensor,
        y_N: torch.Tensor,
        chunk_size: int = 8192,
    ) -> None:
        """Add samples (phi_i, a_i, y_i) to the per-action statistics Phi_a Phi_a^T and Phi_a y_a.

        Existing statistics are first multiplied by ``forgetting``. Each action's rows, in their
        order in the minibatch, are added with one GEMM per chunk of ``chunk_size`` rows
        (chunking bounds the float64 copy of phi: 8192 x 512 x 8 B = 32 MiB). Features past
        ``fit_dim`` go into their own block, with targets 0.
        """
        if phi_ND.dim() != 2 or phi_ND.shape[1] != self.dim:
            raise ValueError(f"phi_ND must have shape (N, {self.dim}), got {tuple(phi_ND.shape)}")
        n = phi_ND.shape[0]
        if action_N.shape != (n,) or y_N.shape != (n,):
            raise ValueError(
                f"action_N and y_N must have shape ({n},), got {tuple(action_N.shape)} and "
                f"{tuple(y_N.shape)}"
            )
        if chunk_size < 1:
            raise ValueError(f"chunk_size must be >= 1, got {chunk_size}")
        if self.forgetting != 1.0:
            self.phiphiT_ADD.mul_(self.forgetting)
            self.phiy_AD.mul_(self.forgetting)
            self.count_A.mul_(self.forgetting)
            self.yy_A.mul_(self.forgetting)
        if n == 0:
            return
        action_N = action_N.to(device=self.device, dtype=torch.long)
        low, high = (int(v) for v in torch.aminmax(action_N))
        if low < 0 or high >= self.num_actions:
            raise ValueError(
                f"actions must lie in [0, {self.num_actions - 1}], got range [{low}, {high}]"
            )
        phi_ND = phi_ND.detach().to(device=self.device)
        y_N = y_N.detach().to(device=self.device, dtype=self.stats_dtype)
        f = self.fit_dim
        for a in range(low, high + 1):  # each action's rows in their order in the minibatch
            rows_M = torch.nonzero(action_N == a).squeeze(1)
            count = rows_M.shape[0]
            self.count_A[a] += count
            for lo in range(0, count, chunk_size):
                idx_C = rows_M[lo : lo + chunk_size]
                x_CD = phi_ND.index_select(0, idx_C).to(self.stats_dtype)
                y_C = y_N.index_select(0, idx_C)
                fit_CF, rest_CR = x_CD[:, :f], x_CD[:, f:]  # the second block's targets are 0
                self.phiphiT_ADD[a, :f, :f].addmm_(fit_CF.T, fit_CF)
                self.phiphiT_ADD[a, f:, f:].addmm_(rest_CR.T, rest_CR)  # empty when f = dim
                self.phiy_AD[a, :f].addmv_(fit_CF.T, y_C)
                self.yy_A[a] += y_C.square().sum()

    @torch.no_grad()
    def refresh(self) -> None:
        """Recompute the Eq. 9 posterior of every action from the statistics, O(|A| d^3).

        Updates the exact mean / square-root covariance (stats dtype) and the float32 caches used
        for acting; counts jitter repairs in ``jitter_events`` / ``last_jitter``. With
        ``scale="residual"`` sigma_eps (and the prior sigma with it) is first re-estimated from the
        residuals under the posterior mean, and the covariance scaled to it.
        """
        # NaN or inf targets reach phi y and y^2 first (cheap to check: A d numbers)
        if not (all_finite(self.phiy_AD) and all_finite(self.yy_A)):
            raise Diverged("the posterior's regression targets hold NaN or inf")
        mean_AD, sqrt_cov_ADD, jitter_A = blr_posterior_factor(
            self.phiphiT_ADD, self.phiy_AD, self.prior_std, self.noise_std
        )
        if self.scale == "residual" and float(self.count_A.sum()) > 0:
            # With sigma = ratio * sigma_eps the ridge sigma_eps^2 / sigma^2 is fixed, so the mean
            # does not depend on sigma_eps and Cov_a = sigma_eps^2 (Phi Phi^T + I / ratio^2)^-1:
            # re-estimating sigma_eps rescales the square root, with no second factorisation.
            new_noise = max(self.noise_floor, math.sqrt(residual_variance(self, mean_AD)))
            sqrt_cov_ADD = sqrt_cov_ADD * (new_noise / self.noise_std)
            self.noise_std, self.prior_std = new_noise, self.prior_ratio * new_noise
        repaired = int((jitter_A > 0).sum())
        self.jitter_events += repaired
        self.last_jitter = float(jitter_A.max()) if repaired else 0.0
        self._mean_AD = mean_AD
        self._sqrt_cov_ADD = sqrt_cov_ADD
        self.num_refreshes += 1
        self._rebuild_cache()

    def fit(self, phi_ND: torch.Tensor, action_N: torch.Tensor, y_N: torch.Tensor) -> None:
        """Batch mode (the paper's posterior update): reset, accumulate all samples, refresh."""
        self.reset_statistics()
        self.accumulate(phi_ND, action_N, y_N)
        self.refresh()

    @torch.no_grad()
    def set_mean(self, mean_AD: torch.Tensor) -> None:
        """Set the posterior mean, e.g. from a linear layer's initial weights before any refresh.

        The covariance is left unchanged; the next ``refresh`` overwrites the mean with Eq. 9.
        """
        if tuple(mean_AD.shape) != (self.num_actions, self.dim):
            raise ValueError(
                f"mean_AD must have shape ({self.num_actions}, {self.dim}), "
                f"got {tuple(mean_AD.shape)}"
            )
        self._mean_AD = mean_AD.detach().to(device=self.device, dtype=self.stats_dtype).clone()
        self._rebuild_cache()

    def _rebuild_cache(self) -> None:
        # float32 copies for acting. The square roots are laid out as (D, A*D) so that phi_BD @ it
        # gives phi^T U_a for every action in a single GEMM (used by q_sample and predictive_var).
        # They are refreshed in place, so a captured CUDA graph (farsighter.agents.cuda_graph) that
        # reads mean_AD sees every refresh.
        a, d = self.num_actions, self.dim
        self.version += 1
        self._mean32_AD = _in_place(getattr(self, "_mean32_AD", None), self._mean_AD)
        self._sqrt_cov32_ADD = _in_place(getattr(self, "_sqrt_cov32_ADD", None), self._sqrt_cov_ADD)
        sqrt_cov_DX = self._sqrt_cov32_ADD.permute(1, 0, 2).reshape(d, a * d)
        self._sqrt_cov32_DX = _in_place(getattr(self, "_sqrt_cov32_DX", None), sqrt_cov_DX)

    # ----------------------------------------------------------------------------------------------
    # posterior access
    # ----------------------------------------------------------------------------------------------
    @property
    def mean_AD(self) -> torch.Tensor:
        """Posterior mean of Eq. 9 (float32, on ``device``)."""
        return self._mean32_AD

    @property
    def sqrt_cov_ADD(self) -> torch.Tensor:
        """Unscaled square root U_a of Cov_a (U U^T = Cov_a; float32, upper triangular)."""
        return self._sqrt_cov32_ADD

    @property
    def cov_ADD(self) -> torch.Tensor:
        """cov_scale * Cov_a, the covariance used for sampling (stats dtype)."""
        cov_ADD = self._sqrt_cov_ADD @ self._sqrt_cov_ADD.transpose(-1, -2)
        return self.cov_scale * 0.5 * (cov_ADD + cov_ADD.transpose(-1, -2))

    def posterior(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The literal Eq. 9 posterior (mean_AD, Cov_a), unscaled, in the stats dtype."""
        cov_ADD = self._sqrt_cov_ADD @ self._sqrt_cov_ADD.transpose(-1, -2)
        return self._mean_AD.clone(), 0.5 * (cov_ADD + cov_ADD.transpose(-1, -2))

    def _phi32(self, phi_BD: torch.Tensor) -> torch.Tensor:
        if phi_BD.dim() != 2 or phi_BD.shape[1] != self.dim:
            raise ValueError(f"phi_BD must have shape (B, {self.dim}), got {tuple(phi_BD.shape)}")
        return phi_BD.detach().to(device=self.device, dtype=torch.float32)

    def _block_rows(self) -> int:
        return max(1, _MAX_BLOCK_ELEMS // (self.num_actions * self.dim))

    # ----------------------------------------------------------------------------------------------
    # acting
    # ----------------------------------------------------------------------------------------------
    @torch.no_grad()
    def q_mean(self, phi_BD: torch.Tensor) -> torch.Tensor:
        """Q under the posterior mean, phi^T mean_a (Eq. 8's w = mean), shape (B, A), float32."""
        return self._phi32(phi_BD) @ self._mean32_AD.T

    @torch.no_grad()
    def q_sample(
        self, phi_BD: torch.Tensor, generator: torch.Generator | None = None
    ) -> torch.Tensor:
        """Thompson-sampled Q of Eq. 7: phi^T (mean_a + sqrt(cov_scale) U_a z), shape (B, A).

        A fresh, independent z ~ N(0, I_d) is drawn for every row (state / environment) and every
        action. Only phi^T U_a (B x A x D) is formed, never B x A weight matrices, in row blocks
        of bounded size. ``generator`` must live on the head's device.
        """
        phi_BD = self._phi32(phi_BD)
        return phi_BD @ self._mean32_AD.T + self.q_noise(phi_BD, generator)

    @torch.no_grad()
    def q_noise(
        self,
        phi_BD: torch.Tensor,
        generator: torch.Generator | None = None,
        z_BAD: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """The random part of ``q_sample``: sqrt(cov_scale) phi^T U_a z with a fresh z per row and
        action, shape (B, A); its variance is ``predictive_var``. ``z_BAD`` gives the standard
        normals instead of drawing them (the closed form is checked so). A target's noise, fresh
        per row only, is drawn from fewer normals by :meth:`q_noise_rows`."""
        noise_BA, scale = self._per_action(phi_BD), math.sqrt(self.cov_scale)
        for rows, phiu_KAD in self._phi_u_blocks(phi_BD):
            z_KAD = self._normals(len(phiu_KAD), generator) if z_BAD is None else z_BAD[rows]
            noise_BA[rows] = scale * (phiu_KAD * z_KAD).sum(-1)
        return noise_BA

    @torch.no_grad()
    def q_noise_rows(self, phi_BD: torch.Tensor, eps_BA: torch.Tensor) -> torch.Tensor:
        """``q_noise``'s distribution, drawn from one standard normal per row and action:
        phi^T U_a z with z ~ N(0, I_d) is N(0, phi^T U_a U_a^T phi), so
        sqrt(cov_scale) ||U_a^T phi|| eps_a with eps_a ~ N(0, 1) is the same draw, made from A
        normals a row instead of A d (:meth:`noise_eps` draws them). For draws that are fresh
        per row only (a target's noise): a draw held over several rows needs its z."""
        sd_BA = self._per_action(phi_BD)
        for rows, phiu_KAD in self._phi_u_blocks(phi_BD):
            torch.linalg.vector_norm(phiu_KAD, dim=-1, out=sd_BA[rows])
        return sd_BA.mul_(eps_BA).mul_(math.sqrt(self.cov_scale))

    @torch.no_grad()
    def q_noise_rows_action(
        self, phi_BD: torch.Tensor, action_B: torch.Tensor, eps_B: torch.Tensor
    ) -> torch.Tensor:
        """:meth:`q_noise_rows` of one action per row, sqrt(cov_scale) ||U_{a_b}^T phi_b|| eps_b,
        shape (B,): B d^2 arithmetic (each action's rows in one product) where every action's
        costs B A d^2, so with 7 actions (MiniGrid) a seventh of it. On an accelerator every
        action's product is formed and the row's one gathered, which keeps the step free of
        data-dependent shapes (a captured graph can run it)."""
        if self.device.type != "cpu":
            ones_BA = torch.ones(phi_BD.shape[0], self.num_actions, device=self.device)
            sd_B = self.q_noise_rows(phi_BD, ones_BA).gather(
                1, action_B.to(device=self.device, dtype=torch.long)[:, None]
            )[:, 0]
            return sd_B.mul_(eps_B)
        out_B = torch.empty(phi_BD.shape[0], dtype=torch.float32, device=self.device)
        for idx_K, phiu_KD in self._phi_u_by_action(phi_BD, action_B):
            out_B[idx_K] = torch.linalg.vector_norm(phiu_KD, dim=-1)
        return out_B.mul_(eps_B).mul_(math.sqrt(self.cov_scale))

    def _phi_u_by_action(
        self, phi_BD: torch.Tensor, action_B: torch.Tensor
    ) -> Iterator[tuple[torch.Tensor, torch.Tensor]]:
        """phi_b^T U_{a_b} of every row for its own action, (K, D), one product per action
        present, each with the rows it covers."""
        phi_BD = self._phi32(phi_BD)
        action_B = action_B.to(device=self.device, dtype=torch.long)
        if action_B.shape != (phi_BD.shape[0],):
            raise ValueError(
                f"action_B must have shape ({phi_BD.shape[0]},), got {tuple(action_B.shape)}"
            )
        for a in torch.unique(action_B).tolist():
            idx_K = (action_B == a).nonzero().squeeze(-1)
            yield idx_K, phi_BD.index_select(0, idx_K) @ self._sqrt_cov32_ADD[a]

    def _per_action(self, phi_BD: torch.Tensor) -> torch.Tensor:
        """An uninitialised float32 (B, A) for a value per row and action of ``phi_BD``."""
        return torch.empty(
            phi_BD.shape[0], self.num_actions, dtype=torch.float32, device=self.device
        )

    def _phi_u_blocks(self, phi_BD: torch.Tensor) -> Iterator[tuple[slice, torch.Tensor]]:
        """phi^T U_a of every row and action, (K, A, D), in row blocks of bounded size, each
        with the rows it covers."""
        phi_BD = self._phi32(phi_BD)
        a, d, step = self.num_actions, self.dim, self._block_rows()
        for lo in range(0, phi_BD.shape[0], step):
            yield (
                slice(lo, lo + step),
                (phi_BD[lo : lo + step] @ self._sqrt_cov32_DX).view(-1, a, d),
            )

    def noise_eps(self, rows: int, generator: torch.Generator | None = None) -> torch.Tensor:
        """The standard normals of :meth:`q_noise_rows`, shape (rows, A)."""
        shape = (rows, self.num_actions)
        return torch.randn(shape, generator=generator, device=self.device, dtype=torch.float32)

    def _normals(self, rows: int, generator: torch.Generator | None) -> torch.Tensor:
        """One block of standard normals, shape (rows, A, D)."""
        shape = (rows, self.num_actions, self.dim)
        return torch.randn(shape, generator=generator, device=self.device, dtype=torch.float32)

    @torch.no_grad()
    def sample_weights(self, n: int, generator: torch.Generator | None = None) -> torch.Tensor:
        """n independent draws w = mean_a + sqrt(cov_scale) act_scale U_a z of every action's
        weights (Eq. 7; ``act_scale`` 1 unless ``blr.act_width`` widens the acting draws).

        Returns shape (n, A, D), float32; z is independent across draws and actions.
        """
        if n < 0:
            raise ValueError(f"n must be >= 0, got {n}")
        z_ADN = torch.randn(
            (self.num_actions, self.dim, n),
            generator=generator,
            device=self.device,
            dtype=torch.float32,
        )
        if n <= 2 and self.device.type == "cpu":
            # One or two draws (an environment's held draw replaced): (z^T U^T)^T, the same bits
            # as U z. On CPU, bmm with one or two columns takes a slow path (0.8 ms for two
            # 596 x 596 actions); with the product turned around it takes 0.16 ms.
            noise_ADN = torch.bmm(z_ADN.transpose(1, 2), self._sqrt_cov32_ADD.transpose(1, 2))
            noise_ADN = noise_ADN.transpose(1, 2)
        else:
            noise_ADN = torch.bmm(self._sqrt_cov32_ADD, z_ADN)
        width = math.sqrt(self.cov_scale) * self.act_scale
        return self._mean32_AD.unsqueeze(0) + width * noise_ADN.permute(2, 0, 1)

    @torch.no_grad()
    def predictive_var(self, phi_BD: torch.Tensor) -> torch.Tensor:
        """Variance of the sampled Q: cov_scale * phi^T Cov_a phi = cov_scale * ||U_a^T phi||^2.

        Shape (B, A), float32. Costs B * A * D^2; for one action per row use
        ``predictive_var_action``.
        """
        out_BA = self._per_action(phi_BD)
        for rows, phiu_KAD in self._phi_u_blocks(phi_BD):
            out_BA[rows] = phiu_KAD.square().sum(-1)
        return self.cov_scale * out_BA

    @torch.no_grad()
    def predictive_var_action(self, phi_BD: torch.Tensor, action_B: torch.Tensor) -> torch.Tensor:
        """cov_scale * phi_b^T Cov_{a_b} phi_b for one action per row, shape (B,), float32.

        Rows are grouped by action (one GEMM per action present), so the cost is B * D^2 rather
        than B * A * D^2 (this matters for the adaptive-k Q-variance over ~1e5 refresh states).
        """
        out_B = torch.empty(phi_BD.shape[0], dtype=torch.float32, device=self.device)
        for idx_K, phiu_KD in self._phi_u_by_action(phi_BD, action_B):
            out_B[idx_K] = phiu_KD.square().sum(-1)
        return self.cov_scale * out_B

    # ----------------------------------------------------------------------------------------------
    # checkpointing
    # ----------------------------------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        """Plain dict of tensors and numbers that restores this head exactly."""
        return {
            "num_actions": self.num_actions,
            "dim": self.dim,
            "prior_std": self.prior_std,
            "noise_std": self.noise_std,
            "cov_scale": self.cov_scale,
            "act_scale": self.act_scale,
            "forgetting": self.forgetting,
            "scale": self.scale,
            "noise_floor": self.noise_floor,
            "prior_ratio": self.prior_ratio,
            "jitter_events": self.jitter_events,
            "last_jitter": self.last_jitter,
            "num_refreshes": self.num_refreshes,
            "version": self.version,
            "phiphiT_ADD": self.phiphiT_ADD.clone(),
            "phiy_AD": self.phiy_AD.clone(),
            "count_A": self.count_A.clone(),
            "yy_A": self.yy_A.clone(),
            "mean_AD": self._mean_AD.clone(),
            "sqrt_cov_ADD": self._sqrt_cov_ADD.clone(),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore from ``state_dict()``; num_actions and dim must match this head."""
        if int(state["num_actions"]) != self.num_actions or int(state["dim"]) != self.dim:
            raise ValueError(
                f"state is for num_actions={state['num_actions']}, dim={state['dim']}; this head "
                f"has num_actions={self.num_actions}, dim={self.dim}"
            )
        _check_stds(float(state["prior_std"]), float(state["noise_std"]))
        self.prior_std = float(state["prior_std"])
        self.noise_std = float(state["noise_std"])
        self.cov_scale = float(state["cov_scale"])
        self.act_scale = float(state.get("act_scale", 1.0))
        self.forgetting = float(state["forgetting"])
        self.scale = str(state.get("scale", "fixed"))
        self.noise_floor = float(state.get("noise_floor", self.noise_std))
        self.prior_ratio = float(state.get("prior_ratio", self.prior_std / self.noise_std))
        self.jitter_events = int(state["jitter_events"])
        self.last_jitter = float(state["last_jitter"])
        self.num_refreshes = int(state["num_refreshes"])

        def _t(key: str) -> torch.Tensor:
            return state[key].detach().to(device=self.device, dtype=self.stats_dtype).clone()

        self.phiphiT_ADD = _t("phiphiT_ADD")
        self.phiy_AD = _t("phiy_AD")
        self.count_A = _t("count_A")
        self.yy_A = _t("yy_A") if "yy_A" in state else torch.zeros_like(self.count_A)
        self._mean_AD = _t("mean_AD")
        self._sqrt_cov_ADD = _t("sqrt_cov_ADD")
        self._rebuild_cache()
        # the saved count, so that draws saved with it (ThompsonDraws) stay valid after a resume
        self.version = int(state.get("version", self.version))


def _in_place(cache: torch.Tensor | None, value: torch.Tensor) -> torch.Tensor:
    """``value`` as a contiguous float32 tensor, written into ``cache`` when it fits."""
    if cache is not None and cache.shape == value.shape and cache.device == value.device:
        return cache.copy_(value)
    return value.to(torch.float32).contiguous().clone()


@torch.no_grad()
def residual_variance(head: BLRHead, mean_AD: torch.Tensor | None = None) -> float:
    """Mean squared residual of the regression targets under a weight mean, pooled over actions.

    sum_a ||y_a - Phi_a^T m_a||^2 / sum_a n_a, from the statistics alone:
    ||y - Phi^T m||^2 = sum y^2 - 2 m^T Phi y + m^T Phi Phi^T m. The weights are the
    forgetting-weighted counts, so with forgetting it is a weighted mean. ``mean_AD`` defaults to
    the head's posterior mean (stats dtype). Returns 0 when the head holds no data.
    """
    m_AD = head._mean_AD if mean_AD is None else mean_AD.to(head.stats_dtype)
    n = float(head.count_A.sum())
    if n <= 0:
        return 0.0
    fit_A = torch.einsum("ad,ade,ae->a", m_AD, head.phiphiT_ADD, m_AD)
    rss = float((head.yy_A - 2.0 * (m_AD * head.phiy_AD).sum(-1) + fit_A).sum())
    return max(rss, 0.0) / n
