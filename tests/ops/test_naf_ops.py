"""Tests for the NAF math of Eq. 4 (farsighter.ops.naf)."""

from __future__ import annotations

import math

import pytest
import torch

from farsighter.ops.naf import (
    NAFHead,
    lower_triangular,
    naf_advantage,
    naf_q,
    naf_td_target,
    num_tril_entries,
    scale_action,
    soft_clamp,
    unscale_action,
)


@pytest.fixture(autouse=True)
def _seed() -> None:
    torch.manual_seed(0)


@pytest.mark.parametrize("action_dim", [1, 2, 3, 6])
def test_lower_triangular_layout(action_dim: int) -> None:
    m = num_tril_entries(action_dim)
    entries_BM = torch.randn(5, m)
    l_BAA = lower_triangular(entries_BM, action_dim)
    assert l_BAA.shape == (5, action_dim, action_dim)
    # zero above the diagonal
    assert torch.all(torch.triu(l_BAA, diagonal=1) == 0)
    # row-major fill order of torch.tril_indices, diagonal exponentiated
    rows, cols = torch.tril_indices(action_dim, action_dim)
    for k in range(m):
        r, c = int(rows[k]), int(cols[k])
        expected_B = torch.exp(entries_BM[:, k]) if r == c else entries_BM[:, k]
        torch.testing.assert_close(l_BAA[:, r, c], expected_B)


def test_lower_triangular_extra_leading_dims_and_bad_size() -> None:
    entries = torch.randn(2, 3, num_tril_entries(3))
    assert lower_triangular(entries, 3).shape == (2, 3, 3, 3)
    with pytest.raises(ValueError):
        lower_triangular(torch.randn(4, 5), 3)


def test_lower_triangular_clamp_keeps_values_and_grads_finite() -> None:
    entries_BM = torch.tensor([[1e4, -1e4, 1e4], [-1e4, 50.0, -1e4]], requires_grad=True)
    l_BAA = lower_triangular(entries_BM, 2)
    assert torch.isfinite(l_BAA).all()
    diag = torch.diagonal(l_BAA, dim1=-2, dim2=-1)
    assert torch.all(diag <= math.exp(6.0))  # the soft bound's margin is 1
    assert torch.all(diag >= math.exp(-6.0))
    l_BAA.sum().backward()
    assert entries_BM.grad is not None and torch.isfinite(entries_BM.grad).all()
    # unclamped: large off-diagonal entries must not produce NaN gradients either
    entries2 = torch.tensor([[0.5, 1e4, -0.3]], requires_grad=True)
    lower_triangular(entries2, 2, log_diag_bounds=None).sum().backward()
    assert entries2.grad is not None and torch.isfinite(entries2.grad).all()


@pytest.mark.parametrize("action_dim", [1, 2, 4, 7])
def test_p_is_symmetric_positive_definite(action_dim: int) -> None:
    entries_BM = 2.0 * torch.randn(256, num_tril_entries(action_dim), dtype=torch.float64)
    l_BAA = lower_triangular(entries_BM, action_dim)
    p_BAA = l_BAA @ l_BAA.transpose(-1, -2)
    torch.testing.assert_close(p_BAA, p_BAA.transpose(-1, -2))
    eig_BA = torch.linalg.eigvalsh(p_BAA)
    assert torch.all(eig_BA > 0)


def test_advantage_matches_explicit_quadratic_form() -> None:
    a_dim = 4
    l_BAA = lower_triangular(torch.randn(64, num_tril_entries(a_dim), dtype=torch.float64), a_dim)
    mu_BA = torch.randn(64, a_dim, dtype=torch.float64)
    act_BA = torch.randn(64, a_dim, dtype=torch.float64)
    p_BAA = l_BAA @ l_BAA.transpose(-1, -2)
    d_BA = act_BA - mu_BA
    expected_B = -0.5 * torch.einsum("bi,bij,bj->b", d_BA, p_BAA, d_BA)
    torch.testing.assert_close(naf_advantage(mu_BA, l_BAA, act_BA), expected_B)


