"""Farsighter's posterior refresh (Algorithm 1 lines 6 and 7), for one posterior: each seed of
:class:`~farsighter.agents.farsighter.FarsighterAgent` hands it its own networks (``torso``),
streams and regression targets (``targets``)."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
import torch
from torch import nn

from farsighter.agents.common import (
    Counters,
    RecentRows,
    TensorBatch,
    adapt_k,
    batch_tensors,
    build_seeded,
)
from farsighter.config import Config
from farsighter.networks import MLPTorso, RandomFeatureTorso, Torso, make_torso
from farsighter.ops.blr import BLRHead, action_gap_scale, greedy_predictive_variance
from farsighter.ops.refit import ReplayRows
from farsighter.replay import TERMINATED, TRUNCATED, ReplayBuffer

FEATURE_CHUNK = 4_096  # rows per forward pass when computing features for a posterior refresh
RECENT_FEATURES = 2_048  # incremental mode: minibatch features kept for adaptive k's Q-variance
REFIT_ROWS = 50_000  # blr.switch_restart refit: the latest rows of the replay it fits


@dataclass
class FarsighterCounters(Counters):
    refreshes: int = 0  # posterior refreshes made (every M steps)
    draws: int = 0  # Thompson draws made (one per environment and acting step with redraw=step)
    steps_since_draw: int = 0  # acting steps since the held draw (redraw = every, k)
    q_variance: float = float("nan")  # at the latest refresh (adaptive k's signal)

    def __post_init__(self) -> None:
        # With adaptive k off, q_variance is a diagnostic: computed when read (settle), from what
        # the latest refresh held. Not a field, so never saved.
        self._pending: Callable[[], float | None] | None = None

    def defer_q_variance(self, head: BLRHead, phi_ND: torch.Tensor) -> None:
        """The latest refresh's Q-variance, computed when :meth:`settle` is called: the same
        numbers (the posterior changes only at a refresh, and the rows are kept as they were),
        without the A d^2 per row work at every refresh (a fifth of a refresh at d = 640)."""
        rows_ND, version = phi_ND.clone(), head.version

        def compute() -> float | None:  # None: the posterior was loaded since; keep its value
            return greedy_predictive_variance(head, rows_ND) if head.version == version else None

        self._pending = compute

    def settle(self) -> FarsighterCounters:
        """These counters with ``q_variance`` computed if it was deferred (before it is read or
        saved)."""
        if self._pending is not None:
            value, self._pending = self._pending(), None
            if value is not None:
                self.q_variance = value
        return self


def seeded_torso(
    cfg: Config, obs_space: gym.spaces.Box, num_actions: int
) -> tuple[Torso, torch.Tensor]:
    """The torso and the posterior's initial mean of seed ``cfg.seed``: the mean starts where a
    linear Q head would (no bias: Q = phi^T w_a)."""

    def build() -> tuple[Torso, torch.Tensor]:
        torso: Torso = make_torso(obs_space, cfg.hidden_sizes)
        if cfg.blr.random_features and isinstance(torso, MLPTorso):  # images: learned alone
            entries = int(np.prod(obs_space.shape))
            width = cfg.blr.random_feature_width(entries)
            torso = RandomFeatureTorso(torso, entries, width)
        return torso, nn.Linear(torso.out_dim, num_actions, bias=False).weight.detach()

    return build_seeded(cfg.seed, build)  # type: ignore[no-any-return]


def make_head(
    cfg: Config,
    num_actions: int,
    dim: int,
    init_AD: torch.Tensor,
    device: torch.device,
    fit_dim: int | None = None,
) -> BLRHead:
    """The BLR posterior of ``cfg.blr`` over ``num_actions`` weight vectors of width ``dim``,
    its mean starting at ``init_AD`` (where a linear Q head would start) over the ``fit_dim``
    features it regresses on (:func:`fitted_dim`) and at 0 past them."""
    b = cfg.blr
    head = BLRHead(
        num_actions=num_actions,
        dim=dim,
        prior_std=b.prior_std,
        noise_std=b.noise_std,
        cov_scale=b.cov_scale,
        forgetting=b.forgetting,
        scale=b.scale,
        device=device,
        fit_dim=fit_dim,
    )
    init_AD = init_AD.clone()
    init_AD[:, head.fit_dim :] = 0.0
    head.set_mean(init_AD.to(device))
    return head


def fitted_dim(cfg: Config, torso: Torso) -> int | None:
    """The features the posterior mean regresses on (``BLRHead``'s ``fit_dim``): the learned
    ones alone where the random features fit no target (``blr.random_features_fit`` False),
    else all of them (None)."""
    if isinstance(torso, RandomFeatureTorso) and not cfg.blr.random_features_fit:
        return int(torso.torso.out_dim)
    return None


def accumulate(
    cfg: Config,
    head: BLRHead,
    recent_phi: RecentRows,
    phi_BD: torch.Tensor,
    a_B: torch.Tensor,
    y_B: torch.Tensor,
) -> None:
    """Incremental mode: add a minibatch to the running statistics with weight
    w = data_weight train_every / batch_size (scaling phi and y by sqrt(w) scales Phi Phi^T and
    Phi y by w),
    and keep its features for adaptive k's Q-variance."""
    root_w = (cfg.blr.data_weight * cfg.train_every / cfg.batch_size) ** 0.5
    head.accumulate(phi_BD * root_w, a_B, y_B * root_w)
    recent_phi.add(phi_BD)


def refresh_posterior(
    cfg: Config,
    head: BLRHead,
    counters: FarsighterCounters,
    recent_phi: RecentRows,
    replay: ReplayBuffer,
    rng: np.random.Generator,
    device: torch.device,
    torso: Callable[[torch.Tensor], torch.Tensor],
    targets: Callable[[TensorBatch], torch.Tensor],
    streams: slice = slice(None),
) -> None:
    """Algorithm 1 line 6 (and line 7 with adaptive k) for one posterior: in batch mode a fit
    on the features (``torso``) and regression targets (``targets``) of D tuples of the replay's
    ``streams`` (:func:`refresh_rows`); in incremental mode from its running statistics."""
    if cfg.blr.mode == "batch":
        d, k = cfg.blr.posterior_samples, counters.k
        if cfg.blr.posterior_sampling == "uniform":  # the BDQN code: whole buffer, replaced
            e_N, l_N = replay.uniform_indices(d, rng, streams)
        else:  # the latest D tuples; with stride one is stored per k steps, so k D rows
            e_N, l_N = replay.recent_indices(d * (k if cfg.stride else 1), streams)
        phi_ND, a_N, y_N = refresh_rows(replay, e_N, l_N, cfg, k, device, torso, targets)
        if len(a_N) == 0:
            return
        head.fit(phi_ND, a_N, y_N)  # statistics reset each refresh, as in BDQN's code
    else:  # the statistics are already up to date: no features are recomputed
        recent = recent_phi.rows()
        if recent is None:
            return
        head.refresh()
        phi_ND = recent
    if cfg.blr.act_width == "action-gap":
        head.act_scale = action_gap_scale(head, phi_ND)
    if not cfg.adaptive_k.enabled:  # a diagnostic only: computed when read
        counters.defer_q_variance(head, phi_ND)
        return
    counters.q_variance = greedy_predictive_variance(head, phi_ND)
    adapt_k(counters, counters.q_variance, cfg.adaptive_k, replay)


def windows(
    replay: ReplayBuffer,
    e_N: np.ndarray,
    l_N: np.ndarray,
    cfg: Config,
    k: int,
    device: torch.device,
) -> Iterator[TensorBatch]:
    """The valid k-step windows starting at the given rows of ``replay``, ``FEATURE_CHUNK``
    candidates at a time (stacked frames are never all in memory)."""
    for lo in range(0, len(e_N), FEATURE_CHUNK):
        part = replay.sample_indices(
            e_N[lo : lo + FEATURE_CHUNK],
            l_N[lo : lo + FEATURE_CHUNK],
            k,
            cfg.gamma,
            stride=k if cfg.stride else 1,  # Algorithm 1: one tuple per k
            on_device=True,  # from the device mirror when the replay keeps one
        )
        if len(part.actions) > 0:
            yield batch_tensors(part, device)


@torch.no_grad()
def refresh_rows(
    replay: ReplayBuffer,
    e_N: np.ndarray,
    l_N: np.ndarray,
    cfg: Config,
    k: int,
    device: torch.device,
    torso: Callable[[torch.Tensor], torch.Tensor],
    targets: Callable[[TensorBatch], torch.Tensor],
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Features of the current theta (``torso``) and the regression targets (``targets``) of
    the valid k-step tuples starting at the given rows of ``replay``: a batch-mode posterior
    refresh's data, gathered chunk by chunk (:func:`windows`)."""
    phis, actions, ys = [], [], []
    for t in windows(replay, e_N, l_N, cfg, k, device):
        phis.append(torso(t.obs_B))
        actions.append(t.actions_B)
        ys.append(targets(t))
    if not phis:
        empty = torch.zeros(0, device=device)
        return empty, empty.long(), empty
    return torch.cat(phis), torch.cat(actions), torch.cat(ys)


@torch.no_grad()
def replay_rows(
    replay: ReplayBuffer,
    cfg: Config,
    k: int,
    device: torch.device,
    torso: Callable[[torch.Tensor], torch.Tensor],
    streams: slice = slice(None),
) -> ReplayRows:
    """The valid k-step windows of the latest ``REFIT_ROWS`` rows of ``replay``'s ``streams``
    (cut where the replay cuts them), with phi(s) and phi(s') of ``torso``: what
    ``blr.switch_restart = refit`` fits (:func:`farsighter.ops.refit.refit`). One feature map
    for both: a fit iterated to its fixed point on the online features and read at the target
    torso's (which lag them) extrapolates, and its values climbed past any return (the drifting
    lock L = 10: every Q above 1, up to 3.4, for a reward of 1)."""
    e_N, l_N = replay.recent_indices(REFIT_ROWS, streams)
    parts = [
        (torso(t.obs_B).double(), t.actions_B, t.returns_B, t.bootstrap_B, torso(t.next_obs_B))
        for t in windows(replay, e_N, l_N, cfg, k, device)
    ]
    if not parts:
        empty = torch.zeros(0, device=device)
        return ReplayRows(empty[:, None].double(), empty.long(), empty, empty, empty[:, None])
    phi, actions, returns, bootstrap, phi_next = (torch.cat(x) for x in zip(*parts, strict=True))
    ceiling = largest_reward_sum(replay, e_N, l_N, cfg.gamma)
    return ReplayRows(phi, actions, returns, bootstrap, phi_next, ceiling)


def largest_reward_sum(
    replay: ReplayBuffer, e_N: np.ndarray, l_N: np.ndarray, gamma: float
) -> float:
    """The largest discounted sum of rewards from any of the given rows (each stream's in
    increasing order) to any later row of its episode (at most to its end, or to the latest row
    where the episode goes on): what the rewards confirm, and at least every k-step return."""
    best = -math.inf
    for e in np.unique(e_N):
        mine = l_N[e_N == e]
        slots = mine % replay.capacity
        rewards = replay.rewards[e, slots].astype(np.float64)
        ends = (replay.flags[e, slots] & (TERMINATED | TRUNCATED)) != 0
        g = 0.0  # the largest sum from row i on: its reward and, where it pays, the best after
        for i in range(len(mine) - 1, -1, -1):
            g = rewards[i] + (0.0 if ends[i] else gamma * max(g, 0.0))
            best = max(best, g)
    return best
