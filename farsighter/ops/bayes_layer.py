"""Bayesian linear layer (Bayes by backprop) and the ELBO loss of the paper's Eq. 10.

The continuous-action agents (``bnaf``, ``farsighter-naf``; paper Sec. 4.3, appendix 8,
Algorithm 3, SPEC section 2.2) put a Bayesian layer on top of the shared representation
phi(s) to produce the NAF action mu(phi(s) | theta^a). Its weights theta^a carry a factorised
Gaussian variational posterior q (Blundell et al. 2015, "Weight Uncertainty in Neural
Networks"): every weight and bias is an independent Gaussian with its own mean ``mu`` and
standard deviation ``sigma = softplus(rho)``, and the prior is N(0, prior_std^2) per weight.

The layer is used in three ways (``forward`` modes):

* ``"mean"``: deterministic, the posterior-mean weights. Used when training theta, theta^V,
  theta^P with mu fixed at its posterior mean (Sec. 4.3, "Update theta^V, theta^P, theta"), and
  for target computations.
* ``"local_reparam"``: the local reparameterisation trick (Kingma, Salimans and Welling 2015):
  instead of sampling weights, sample the layer's pre-activation output directly from its
  exact Gaussian marginal under q, with an independent noise per row. Used for the ELBO.
* ``"sample"``: draw one full weight set and apply it to the whole batch (Thompson sampling).

For acting, an agent draws weights explicitly with :meth:`BayesianLinear.sample_weights`
(one set per environment step) or :meth:`BayesianLinear.sample_weights_batch` (one set per
environment of a vector env) and applies them with ``forward_with`` / ``forward_with_batch``;
all randomness goes through optional :class:`torch.Generator` arguments.

Shape suffixes: B batch, I in_features, O out_features, N number of weight draws /
environments.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Literal, NamedTuple

import torch
import torch.nn.functional as F
from torch import Tensor, nn

__all__ = [
    "BayesianLinear",
    "ELBOTerms",
    "ForwardMode",
    "elbo_loss",
    "elbo_terms",
    "gaussian_kl",
    "inverse_softplus",
]

ForwardMode = Literal["mean", "local_reparam", "sample"]

# Added to the output variance before the square root in local_reparam mode so that the
# gradient of sqrt stays finite when a row has zero variance (e.g. an all-zero input with
# bias=False). Its effect on the standard deviation is at most 1e-8.
_VAR_EPS = 1e-16


def inverse_softplus(sigma: float) -> float:
    """Return ``rho`` with ``softplus(rho) == sigma`` (for ``sigma > 0``), computed stably."""
    if sigma <= 0.0:
        raise ValueError(f"sigma must be positive, got {sigma}")
    if sigma > 20.0:
        return sigma + math.log(-math.expm1(-sigma))
    return math.log(math.expm1(sigma))


def gaussian_kl(mu: Tensor, sigma: Tensor, prior_std: float) -> Tensor:
    """Closed-form ``sum KL(N(mu, sigma^2) || N(0, prior_std^2))`` over all elements.

    Per element: ``log(prior_std / sigma) + (sigma^2 + mu^2) / (2 prior_std^2) - 1/2``.
    """
    var_ratio = (sigma / prior_std) ** 2
    return 0.5 * (var_ratio + (mu / prior_std) ** 2 - 1.0 - torch.log(var_ratio)).sum()


class BayesianLinear(nn.Module):
    """Linear layer with a factorised Gaussian posterior over its weights and biases.

    Parameters are ``weight_mu`` (O, I), ``weight_rho`` (O, I), ``bias_mu`` (O,),
    ``bias_rho`` (O,); the standard deviations are ``softplus(rho)``. The prior is an isotropic
    N(0, prior_std^2) on every weight and bias.

    Args:
        in_features: input size I (the representation size, 32 in appendix 9.1.2).
        out_features: output size O (the action dimension for the NAF mu-layer).
        prior_std: standard deviation of the zero-mean Gaussian prior.
        init_sigma: initial posterior standard deviation of every weight (small, so that the
            layer starts close to a deterministic ``nn.Linear``).
        bias: whether the layer has a (Bayesian) bias. Without one, methods that return biases
            return zeros.

    The means are initialised like ``nn.Linear`` (uniform in +-1/sqrt(I)).
    """

    weight_mu: nn.Parameter
    weight_rho: nn.Parameter
    bias_mu: nn.Parameter | None
    bias_rho: nn.Parameter | None

    def __init__(
        self,
        in_features: int,
        out_features: int,
        *,
        prior_std: float = 1.0,
        init_sigma: float = 1e-3,
        bias: bool = True,
    ) -> None:
        super().__init__()
        if in_features <= 0 or out_features <= 0:
            raise ValueError("in_features and out_features must be positive")
        if prior_std <= 0.0:
            raise ValueError(f"prior_std must be positive, got {prior_std}")
        if init_sigma <= 0.0:
            raise ValueError(f"init_sigma must be positive, got {init_sigma}")
        self.in_features = in_features
        self.out_features = out_features
        self.prior_std = float(prior_std)
        self.init_sigma = float(init_sigma)
        self.weight_mu = nn.Parameter(torch.empty(out_features, in_features))
        self.weight_rho = nn.Parameter(torch.empty(out_features, in_features))
        if bias:
            self.bias_mu = nn.Parameter(torch.empty(out_features))
            self.bias_rho = nn.Parameter(torch.empty(out_features))
        else:
            self.register_parameter("bias_mu", None)
            self.register_parameter("bias_rho", None)
        self.reset_parameters()

    # ------------------------------------------------------------------ parameters
    def reset_parameters(self) -> None:
        """Means as in ``nn.Linear``; every sigma set to ``init_sigma``."""
        bound = 1.0 / math.sqrt(self.in_features)
        rho0 = inverse_softplus(self.init_sigma)
        with torch.no_grad():
            self.weight_mu.uniform_(-bound, bound)
            self.weight_rho.fill_(rho0)
            if self.bias_mu is not None and self.bias_rho is not None:
                self.bias_mu.uniform_(-bound, bound)
                self.bias_rho.fill_(rho0)

    @property
    def weight_sigma(self) -> Tensor:
        """Posterior standard deviations of the weights, shape (O, I)."""
        return F.softplus(self.weight_rho)

    @property
    def bias_sigma(self) -> Tensor | None:
        """Posterior standard deviations of the biases, shape (O,), or None without bias."""
        return None if self.bias_rho is None else F.softplus(self.bias_rho)

    # ------------------------------------------------------------------ moments / KL
    def output_mean_var(self, x_BI: Tensor) -> tuple[Tensor, Tensor]:
        """Exact mean and variance of the output ``x W^T + b`` under q, shape (..., O) each.

        With independent weights, output o of a row x is Gaussian with mean
        ``sum_i x_i mu_oi + mu_b_o`` and variance ``sum_i x_i^2 sigma_oi^2 + sigma_b_o^2``; the
        outputs of one row are independent of each other (they use disjoint weights).
        """
        mean_BO = F.linear(x_BI, self.weight_mu, self.bias_mu)
        bias_sigma = self.bias_sigma
        var_BO = F.linear(
            x_BI * x_BI, self.weight_sigma**2, None if bias_sigma is None else bias_sigma**2
        )
        return mean_BO, var_BO

    def kl(self) -> Tensor:
        """Closed-form KL(q || prior) summed over all weights and biases (a scalar)."""
        total = gaussian_kl(self.weight_mu, self.weight_sigma, self.prior_std)
        bias_sigma = self.bias_sigma
        if self.bias_mu is not None and bias_sigma is not None:
            total = total + gaussian_kl(self.bias_mu, bias_sigma, self.prior_std)
        return total

    # ------------------------------------------------------------------ sampling
    def _randn(self, shape: tuple[int, ...], generator: torch.Generator | None) -> Tensor:
        return torch.randn(
            shape,
            generator=generator,
            device=self.weight_mu.device,
            dtype=self.weight_mu.dtype,
        )

    def sample_weights(self, generator: torch.Generator | None = None) -> tuple[Tensor, Tensor]:
        """Draw one weight set from q: ``(W_OI, b_O)`` (``b_O`` is zeros without bias).

        Differentiable with respect to mu and rho (reparameterisation); wrap in
        ``torch.no_grad()`` when only acting. The generator must live on the layer's device.
        """
        eps_OI = self._randn((self.out_features, self.in_features), generator)
        w_OI = self.weight_mu + self.weight_sigma * eps_OI
        bias_sigma = self.bias_sigma
        if self.bias_mu is None or bias_sigma is None:
            return w_OI, self.weight_mu.new_zeros(self.out_features)
        eps_O = self._randn((self.out_features,), generator)
        return w_OI, self.bias_mu + bias_sigma * eps_O

    def sample_weights_batch(
        self, n: int, generator: torch.Generator | None = None
    ) -> tuple[Tensor, Tensor]:
        """Draw ``n`` independent weight sets: ``(W_NOI, b_NO)``, one per environment."""
        eps_NOI = self._randn((n, self.out_features, self.in_features), generator)
        w_NOI = self.weight_mu + self.weight_sigma * eps_NOI
        bias_sigma = self.bias_sigma
        if self.bias_mu is None or bias_sigma is None:
            return w_NOI, self.weight_mu.new_zeros(n, self.out_features)
        eps_NO = self._randn((n, self.out_features), generator)
        return w_NOI, self.bias_mu + bias_sigma * eps_NO

    @staticmethod
    def forward_with(x_BI: Tensor, w_OI: Tensor, b_O: Tensor) -> Tensor:
        """Apply one explicit weight set to every row: ``x W^T + b``, shape (..., O)."""
        return F.linear(x_BI, w_OI, b_O)

    @staticmethod
    def forward_with_batch(x_NI: Tensor, w_NOI: Tensor, b_NO: Tensor) -> Tensor:
        """Apply weight set n to input row n: ``y_n = W_n x_n + b_n``.

        ``x`` may be (N, I) -> (N, O) or (N, B, I) -> (N, B, O) (draw n applied to its B rows).
        """
        if x_NI.dim() == 2:
            return torch.einsum("noi,ni->no", w_NOI, x_NI) + b_NO
        if x_NI.dim() == 3:
            return torch.einsum("noi,nbi->nbo", w_NOI, x_NI) + b_NO.unsqueeze(1)
        raise ValueError(f"x must have shape (N, I) or (N, B, I), got {tuple(x_NI.shape)}")

    # ------------------------------------------------------------------ forward
    def forward(
        self,
        x_BI: Tensor,
        mode: ForwardMode = "mean",
        generator: torch.Generator | None = None,
    ) -> Tensor:
        """Layer output, shape (..., O).

        Args:
            x_BI: input of shape (..., I).
            mode: ``"mean"`` (posterior-mean weights, deterministic), ``"local_reparam"``
                (output drawn from its exact Gaussian marginal under q, independent noise per
                row and output), or ``"sample"`` (one weight set drawn and shared by the batch).
            generator: optional random generator for the two stochastic modes.
        """
        if mode == "mean":
            return F.linear(x_BI, self.weight_mu, self.bias_mu)
        if mode == "local_reparam":
            mean_BO, var_BO = self.output_mean_var(x_BI)
            eps_BO = torch.randn(
                mean_BO.shape, generator=generator, device=mean_BO.device, dtype=mean_BO.dtype
            )
            return mean_BO + torch.sqrt(var_BO + _VAR_EPS) * eps_BO
        if mode == "sample":
            w_OI, b_O = self.sample_weights(generator)
            return F.linear(x_BI, w_OI, b_O)
        raise ValueError(f"unknown mode {mode!r}; expected 'mean', 'local_reparam' or 'sample'")

    def extra_repr(self) -> str:
        return (
            f"in_features={self.in_features}, out_features={self.out_features}, "
            f"prior_std={self.prior_std}, init_sigma={self.init_sigma}, "
            f"bias={self.bias_mu is not None}"
        )


class ELBOTerms(NamedTuple):
    """Per-sample negative ELBO and its two parts (all scalars)."""

    loss: Tensor
    """``nll + kl_weight * kl / num_data``: minimise this."""
    nll: Tensor
    """Monte Carlo estimate of -E_q[log N(y | predict_fn(mu_out), noise_std^2)], batch mean."""
    kl: Tensor
    """KL(q || prior) summed over the layer's weights (not divided by num_data)."""


