"""k-step returns at terminals and truncations; the double-Q target of Eq. 2."""

import numpy as np
import torch

from farsighter.ops.targets import centered_optimism, double_q_target, nstep_returns

G = 0.9


def test_full_window_no_episode_end() -> None:
    r = np.array([[1.0, 2.0, 3.0]])
    z = np.zeros_like(r, dtype=bool)
    ret, n, boot = nstep_returns(r, z, z, G)
    assert np.isclose(ret[0], 1 + G * 2 + G**2 * 3)
    assert n[0] == 3 and np.isclose(boot[0], G**3)


def test_terminal_inside_window_stops_sum_and_bootstrap() -> None:
    r = np.array([[1.0, 2.0, 100.0, 5.0]])
    term = np.array([[False, True, False, False]])
    trunc = np.zeros_like(term)
    ret, n, boot = nstep_returns(r, term, trunc, G)
    assert np.isclose(ret[0], 1 + G * 2)  # nothing from the next episode
    assert n[0] == 2 and boot[0] == 0.0  # a terminal state gets no bootstrap


def test_truncation_inside_window_bootstraps_with_gamma_j() -> None:
    r = np.array([[1.0, 2.0, 100.0]])
    term = np.zeros((1, 3), dtype=bool)
    trunc = np.array([[False, True, False]])
    ret, n, boot = nstep_returns(r, term, trunc, G)
    assert np.isclose(ret[0], 1 + G * 2)
    assert n[0] == 2 and np.isclose(boot[0], G**2)


def test_terminal_on_first_step_and_k1() -> None:
    r = np.array([[7.0, 1.0], [3.0, 4.0]])
    term = np.array([[True, False], [False, False]])
    ret, n, boot = nstep_returns(r, term, np.zeros_like(term), G)
    assert np.allclose(ret, [7.0, 3 + G * 4]) and list(n) == [1, 2]
    assert np.allclose(boot, [0.0, G**2])
    ret1, n1, boot1 = nstep_returns(r[:, :1], term[:, :1], np.zeros((2, 1), bool), G)
    assert np.allclose(ret1, [7.0, 3.0]) and np.allclose(boot1, [0.0, G])


def test_random_windows_match_a_step_by_step_reading() -> None:
    """Every window length, ends anywhere (terminations, truncations, both, none): returns,
    steps and bootstrap as one reads them step by step (an end on the window's last step does
    not shorten it; a termination there still stops the bootstrap)."""
    rng = np.random.default_rng(0)
    for k in range(1, 7):
        r = rng.normal(size=(400, k))
        term = rng.random((400, k)) < 0.15
        trunc = rng.random((400, k)) < 0.15
        ret, n, boot = nstep_returns(r, term, trunc, G)
        assert n.dtype == np.int64 and ret.dtype == boot.dtype == np.float32
        _check_step_by_step(r, term, trunc, np.zeros_like(term), (ret, n, boot))


def _check_step_by_step(
    r: np.ndarray,
    term: np.ndarray,
    trunc: np.ndarray,
    cut: np.ndarray,
    got: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> None:
    """Each row's window read step by step: it stops before a cut step after the first, or
    after a step that ends the episode; no bootstrap after a termination."""
    ret, n, boot = got
    for b in range(r.shape[0]):
        total, steps = 0.0, 0
        for j in range(r.shape[1]):
            if j >= 1 and cut[b, j]:
                break
            total += G**j * r[b, j]
            steps += 1
            if term[b, j] or trunc[b, j]:
                break
        assert n[b] == steps
        assert np.isclose(ret[b], total, rtol=1e-6, atol=1e-6)
        assert boot[b] == np.float32(0.0 if term[b, steps - 1] else G**steps)


def test_double_q_target_uses_online_argmax_and_target_value() -> None:
    q_online = torch.tensor([[1.0, 5.0, 2.0], [9.0, 0.0, 1.0]])
    q_target = torch.tensor([[10.0, -1.0, 30.0], [2.0, 50.0, 60.0]])
    y = double_q_target(torch.tensor([1.0, 2.0]), torch.tensor([0.5, 0.0]), q_online, q_target)
    # row 0: online argmax is action 1, valued by the target net at -1 (not max 30)
    assert torch.allclose(y, torch.tensor([1.0 + 0.5 * -1.0, 2.0]))


def test_clip_gradients_gives_clip_grad_norm_s_numbers() -> None:
    import copy

    from torch import nn

    from farsighter.agents.common import clip_gradients

    torch.manual_seed(0)
    for scale in (1e-3, 1.0, 100.0):  # below, near and above the bound
        net = nn.Sequential(nn.Linear(50, 40), nn.ReLU(), nn.Linear(40, 3))
        other = copy.deepcopy(net)
        x = torch.randn(16, 50) * scale
        for n in (net, other):
            n(x).pow(2).sum().backward()
        before = nn.utils.get_total_norm([p.grad for p in net.parameters()])
        nn.utils.clip_grad_norm_(net.parameters(), 10.0)
        clip_gradients(list(other.parameters()), 10.0)
        assert all(
            torch.equal(a.grad, b.grad)
            for a, b in zip(net.parameters(), other.parameters(), strict=True)
        )
        after = nn.utils.get_total_norm([p.grad for p in other.parameters()])
        assert after <= 10.0 + 1e-4 and (before > 10.0 or torch.equal(after, before))


def test_centered_optimism_sums_to_zero_and_leaves_ends_alone() -> None:
    y_mean = torch.tensor([1.0, 2.0, 3.0, 4.0])
    bonus = torch.tensor([0.4, 0.1, 0.0, 0.7])
    bootstrap = torch.tensor([0.9, 0.45, 0.0, 0.9])
    out = centered_optimism(y_mean + bonus, y_mean, bootstrap)
    # (0.4 + 0.1 + 0.7) / (0.9 + 0.45 + 0.9) = 1.2 / 2.25 per unit of bootstrap
    torch.testing.assert_close(out, y_mean + bonus - bootstrap * (1.2 / 2.25))
    assert abs(float((out - y_mean).sum())) < 1e-6 and out[2] == 3.0
    none = torch.zeros(4)  # nothing bootstraps: nothing to centre
    torch.testing.assert_close(centered_optimism(y_mean + bonus, y_mean, none), y_mean + bonus)


def test_cut_windows_stop_before_the_first_exploratory_step() -> None:
    """k_target cut: against a step-by-step reading, the window stops before the first step
    j >= 1 whose action was exploratory and bootstraps from s_{t+j} with gamma^j; the first
    step's own flag never cuts; an episode end before the cut still ends the window (a
    terminal one with no bootstrap). Without flags the windows are the plain ones."""
    rng = np.random.default_rng(1)
    for k in range(1, 7):
        r = rng.normal(size=(400, k))
        term = rng.random((400, k)) < 0.1
        trunc = rng.random((400, k)) < 0.1
        cut = rng.random((400, k)) < 0.3
        _check_step_by_step(r, term, trunc, cut, nstep_returns(r, term, trunc, G, cut))
        plain = nstep_returns(r, term, trunc, G)
        none = nstep_returns(r, term, trunc, G, np.zeros_like(cut))
        for a, c in zip(plain, none, strict=True):
            assert np.array_equal(a, c)
