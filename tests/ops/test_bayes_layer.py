"""Tests for farsighter.ops.bayes_layer: BayesianLinear moments, KL, sampling and the ELBO."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from torch.distributions import Normal

from farsighter.ops.bayes_layer import (
    BayesianLinear,
    elbo_loss,
    elbo_terms,
    inverse_softplus,
)
from farsighter.ops.naf import NAFHead, naf_q


@pytest.fixture(autouse=True)
def _seed_and_threads() -> None:
    torch.manual_seed(0)
    torch.set_num_threads(1)


def _randomise(layer: BayesianLinear, sigma_low: float, sigma_high: float, seed: int) -> None:
    """Give every weight a random mean and a random sigma in [sigma_low, sigma_high]."""
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for mu, rho in ((layer.weight_mu, layer.weight_rho), (layer.bias_mu, layer.bias_rho)):
            assert mu is not None and rho is not None
            mu.copy_(torch.randn(mu.shape, generator=g))
            sigma = sigma_low + (sigma_high - sigma_low) * torch.rand(rho.shape, generator=g)
            rho.copy_(torch.log(torch.expm1(sigma)))


def test_inverse_softplus_and_init_sigma() -> None:
    for s in (1e-4, 1e-3, 0.5, 1.0, 30.0):
        rho = inverse_softplus(s)
        assert math.isclose(float(torch.nn.functional.softplus(torch.tensor(rho))), s, rel_tol=1e-5)
    layer = BayesianLinear(4, 2, init_sigma=1e-3)
    torch.testing.assert_close(layer.weight_sigma, torch.full((2, 4), 1e-3))
    assert layer.bias_sigma is not None
    torch.testing.assert_close(layer.bias_sigma, torch.full((2,), 1e-3))


def test_kl_matches_numpy_closed_form() -> None:
    layer = BayesianLinear(5, 3, prior_std=0.7)
    _randomise(layer, 0.05, 2.0, seed=1)
    prior = 0.7
    total = 0.0
    for mu_t, rho_t in ((layer.weight_mu, layer.weight_rho), (layer.bias_mu, layer.bias_rho)):
        assert mu_t is not None and rho_t is not None
        mu = mu_t.detach().double().numpy()
        sigma = np.log1p(np.exp(rho_t.detach().double().numpy()))
        # KL(N(mu, s^2) || N(0, p^2)) = log(p/s) + (s^2 + mu^2) / (2 p^2) - 1/2
        total += float(np.sum(np.log(prior / sigma) + (sigma**2 + mu**2) / (2 * prior**2) - 0.5))
    assert math.isclose(layer.kl().item(), total, rel_tol=1e-5)


def test_kl_is_zero_when_q_equals_prior() -> None:
    layer = BayesianLinear(6, 4, prior_std=0.3, init_sigma=0.3)
    with torch.no_grad():
        layer.weight_mu.zero_()
        assert layer.bias_mu is not None
        layer.bias_mu.zero_()
    assert abs(layer.kl().item()) < 1e-5
    # and strictly positive otherwise
    assert BayesianLinear(6, 4, prior_std=0.3).kl().item() > 1.0


def test_kl_matches_monte_carlo() -> None:
    layer = BayesianLinear(3, 2, prior_std=1.0)
    _randomise(layer, 0.3, 0.9, seed=2)
    n = 20000
    g = torch.Generator().manual_seed(3)
    with torch.no_grad():
        w_NOI, b_NO = layer.sample_weights_batch(n, g)
        assert layer.bias_mu is not None and layer.bias_sigma is not None
        q_w = Normal(layer.weight_mu, layer.weight_sigma)
        q_b = Normal(layer.bias_mu, layer.bias_sigma)
        p = Normal(0.0, 1.0)
        log_ratio_N = (q_w.log_prob(w_NOI) - p.log_prob(w_NOI)).sum(dim=(1, 2)) + (
            q_b.log_prob(b_NO) - p.log_prob(b_NO)
        ).sum(dim=1)
        mc, se = float(log_ratio_N.mean()), float(log_ratio_N.std()) / math.sqrt(n)
        exact = layer.kl().item()
    assert abs(mc - exact) < 4 * se + 1e-4, (mc, exact, se)


def _assert_moments(samples_NBO: torch.Tensor, mean_BO: torch.Tensor, var_BO: torch.Tensor) -> None:
    n = samples_NBO.shape[0]
    mc_mean = samples_NBO.mean(0)
    mc_var = samples_NBO.var(0)
    # mean within 4 standard errors; variance within 6% (its relative s.e. is sqrt(2/n) ~ 1.4%)
    assert torch.all((mc_mean - mean_BO).abs() < 4 * torch.sqrt(var_BO / n) + 1e-6)
    assert torch.all((mc_var / var_BO - 1).abs() < 0.06), (mc_var, var_BO)


def test_output_mean_var_matches_sample_mode_monte_carlo() -> None:
    layer = BayesianLinear(4, 3)
    _randomise(layer, 0.1, 0.6, seed=4)
    x_BI = torch.randn(5, 4)
    g = torch.Generator().manual_seed(5)
    with torch.no_grad():
        samples_NBO = torch.stack([layer(x_BI, mode="sample", generator=g) for _ in range(10000)])
        mean_BO, var_BO = layer.output_mean_var(x_BI)
    _assert_moments(samples_NBO, mean_BO, var_BO)
    # the closed form itself: mean x mu^T + b_mu, variance x^2 sigma^2^T + sigma_b^2
    assert layer.bias_mu is not None and layer.bias_sigma is not None
    torch.testing.assert_close(mean_BO, x_BI @ layer.weight_mu.T + layer.bias_mu)
    torch.testing.assert_close(var_BO, x_BI**2 @ (layer.weight_sigma**2).T + layer.bias_sigma**2)


def test_local_reparam_has_the_output_moments() -> None:
    layer = BayesianLinear(4, 3)
    _randomise(layer, 0.1, 0.6, seed=6)
    x_BI = torch.randn(5, 4)
    n = 10000
    g = torch.Generator().manual_seed(7)
    with torch.no_grad():
        x_NBI = x_BI.expand(n, 5, 4)
        samples_NBO = layer(x_NBI, mode="local_reparam", generator=g)
        mean_BO, var_BO = layer.output_mean_var(x_BI)
    _assert_moments(samples_NBO, mean_BO, var_BO)
    # independent noise per row: identical input rows get different outputs
    with torch.no_grad():
        out = layer(x_BI[:1].expand(2, 4), mode="local_reparam", generator=g)
    assert not torch.allclose(out[0], out[1])


def test_modes_determinism_and_generator_reproducibility() -> None:
    layer = BayesianLinear(4, 2, init_sigma=0.2)
    x_BI = torch.randn(6, 4)
    with torch.no_grad():
        m1, m2 = layer(x_BI), layer(x_BI, mode="mean")
        torch.testing.assert_close(m1, m2, rtol=0, atol=0)
        torch.testing.assert_close(
            m1, torch.nn.functional.linear(x_BI, layer.weight_mu, layer.bias_mu)
        )
        s1, s2 = layer(x_BI, mode="sample"), layer(x_BI, mode="sample")
        assert not torch.allclose(s1, s2)
        # sample mode shares one weight set across the batch: equals forward_with on that draw
        out = layer(x_BI, mode="sample", generator=torch.Generator().manual_seed(11))
        w_OI, b_O = layer.sample_weights(torch.Generator().manual_seed(11))
        torch.testing.assert_close(out, layer.forward_with(x_BI, w_OI, b_O))
        # same seed -> same weights, different seeds -> different weights
        w_a, b_a = layer.sample_weights(torch.Generator().manual_seed(1))
        w_b, b_b = layer.sample_weights(torch.Generator().manual_seed(1))
        w_c, _ = layer.sample_weights(torch.Generator().manual_seed(2))
        torch.testing.assert_close(w_a, w_b, rtol=0, atol=0)
        torch.testing.assert_close(b_a, b_b, rtol=0, atol=0)
        assert not torch.allclose(w_a, w_c)
        wb1, bb1 = layer.sample_weights_batch(3, torch.Generator().manual_seed(4))
        wb2, bb2 = layer.sample_weights_batch(3, torch.Generator().manual_seed(4))
        torch.testing.assert_close(wb1, wb2, rtol=0, atol=0)
        torch.testing.assert_close(bb1, bb2, rtol=0, atol=0)
    with pytest.raises(ValueError):
        layer(x_BI, mode="bogus")  # type: ignore[arg-type]


def test_batch_draws_one_weight_set_per_environment() -> None:
    layer = BayesianLinear(4, 3, init_sigma=0.3)
    n = 5
    with torch.no_grad():
        w_NOI, b_NO = layer.sample_weights_batch(n, torch.Generator().manual_seed(0))
        assert w_NOI.shape == (n, 3, 4) and b_NO.shape == (n, 3)
        assert not torch.allclose(w_NOI[0], w_NOI[1])
        x_NI = torch.randn(n, 4)
        y_NO = layer.forward_with_batch(x_NI, w_NOI, b_NO)
        expected = torch.stack([layer.forward_with(x_NI[i], w_NOI[i], b_NO[i]) for i in range(n)])
        torch.testing.assert_close(y_NO, expected)
        x_NBI = torch.randn(n, 7, 4)
        y_NBO = layer.forward_with_batch(x_NBI, w_NOI, b_NO)
        expected3 = torch.stack([layer.forward_with(x_NBI[i], w_NOI[i], b_NO[i]) for i in range(n)])
        torch.testing.assert_close(y_NBO, expected3)


def test_no_bias_layer() -> None:
    layer = BayesianLinear(3, 2, bias=False, init_sigma=0.1)
    x_BI = torch.randn(4, 3)
    assert layer.bias_mu is None and layer.bias_sigma is None
    w_OI, b_O = layer.sample_weights()
    torch.testing.assert_close(b_O, torch.zeros(2))
    w_NOI, b_NO = layer.sample_weights_batch(3)
    assert b_NO.shape == (3, 2)
    mean_BO, var_BO = layer.output_mean_var(x_BI)
    torch.testing.assert_close(var_BO, x_BI**2 @ (layer.weight_sigma**2).T)
    # a zero input row has zero variance: local_reparam gradients stay finite
    x0 = torch.zeros(2, 3)
    layer(x0, mode="local_reparam").sum().backward()
    assert layer.weight_rho.grad is not None and torch.isfinite(layer.weight_rho.grad).all()
    assert layer.kl() > 0


def test_gradient_routing_by_mode() -> None:
    layer = BayesianLinear(3, 2, init_sigma=0.1)
    x_BI = torch.randn(4, 3)
    layer(x_BI, mode="mean").sum().backward()
    assert layer.weight_rho.grad is None and layer.weight_mu.grad is not None
    layer.zero_grad()
    layer(x_BI, mode="local_reparam").pow(2).sum().backward()
    assert layer.weight_rho.grad is not None and layer.weight_rho.grad.abs().sum() > 0


def test_elbo_loss_matches_hand_computation() -> None:
    layer = BayesianLinear(3, 1, prior_std=0.5, init_sigma=0.2)
    x_BI, y_B = torch.randn(8, 3), torch.randn(8)
    noise_std, num_data = 0.7, 100
    terms = elbo_terms(
        layer,
        x_BI,
        lambda m: m.squeeze(-1),
        y_B,
        noise_std,
        num_data,
        kl_weight=0.5,
        generator=torch.Generator().manual_seed(9),
    )
    with torch.no_grad():
        g = torch.Generator().manual_seed(9)
        mean_BO, var_BO = layer.output_mean_var(x_BI)
        pred_B = (mean_BO + var_BO.sqrt() * torch.randn(mean_BO.shape, generator=g)).squeeze(-1)
        nll = -Normal(pred_B, noise_std).log_prob(y_B).mean()
        expected = nll + 0.5 * layer.kl() / num_data
    torch.testing.assert_close(terms.nll.detach(), nll)
    torch.testing.assert_close(terms.loss.detach(), expected)
    loss = elbo_loss(
        layer,
        x_BI,
        lambda m: m.squeeze(-1),
        y_B,
        noise_std,
        num_data,
        kl_weight=0.5,
        generator=torch.Generator().manual_seed(9),
    )
    torch.testing.assert_close(loss, terms.loss)
    with pytest.raises(ValueError):
        elbo_loss(layer, x_BI, lambda m: m, y_B, noise_std, num_data)  # (B, 1) vs (B,)


def test_elbo_through_frozen_naf_q_only_trains_the_layer() -> None:
    """The agent's use: predict_fn = Q(s, a) with frozen V and P heads at the sampled mu."""
    a_dim, d = 2, 8
    head = NAFHead(d, a_dim).requires_grad_(False)
    layer = BayesianLinear(d, a_dim, init_sigma=0.05)
    phi_BD, act_BA, y_B = torch.randn(16, d), torch.rand(16, a_dim) * 2 - 1, torch.randn(16)
    v_B, l_BAA = head(phi_BD)

    def predict_q(mu_out_BA: torch.Tensor) -> torch.Tensor:
        return naf_q(v_B, torch.tanh(mu_out_BA), l_BAA, act_BA)

    elbo_loss(layer, phi_BD, predict_q, y_B, noise_std=1.0, num_data=1000).backward()
    assert all(p.grad is None for p in head.parameters())
    assert layer.weight_mu.grad is not None and layer.weight_rho.grad is not None
    assert torch.isfinite(layer.weight_rho.grad).all()