def elbo_terms(
    layer: BayesianLinear,
    x_BI: Tensor,
    predict_fn: Callable[[Tensor], Tensor],
    y_B: Tensor,
    noise_std: float,
    num_data: int,
    kl_weight: float = 1.0,
    generator: torch.Generator | None = None,
) -> ELBOTerms:
    """Negative ELBO of the paper's Eq. 10 as SPEC section 2.2 reads it, with its parts.

    Eq. 10 is ``KL(q(theta^a) || p(theta^a)) - E_{theta^a ~ q}[log p(data | theta^a)]``. SPEC 2.2
    fixes the likelihood: the data are the TD targets y_i of a minibatch, and the model is
    ``y_i ~ N(Q(s_i, a_i; mu(phi(s_i) | theta^a)), sigma_eps^2)``, i.e. Q computed by the NAF
    with the representation theta and the V and P heads frozen, at the action mu produced by
    the Bayesian layer with theta^a ~ q. In this function:

    * ``x_BI`` is the layer input (phi(s_i) in the agent, computed without gradient);
    * ``layer(x_BI, mode="local_reparam")`` draws the layer's output (the pre-squash action) from
      its exact marginal under q (local reparameterisation, Kingma et al. 2015), one independent
      draw per row; this is an unbiased, lower-variance estimator of the expected
      log-likelihood compared with drawing one weight set for the whole batch;
    * ``predict_fn(mu_out_BO)`` maps that output to the predicted quantity with shape of ``y_B``
      (in the agent: tanh-squash and scale to the action bounds, then ``naf_q`` with the frozen
      V and L at the stored action a_i); it must not hold gradients for frozen parameters the
      caller wants untouched (freeze them or exclude them from the optimiser);
    * the Gaussian negative log-likelihood uses variance ``noise_std^2`` (sigma_eps^2) and
      includes its constant, ``0.5 log(2 pi noise_std^2)``; per sample it is summed over all
      dims after the first, then averaged over the batch;
    * KL(q || prior) is divided by ``num_data`` (the number of data the posterior is fitted to,
      e.g. the replay size used for the refresh), so that ``loss`` is the negative ELBO per data
      point: ``-ELBO / num_data`` estimated from a minibatch. ``kl_weight`` rescales the KL term
      (1 gives the true ELBO; smaller values are a common "KL annealing" option).

    Returns:
        :class:`ELBOTerms` ``(loss, nll, kl)``.
    """
    if noise_std <= 0.0:
        raise ValueError(f"noise_std must be positive, got {noise_std}")
    if num_data <= 0:
        raise ValueError(f"num_data must be positive, got {num_data}")
    if y_B.dim() == 0:
        raise ValueError("y_B must have a batch dimension")
    mu_out_BO = layer(x_BI, mode="local_reparam", generator=generator)
    pred_B = predict_fn(mu_out_BO)
    if pred_B.shape != y_B.shape:
        raise ValueError(
            f"predict_fn output shape {tuple(pred_B.shape)} != target shape {tuple(y_B.shape)}"
        )
    z_B = (y_B - pred_B) / noise_std
    nll_elem = 0.5 * z_B * z_B + math.log(noise_std) + 0.5 * math.log(2.0 * math.pi)
    nll = nll_elem.reshape(nll_elem.shape[0], -1).sum(dim=1).mean()
    kl = layer.kl()
    loss = nll + kl_weight * kl / num_data
    return ELBOTerms(loss=loss, nll=nll, kl=kl)


def elbo_loss(
    layer: BayesianLinear,
    x_BI: Tensor,
    predict_fn: Callable[[Tensor], Tensor],
    y_B: Tensor,
    noise_std: float,
    num_data: int,
    kl_weight: float = 1.0,
    generator: torch.Generator | None = None,
) -> Tensor:
    """Per-sample negative ELBO (Eq. 10, SPEC 2.2); see :func:`elbo_terms` for the reading."""
    return elbo_terms(layer, x_BI, predict_fn, y_B, noise_std, num_data, kl_weight, generator).loss
