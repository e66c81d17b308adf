"""Tests of the BLR head (Eq. 9 posterior, Eq. 7 Thompson sampling) against independent numpy."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from farsighter.errors import Diverged
from farsighter.ops.blr import (
    BLRHead,
    ThompsonDraws,
    blr_posterior,
    cholesky_jitter,
    greedy_predictive_variance,
)

PRIOR_STD = 0.7
NOISE_STD = 1.3


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def _make_data(
    counts: list[int], dim: int, seed: int
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Random features / targets; action a gets counts[a] samples (0 allowed), shuffled order."""
    rng = np.random.default_rng(seed)
    action_N = np.concatenate([np.full(c, a) for a, c in enumerate(counts)])
    rng.shuffle(action_N)
    n = len(action_N)
    phi_ND = rng.normal(size=(n, dim)) + 0.3
    w_true_AD = rng.normal(size=(len(counts), dim))
    y_N = (phi_ND * w_true_AD[action_N]).sum(1) + NOISE_STD * rng.normal(size=n)
    return (
        torch.as_tensor(phi_ND, dtype=torch.float32),
        torch.as_tensor(action_N, dtype=torch.long),
        torch.as_tensor(y_N, dtype=torch.float32),
    )


def _numpy_posterior(
    phi_ND: np.ndarray,
    action_N: np.ndarray,
    y_N: np.ndarray,
    num_actions: int,
    prior_std: float,
    noise_std: float,
    weight_N: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form ridge / BLR posterior per action (Eq. 9), written independently in numpy."""
    dim = phi_ND.shape[1]
    if weight_N is None:
        weight_N = np.ones(len(y_N))
    means, covs = [], []
    for a in range(num_actions):
        m = action_N == a
        x = phi_ND[m].astype(np.float64)
        w = weight_N[m]
        y = y_N[m].astype(np.float64)
        prec = (x.T * w) @ x / noise_std**2 + np.eye(dim) / prior_std**2
        means.append(np.linalg.solve(prec, (x.T * w) @ y / noise_std**2))
        covs.append(np.linalg.inv(prec))
    return np.stack(means), np.stack(covs)


def _head(num_actions: int, dim: int, **kw: float) -> BLRHead:
    kw.setdefault("prior_std", PRIOR_STD)
    kw.setdefault("noise_std", NOISE_STD)
    return BLRHead(num_actions=num_actions, dim=dim, **kw)  # type: ignore[arg-type]


def test_batch_posterior_matches_numpy_closed_form() -> None:
    counts = [50, 7, 0, 300]  # different counts and an action with no data
    dim = 6
    phi, act, y = _make_data(counts, dim, seed=0)
    head = _head(len(counts), dim)
    head.fit(phi, act, y)
    mean_np, cov_np = _numpy_posterior(
        phi.numpy(), act.numpy(), y.numpy(), len(counts), PRIOR_STD, NOISE_STD
    )
    mean_t, cov_t = head.posterior()
    for a in range(len(counts)):
        if counts[a] == 0:
            # no data: posterior = prior, mean 0, covariance prior_std^2 I
            np.testing.assert_array_equal(mean_t[a].numpy(), np.zeros(dim))
            np.testing.assert_allclose(cov_t[a].numpy(), PRIOR_STD**2 * np.eye(dim), rtol=1e-12)
            continue
        assert _rel(mean_t[a].numpy(), mean_np[a]) < 1e-6
        assert _rel(cov_t[a].numpy(), cov_np[a]) < 1e-6
    # float32 views used for acting, and the pure function, agree too
    np.testing.assert_allclose(head.mean_AD.numpy(), mean_np, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(head.cov_ADD.numpy(), cov_np, rtol=1e-9, atol=1e-12)
    m2, c2 = blr_posterior(head.phiphiT_ADD, head.phiy_AD, PRIOR_STD, NOISE_STD)
    assert _rel(m2.numpy(), mean_np) < 1e-6 and _rel(c2.numpy(), cov_np) < 1e-6
    assert head.jitter_events == 0
    np.testing.assert_array_equal(head.count_A.numpy(), counts)


def test_features_past_fit_dim_fit_no_target_and_share_no_covariance() -> None:
    """fit_dim f: the posterior is two independent ones in closed form, the first f features
    regressed on the targets, the rest on targets 0 (mean 0, own covariance)."""
    counts, dim, f = [60, 9, 0], 7, 4
    phi, act, y = _make_data(counts, dim, seed=5)
    head = _head(len(counts), dim, fit_dim=f)
    for lo in range(0, len(y), 25):
        head.accumulate(phi[lo : lo + 25], act[lo : lo + 25], y[lo : lo + 25], chunk_size=8)
    head.refresh()
    x, a_np, y_np = phi.numpy(), act.numpy(), y.numpy()
    mean_fit, cov_fit = _numpy_posterior(x[:, :f], a_np, y_np, 3, PRIOR_STD, NOISE_STD)
    zeros = np.zeros_like(y_np)
    mean_rest, cov_rest = _numpy_posterior(x[:, f:], a_np, zeros, 3, PRIOR_STD, NOISE_STD)
    mean_t, cov_t = (t.numpy() for t in head.posterior())
    np.testing.assert_allclose(mean_t[:, :f], mean_fit, rtol=1e-8, atol=1e-10)
    np.testing.assert_array_equal(mean_t[:, f:], 0.0)
    np.testing.assert_allclose(cov_t[:, :f, :f], cov_fit, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(cov_t[:, f:, f:], cov_rest, rtol=1e-8, atol=1e-12)
    np.testing.assert_array_equal(cov_t[:, :f, f:], 0.0)
    np.testing.assert_array_equal(head.count_A.numpy(), counts)
    # the whole width fitted differs (the check above can fail)
    whole = _head(len(counts), dim)
    whole.fit(phi, act, y)
    assert np.abs(whole.posterior()[0].numpy()[:2, f:]).min() > 0
    with pytest.raises(ValueError, match="fit_dim"):
        _head(2, 3, fit_dim=4)


def test_default_hyperparameters_are_spec_values() -> None:
    head = BLRHead(num_actions=2, dim=3)
    assert head.prior_std == 0.1 and head.noise_std == 1.0
    assert head.cov_scale == 1.0 and head.forgetting == 1.0
    assert head.phiphiT_ADD.dtype == torch.float64


def test_prior_before_refresh_and_set_mean() -> None:
    head = _head(3, 4, cov_scale=2.0)
    eye = np.eye(4)
    np.testing.assert_allclose(head.cov_ADD.numpy(), np.stack([2.0 * PRIOR_STD**2 * eye] * 3))
    assert torch.all(head.mean_AD == 0)
    mean_AD = torch.randn(3, 4, generator=torch.Generator().manual_seed(1))
    head.set_mean(mean_AD)
    torch.testing.assert_close(head.mean_AD, mean_AD)
    phi = torch.randn(5, 4, generator=torch.Generator().manual_seed(2))
    torch.testing.assert_close(head.q_mean(phi), phi @ mean_AD.T)
    # the covariance is still the prior
    np.testing.assert_allclose(head.cov_ADD.numpy(), np.stack([2.0 * PRIOR_STD**2 * eye] * 3))
    with pytest.raises(ValueError, match="shape"):
        head.set_mean(torch.zeros(4, 3))


def test_incremental_equals_batch() -> None:
    counts = [120, 40, 0, 77]
    dim = 5
    phi, act, y = _make_data(counts, dim, seed=3)
    batch = _head(len(counts), dim)
    batch.fit(phi, act, y)
    inc = _head(len(counts), dim)
    for lo in range(0, len(y), 45):  # uneven chunks, small chunk_size to exercise inner chunking
        inc.accumulate(phi[lo : lo + 45], act[lo : lo + 45], y[lo : lo + 45], chunk_size=8)
    inc.refresh()
    mb, cb = batch.posterior()
    mi, ci = inc.posterior()
    assert _rel(mi.numpy(), mb.numpy()) < 1e-10
    assert _rel(ci.numpy(), cb.numpy()) < 1e-10
    # refit after a reset gives the same result again (statistics really reset)
    inc.fit(phi, act, y)
    assert _rel(inc.posterior()[0].numpy(), mb.numpy()) < 1e-10


def test_forgetting() -> None:
    counts = [90, 60, 30]
    dim = 4
    phi, act, y = _make_data(counts, dim, seed=4)
    chunks = [(0, 70), (70, 110), (110, 180)]
    lam = 0.6
    head = _head(len(counts), dim, forgetting=lam)
    weight = np.empty(len(y))
    for j, (lo, hi) in enumerate(chunks):
        head.accumulate(phi[lo:hi], act[lo:hi], y[lo:hi])
        weight[lo:hi] = lam ** (len(chunks) - 1 - j)  # chunk j is decayed by later accumulates
    head.refresh()
    mean_np, cov_np = _numpy_posterior(
        phi.numpy(), act.numpy(), y.numpy(), len(counts), PRIOR_STD, NOISE_STD, weight
    )
    mean_t, cov_t = head.posterior()
    assert _rel(mean_t.numpy(), mean_np) < 1e-6
    assert _rel(cov_t.numpy(), cov_np) < 1e-6
    # and forgetting = 1 over the same chunks equals batch mode
    no_forget = _head(len(counts), dim, forgetting=1.0)
    for lo, hi in chunks:
        no_forget.accumulate(phi[lo:hi], act[lo:hi], y[lo:hi])
    no_forget.refresh()
    mean_np1, _ = _numpy_posterior(
        phi.numpy(), act.numpy(), y.numpy(), len(counts), PRIOR_STD, NOISE_STD
    )
    assert _rel(no_forget.posterior()[0].numpy(), mean_np1) < 1e-6


def _fitted_head(cov_scale: float = 1.0) -> BLRHead:
    counts = [15, 40, 5]
    dim = 4
    phi, act, y = _make_data(counts, dim, seed=5)
    head = _head(len(counts), dim, cov_scale=cov_scale)
    head.fit(phi, act, y)
    return head


def test_sample_weights_moments_and_independence() -> None:
    head = _fitted_head(cov_scale=1.7)
    n = 20_000
    w_NAD = head.sample_weights(n, generator=torch.Generator().manual_seed(6)).double().numpy()
    assert w_NAD.shape == (n, 3, 4)
    cov_ADD = head.cov_ADD.numpy()
    mean_AD = head.mean_AD.double().numpy()
    for a in range(3):
        emp_cov = np.cov(w_NAD[:, a, :], rowvar=False)
        assert _rel(emp_cov, cov_ADD[a]) < 0.05
        # mean within 5 standard errors per coordinate
        se = np.sqrt(np.diag(cov_ADD[a]) / n)
        assert np.all(np.abs(w_NAD[:, a, :].mean(0) - mean_AD[a]) < 5 * se)
    # different actions: cross-correlation near 0 (|r| ~ 1/sqrt(n) = 0.007)
    flat = w_NAD.reshape(n, -1)
    corr = np.corrcoef(flat, rowvar=False)
    for a in range(3):
        for b in range(3):
            if a != b:
                block = corr[a * 4 : (a + 1) * 4, b * 4 : (b + 1) * 4]
                assert np.abs(block).max() < 0.05


def test_one_draw_is_mean_plus_square_root_times_normals() -> None:
    """A single draw (an environment's held draw replaced; computed as (z^T U^T)^T on CPU) and
    two, against mean + U z with the same normals, U the upper-triangular L^-T (a product
    transposed the wrong way round would give mean + U^T z, a different distribution)."""
    head = _fitted_head(cov_scale=1.7)
    u_ADD = head._sqrt_cov32_ADD.double()
    assert not torch.allclose(u_ADD, u_ADD.transpose(1, 2))  # so U^T z would differ
    for n in (1, 2, 3):
        w_NAD = head.sample_weights(n, generator=torch.Generator().manual_seed(9)).double()
        z_ADN = torch.randn((3, 4, n), generator=torch.Generator().manual_seed(9)).double()
        want_NAD = head.mean_AD.double() + (1.7**0.5 * u_ADD @ z_ADN).permute(2, 0, 1)
        torch.testing.assert_close(w_NAD, want_NAD, rtol=1e-5, atol=1e-6)


def test_refresh_of_non_finite_targets_says_the_training_diverged() -> None:
    """NaN or inf regression targets (a run whose values blew up) stop the refresh with
    :class:`Diverged`, which the CLI prints as one line, instead of a factorisation error."""
    for bad in (float("nan"), float("inf")):
        head = _head(2, 3)
        phi, act, y = _make_data([4, 4], 3, seed=1)
        y[2] = bad
        head.accumulate(phi, act, y)
        with pytest.raises(Diverged, match="regression targets hold NaN or inf"):
            head.refresh()


def test_thompson_draws_are_the_posterior_each_used_once_in_order() -> None:
    head = _fitted_head(cov_scale=1.7)
    draws = ThompsonDraws(head, block=64)
    gen = torch.Generator().manual_seed(6)
    taken = torch.cat([draws.take(3, gen) for _ in range(21 * 333)])  # 21 takes per block of 63
    assert taken.shape == (3 * 21 * 333, 3, 4)
    # the same numbers as blocks of sample_weights from the same generator state, in order
    ref = torch.Generator().manual_seed(6)
    blocks = torch.cat([head.sample_weights(63, ref) for _ in range(333)])
    assert torch.equal(taken, blocks)
    assert len({tuple(row) for row in taken[:, 0, :].tolist()}) == len(taken)  # none reused
    w_NAD, cov_ADD = taken.double().numpy(), head.cov_ADD.numpy()
    for a in range(3):
        assert _rel(np.cov(w_NAD[:, a, :], rowvar=False), cov_ADD[a]) < 0.05
        se = np.sqrt(np.diag(cov_ADD[a]) / len(w_NAD))
        assert np.all(np.abs(w_NAD[:, a, :].mean(0) - head.mean_AD.double().numpy()[a]) < 5 * se)


def test_thompson_draws_follow_a_posterior_change_mid_block() -> None:
    head = _fitted_head()
    draws = ThompsonDraws(head, block=256)
    gen = torch.Generator().manual_seed(0)
    before = draws.take(1, gen)
    assert before.abs().max() < 50
    head.set_mean(torch.full((3, 4), 100.0))  # a new posterior: the rest of the block is stale
    after = draws.take(1, gen)
    assert (after - 100.0).abs().max() < 50
    phi, act, y = _make_data([15, 40, 5], 4, seed=9)
    head.fit(phi, act, y)  # a refresh
    assert draws.take(1, gen).abs().max() < 50
    with pytest.raises(ValueError, match="n must be >= 1"):
        draws.take(0, gen)
    with pytest.raises(ValueError, match="block must be >= 1"):
        ThompsonDraws(head, block=0)


def test_thompson_draws_resume_from_their_state() -> None:
    head = _fitted_head()
    draws = ThompsonDraws(head, block=10)
    gen = torch.Generator().manual_seed(3)
    draws.take(4, gen)
    saved, gen_state = draws.state_dict(), gen.get_state()
    head_state = head.state_dict()
    rest = [draws.take(4, gen) for _ in range(5)]

    other_head = _head(3, 4)
    other_head.load_state_dict(head_state)
    other = ThompsonDraws(other_head, block=10)
    other.load_state_dict(saved)
    gen.set_state(gen_state)
    assert all(torch.equal(a, other.take(4, gen)) for a in rest)


def test_q_sample_matches_predictive_variance_and_rows_are_independent() -> None:
    head = _fitted_head(cov_scale=0.8)
    n = 20_000
    phi_1D = torch.randn(1, 4, generator=torch.Generator().manual_seed(7))
    # many rows with the same phi: each row must get its own z
    q_NA = head.q_sample(phi_1D.expand(n, 4), generator=torch.Generator().manual_seed(8))
    q = q_NA.double().numpy()
    var_A = head.predictive_var(phi_1D)[0].double().numpy()
    q_mean_A = head.q_mean(phi_1D)[0].double().numpy()
    # exact check of predictive_var = cov_scale phi^T Cov_a phi
    cov_ADD = head.cov_ADD.numpy()
    p = phi_1D[0].double().numpy()
    np.testing.assert_allclose(var_A, np.einsum("d,ade,e->a", p, cov_ADD, p), rtol=1e-5)
    np.testing.assert_allclose(q.var(0, ddof=1), var_A, rtol=0.05)
    assert np.all(np.abs(q.mean(0) - q_mean_A) < 5 * np.sqrt(var_A / n))
    # across actions (same row) and across rows (same action): no correlation
    corr_actions = np.corrcoef(q, rowvar=False)
    assert np.abs(corr_actions - np.eye(3)).max() < 0.05
    corr_rows = np.corrcoef(q[: n // 2, 0], q[n // 2 :, 0])[0, 1]
    assert abs(corr_rows) < 0.05


def test_q_sample_batched_shapes_and_blocks() -> None:
    # B=8 environments, A=18, d=512 (the Atari case) and a batch big enough to need row blocks
    head = BLRHead(num_actions=18, dim=512)
    phi = torch.randn(8, 512, generator=torch.Generator().manual_seed(9))
    assert head.q_sample(phi, generator=torch.Generator().manual_seed(0)).shape == (8, 18)
    small = BLRHead(num_actions=3, dim=4)
    big_phi = torch.randn(400_000, 4, generator=torch.Generator().manual_seed(10))
    var = small.predictive_var(big_phi[:1000])
    np.testing.assert_allclose(
        var.numpy(), (0.01 * big_phi[:1000].square().sum(1, keepdim=True)).expand(-1, 3), rtol=1e-5
    )
    q = small.q_sample(big_phi, generator=torch.Generator().manual_seed(11))
    assert q.shape == (400_000, 3) and torch.isfinite(q).all()


def test_predictive_variance_shrinks_with_data() -> None:
    counts = [400, 400]
    dim = 5
    phi, act, y = _make_data(counts, dim, seed=12)
    probe = torch.randn(50, dim, generator=torch.Generator().manual_seed(13))
    head = _head(2, dim)
    prev = head.predictive_var(probe)
    for lo in range(0, len(y), 100):
        head.accumulate(phi[lo : lo + 100], act[lo : lo + 100], y[lo : lo + 100])
        head.refresh()
        cur = head.predictive_var(probe)
        assert torch.all(cur <= prev * (1 + 1e-5))
        prev = cur
    assert torch.all(prev < 0.2 * head.prior_std**2 * probe.square().sum(1, keepdim=True))


def test_cov_scale_scales_predictive_variance_exactly() -> None:
    phi = torch.randn(20, 4, generator=torch.Generator().manual_seed(14))
    base = _fitted_head(cov_scale=1.0)
    scaled = _fitted_head(cov_scale=0.25)
    torch.testing.assert_close(scaled.predictive_var(phi), 0.25 * base.predictive_var(phi))
    torch.testing.assert_close(scaled.cov_ADD, 0.25 * base.cov_ADD)
    torch.testing.assert_close(scaled.mean_AD, base.mean_AD)
    act = torch.arange(20) % 3
    torch.testing.assert_close(
        scaled.predictive_var_action(phi, act), scaled.predictive_var(phi)[torch.arange(20), act]
    )


def test_cholesky_jitter_repairs_non_pd() -> None:
    rng = np.random.default_rng(15)
    q, _ = np.linalg.qr(rng.normal(size=(6, 6)))
    eig = np.array([-1e-9, 1e-3, 0.1, 1.0, 2.0, 5.0])
    m = q @ np.diag(eig) @ q.T
    m_t = torch.as_tensor(m)
    assert torch.linalg.cholesky_ex(m_t).info != 0
    l_DD, jitter = cholesky_jitter(m_t)
    assert float(jitter) > 0
    np.testing.assert_allclose((l_DD @ l_DD.T).numpy(), m + float(jitter) * np.eye(6), atol=1e-10)
    # batched: a PD matrix in the batch gets no jitter
    l_2DD, jitter_2 = cholesky_jitter(torch.stack([m_t, torch.eye(6, dtype=torch.float64)]))
    assert float(jitter_2[0]) > 0 and float(jitter_2[1]) == 0
    torch.testing.assert_close(l_2DD[1], torch.eye(6, dtype=torch.float64))
    with pytest.raises(ValueError, match="NaN"):
        cholesky_jitter(torch.full((3, 3), float("nan")))
    for bad in (float("inf"), -float("inf"), float("nan")):  # one bad entry in a batch
        m_2DD = torch.eye(4, dtype=torch.float64).repeat(2, 1, 1)
        m_2DD[1, 2, 3] = bad
        with pytest.raises(ValueError, match="NaN or inf"):
            cholesky_jitter(m_2DD)


def test_head_refresh_counts_jitter_events() -> None:
    dim = 5
    head = _head(2, dim)
    rng = np.random.default_rng(16)
    q, _ = np.linalg.qr(rng.normal(size=(dim, dim)))
    # statistics whose precision Phi Phi^T / s_eps^2 + I / s^2 has a tiny negative eigenvalue
    shift = NOISE_STD**2 / PRIOR_STD**2
    eig = np.array([-shift * (1 + 1e-10), 1.0, 2.0, 3.0, 4.0])
    head.phiphiT_ADD[0] = torch.as_tensor(q @ np.diag(eig) @ q.T)
    head.refresh()  # must not raise
    assert head.jitter_events == 1 and head.last_jitter > 0
    assert torch.isfinite(head.mean_AD).all() and torch.isfinite(head.sqrt_cov_ADD).all()
    head.reset_statistics()
    head.refresh()
    assert head.jitter_events == 1 and head.last_jitter == 0.0


def test_state_dict_round_trip() -> None:
    head = _fitted_head(cov_scale=0.5)
    phi, act, y = _make_data([3, 3, 3], 4, seed=17)
    head.accumulate(phi, act, y)  # statistics now differ from the cached posterior
    state = head.state_dict()
    other = BLRHead(num_actions=3, dim=4)
    other.load_state_dict(state)
    probe = torch.randn(6, 4, generator=torch.Generator().manual_seed(18))
    q1 = head.q_sample(probe, generator=torch.Generator().manual_seed(19))
    q2 = other.q_sample(probe, generator=torch.Generator().manual_seed(19))
    torch.testing.assert_close(q1, q2, rtol=0, atol=0)
    head.refresh()
    other.refresh()
    torch.testing.assert_close(head.cov_ADD, other.cov_ADD, rtol=0, atol=0)
    torch.testing.assert_close(head.mean_AD, other.mean_AD, rtol=0, atol=0)
    with pytest.raises(ValueError, match="num_actions"):
        BLRHead(num_actions=2, dim=4).load_state_dict(state)


def test_generator_makes_sampling_reproducible() -> None:
    head = _fitted_head()
    phi = torch.randn(4, 4, generator=torch.Generator().manual_seed(20))
    a = head.q_sample(phi, generator=torch.Generator().manual_seed(21))
    b = head.q_sample(phi, generator=torch.Generator().manual_seed(21))
    c = head.q_sample(phi, generator=torch.Generator().manual_seed(22))
    torch.testing.assert_close(a, b, rtol=0, atol=0)
    assert not torch.equal(a, c)


def test_greedy_predictive_variance() -> None:
    head = _fitted_head()
    phi = torch.randn(30, 4, generator=torch.Generator().manual_seed(23))
    greedy = (phi.double() @ head.posterior()[0].T).argmax(1)
    cov = head.cov_ADD
    p = phi.double()
    expected = torch.einsum("bd,bde,be->b", p, cov[greedy], p).mean()
    assert abs(greedy_predictive_variance(head, phi) - float(expected)) < 1e-5 * float(expected)


def test_argument_validation() -> None:
    with pytest.raises(ValueError, match="prior_std"):
        BLRHead(num_actions=2, dim=3, prior_std=0.0)
    with pytest.raises(ValueError, match="noise_std"):
        BLRHead(num_actions=2, dim=3, noise_std=-1.0)
    with pytest.raises(ValueError, match="forgetting"):
        BLRHead(num_actions=2, dim=3, forgetting=0.0)
    with pytest.raises(ValueError, match="cov_scale"):
        BLRHead(num_actions=2, dim=3, cov_scale=-1.0)
    head = BLRHead(num_actions=2, dim=3)
    with pytest.raises(ValueError, match="actions must lie"):
        head.accumulate(torch.zeros(2, 3), torch.tensor([0, 2]), torch.zeros(2))
    with pytest.raises(ValueError, match="phi_ND"):
        head.accumulate(torch.zeros(2, 4), torch.tensor([0, 1]), torch.zeros(2))
    with pytest.raises(ValueError, match="phi_BD"):
        head.q_sample(torch.zeros(2, 4))