def _fit_regression(n: int, steps: int, seed: int) -> tuple[BayesianLinear, list[float], dict]:
    """Fit y = x w + b + noise with the per-sample negative ELBO; full batch, Adam, linear decay."""
    g = torch.Generator().manual_seed(seed)
    w_true_1I, b_true, noise_std = torch.tensor([[0.8, -1.5, 0.3]]), 0.5, 0.1
    x_BI = torch.randn(n, 3, generator=g)
    y_B1 = x_BI @ w_true_1I.T + b_true + noise_std * torch.randn(n, 1, generator=g)
    torch.manual_seed(seed)
    layer = BayesianLinear(3, 1, prior_std=1.0, init_sigma=0.1)
    assert layer.bias_mu is not None and layer.bias_rho is not None
    opt = torch.optim.Adam(
        [
            {"params": [layer.weight_mu, layer.bias_mu], "lr": 0.03},
            {"params": [layer.weight_rho, layer.bias_rho], "lr": 0.1},
        ]
    )
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda t: 1.0 - t / steps)
    losses = []
    for _ in range(steps):
        loss = elbo_loss(layer, x_BI, lambda m: m, y_B1, noise_std, num_data=n, generator=g)
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        losses.append(loss.item())
    # exact Gaussian posterior of Bayesian linear regression over (w, b), prior N(0, 1)
    xa_BI = torch.cat([x_BI, torch.ones(n, 1)], dim=1).double()
    prec = xa_BI.T @ xa_BI / noise_std**2 + torch.eye(4, dtype=torch.float64)
    post_mean = torch.linalg.solve(prec, xa_BI.T @ y_B1.double() / noise_std**2).squeeze(-1)
    # the mean-field (factorised) optimum has sigma_i = 1 / sqrt(prec_ii)
    mf_sigma = 1.0 / prec.diagonal().sqrt()
    info = {
        "w_true": torch.cat([w_true_1I[0], torch.tensor([b_true])]),
        "post_mean": post_mean,
        "mf_sigma": mf_sigma,
    }
    return layer, losses, info