def test_mu_is_the_argmax_of_q() -> None:
    a_dim, batch, n_actions = 3, 32, 500
    l_BAA = lower_triangular(torch.randn(batch, num_tril_entries(a_dim)), a_dim)
    mu_BA = torch.randn(batch, a_dim)
    v_B = torch.randn(batch)
    q_mu_B = naf_q(v_B, mu_BA, l_BAA, mu_BA)
    torch.testing.assert_close(q_mu_B, v_B)  # A(s, mu) = 0
    act_NBA = mu_BA + 2.0 * torch.randn(n_actions, batch, a_dim)
    q_NB = naf_q(v_B, mu_BA, l_BAA, act_NBA)
    assert torch.all(q_mu_B >= q_NB)
    # gradient of Q with respect to a vanishes at a = mu, and not elsewhere
    a_at_mu = mu_BA.clone().requires_grad_(True)
    (grad_mu,) = torch.autograd.grad(naf_q(v_B, mu_BA, l_BAA, a_at_mu).sum(), a_at_mu)
    assert torch.allclose(grad_mu, torch.zeros_like(grad_mu))
    a_off = (mu_BA + 0.5).requires_grad_(True)
    (grad_off,) = torch.autograd.grad(naf_q(v_B, mu_BA, l_BAA, a_off).sum(), a_off)
    assert grad_off.abs().sum() > 0


def test_td_target_hand_computation() -> None:
    gamma = 0.99
    reward_B = torch.tensor([1.0, -2.0, 0.5, 3.0])
    v_next_B = torch.tensor([10.0, 4.0, -6.0, 100.0])
    terminated_B = torch.tensor([0.0, 0.0, 1.0, 0.0])
    n_steps_B = torch.tensor([1.0, 3.0, 2.0, 5.0])  # k-step windows: gamma^n
    discount_B = gamma**n_steps_B * (1.0 - terminated_B)
    y_B = naf_td_target(reward_B, discount_B, v_next_B)
    expected = torch.tensor([1.0 + 0.99 * 10.0, -2.0 + 0.99**3 * 4.0, 0.5, 3.0 + 0.99**5 * 100.0])
    torch.testing.assert_close(y_B, expected)
    # discount 0 (terminal) -> y = r
    torch.testing.assert_close(naf_td_target(reward_B, torch.zeros(4), v_next_B), reward_B)


def test_naf_head_shapes_and_gradients() -> None:
    head = NAFHead(32, 3)
    phi_BD = torch.randn(8, 32)
    v_B, l_BAA = head(phi_BD)
    assert v_B.shape == (8,) and l_BAA.shape == (8, 3, 3)
    assert torch.all(torch.diagonal(l_BAA, dim1=-2, dim2=-1) > 0)
    mu_BA, act_BA = torch.randn(8, 3), torch.randn(8, 3)
    naf_q(v_B, mu_BA, l_BAA, act_BA).pow(2).mean().backward()
    for p in head.parameters():
        assert p.grad is not None and torch.isfinite(p.grad).all()


def test_scale_unscale_round_trip() -> None:
    low_A = torch.tensor([-2.0, 0.0, -0.4])
    high_A = torch.tensor([2.0, 1.0, 1.0])
    u_BA = torch.rand(16, 3) * 2 - 1
    a_BA = scale_action(u_BA, low_A, high_A)
    assert torch.all(a_BA >= low_A) and torch.all(a_BA <= high_A)
    torch.testing.assert_close(unscale_action(a_BA, low_A, high_A), u_BA)
    ends = torch.tensor([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])
    torch.testing.assert_close(scale_action(ends, low_A, high_A), torch.stack([low_A, high_A]))
    # scalar bounds
    torch.testing.assert_close(scale_action(torch.tensor([0.0]), -3.0, 5.0), torch.tensor([1.0]))


def test_soft_clamp_is_identity_inside_and_keeps_a_gradient_outside() -> None:
    x = torch.tensor([-30.0, -8.0, -5.5, -5.0, 0.0, 2.0, 5.0, 9.0], requires_grad=True)
    y = soft_clamp(x, -5.0, 5.0)
    torch.testing.assert_close(y[3:7], x[3:7].detach(), atol=0, rtol=0)  # identity inside
    assert torch.all(y >= -6.0) and torch.all(y <= 6.0)  # bounded by the margin (1)
    assert -5.5 < y[2] < -5.0 and y[1] < y[2] and y[0] < y[1]  # still monotone outside
    y.sum().backward()
    assert x.grad is not None
    # unlike a hard clamp, an entry past a bound still gets a gradient back inside
    assert torch.all(x.grad[1:] > 0)
    assert x.grad[1] > 5e-3  # three units below the floor: sech^2(3) ~ 0.0099
    torch.testing.assert_close(x.grad[3:7], torch.ones(4))