def test_elbo_regression_recovers_weights_and_sigma_shrinks_with_data() -> None:
    fits = {n: _fit_regression(n, steps=steps, seed=0) for n, steps in ((20, 800), (1000, 2000))}
    sigmas = {}
    for n, (layer, losses, info) in fits.items():
        assert layer.bias_mu is not None and layer.bias_sigma is not None
        mean = torch.cat([layer.weight_mu[0], layer.bias_mu]).detach()
        sigma = torch.cat([layer.weight_sigma[0], layer.bias_sigma]).detach()
        sigmas[n] = sigma
        # the negative ELBO decreases
        assert np.mean(losses[-50:]) < np.mean(losses[:50]) - 10.0
        # posterior mean: matches the exact posterior mean, and approaches the true weights
        assert torch.allclose(mean.double(), info["post_mean"], atol=0.02), (mean, info)
        tol = 0.15 if n == 20 else 0.02  # ~4 posterior std at n = 20
        assert torch.allclose(mean, info["w_true"], atol=tol), (mean, info["w_true"])
        # sigma: close to the mean-field optimum of the exact ELBO
        ratio = sigma.double() / info["mf_sigma"]
        assert torch.all((ratio > 0.8) & (ratio < 1.25)), (n, sigma, info["mf_sigma"])
    # more data -> a narrower posterior (~ 1/sqrt(n): about 7x between n = 20 and n = 1000)
    assert torch.all(sigmas[1000] < sigmas[20] / 3)
