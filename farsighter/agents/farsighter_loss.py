"""Farsighter's and BDQN's loss on theta (Eq. 8) and the regression targets of the posterior,
for S seeds (S = 1 for a run alone).

Q(s, a) = phi_theta(s)^T w_a. The representation theta learns with w fixed at the posterior mean,
on the double-Q target of k-step returns (section 4.4):

    y = r^k + gamma^k phi_target(s')^T mean_target[a*],   a* = argmax_a phi_theta(s')^T w_a

with w the posterior mean (Eq. 8), or the latest acting Thompson draw (``blr.target = thompson``,
the BDQN authors' code). With ``blr.target = sample`` a posterior draw per row and action,
sqrt(cov_scale) phi_target(s')^T U_a z, is added to both Q's of s' (optimism that propagates;
drawn as sqrt(cov_scale) ||U_a^T phi_target(s')|| eps, the same distribution from one normal per
row and action: ``BLRHead.q_noise_rows``; none where s' is s_t with ``blr.stay_optimism``
False); with ``k_target = max`` the target is the larger of the k-step and the one-step target
of the same start, with ``max-mean`` the one larger under the posterior mean (``k_target``).

The minibatch holds seed 0's B rows, then seed 1's, ...; one forward of the (stacked) torsos gives
every seed's features, and each seed's targets and loss are its own (:class:`SeedParts`), so its
gradient is its own loss's. The loss owns the target torsos, which move only at the hard copy
(Algorithm 1 line 8: :meth:`FarsighterLoss.copy_target`). It draws nothing: each seed's draws come
in its inputs under ``name@s`` (:func:`seed_key`; the agent draws them before the update, so a
captured step can take them), and the target features of s' may come from the target caches.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from farsighter.agents.common import TensorBatch, td_loss
from farsighter.agents.cuda_graph import Tensors
from farsighter.agents.farsighter_parts import SeedParts
from farsighter.agents.farsighter_targets import (
    Targets,
    max_targets,
    one_step_batch,
    one_step_draws,
    q_taken,
    uses_one_step,
)
from farsighter.config import Config
from farsighter.stacked import (
    SeedNetwork,
    aligned,
    member_pair,
    online_and_target_seeds,
)

DRAWS = ("w_online_AD", "eps_BA", "one_eps_BA")
"""The names of what the targets draw (:func:`farsighter.agents.farsighter_targets.target_draws`)."""


def seed_key(name: str, s: int) -> str:
    """The input key of seed ``s``'s draw ``name``."""
    return f"{name}@{s}"


class FarsighterLoss:
    """Eq. 8's squared (or Huber) error of Q at the posterior mean, each seed's mean over its
    own rows, summed over the seeds (module docstring)."""

    def __init__(
        self,
        torso: SeedNetwork,
        torso_target: SeedNetwork,
        parts: Sequence[SeedParts],
        cfg: Config,
    ) -> None:
        self.torso, self.torso_target = torso, torso_target.requires_grad_(False)
        self.parts, self.kind = list(parts), cfg.loss
        self.S = len(self.parts)
        caches = [p.cache for p in self.parts if p.cache is not None]

        def clear(module: object, keys: object) -> None:
            for cache in caches:
                cache.clear()

        if caches:  # a copy into the target torsos, or any load of them, empties the caches
            torso_target.register_load_state_dict_post_hook(clear)

    def copy_target(self) -> None:
        """Algorithm 1 line 8: every seed's target torso and target mean <- its online ones (in
        place); the target caches empty."""
        self.torso_target.load_state_dict(self.torso.state_dict())
        for p in self.parts:
            p.target_mean_AD.copy_(p.head.mean_AD)

    def seed_inputs(self, inputs: Tensors, s: int) -> tuple[Tensors, Tensors]:
        """Seed ``s``'s rows of ``inputs`` and its draws (both as given for one seed)."""
        draws = {name: inputs[seed_key(name, s)] for name in DRAWS if seed_key(name, s) in inputs}
        if self.S == 1:
            return inputs, draws
        return {key: self.torso.by_seed(x)[s] for key, x in inputs.items() if "@" not in key}, draws

    def next_features(
        self, next_obs_B: torch.Tensor, cached_BD: torch.Tensor | None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """phi(s') and phi_target(s') of every seed, (S, B, D) each (``cached_BD``: the target
        features the caches gave; each seed's slice laid as a tensor alone, so that its
        products round as its run alone's)."""
        target = self.torso_target if cached_BD is None else None
        phi_next, phi_next_target = online_and_target_seeds(self.torso, target, next_obs_B)
        if phi_next_target is None:
            assert cached_BD is not None
            by_seed = self.torso.by_seed(cached_BD)
            phi_next_target = by_seed if self.S == 1 else aligned(by_seed)
        return phi_next, phi_next_target

    @torch.no_grad()
    def targets(self, t: TensorBatch, inputs: Tensors) -> list[torch.Tensor]:
        """Each seed's y of Eq. 8 on its rows of the minibatch ``t`` (``inputs``: its draws, the
        cached target features, and the one-step windows' ``one_*`` fields where a seed's
        ``k_target`` compares them), advantage learning applied where a seed is calibrated."""
        return [y_B for _, _, y_B in self.seed_targets(t, inputs)]

    @torch.no_grad()
    def seed_targets(
        self, t: TensorBatch, inputs: Tensors
    ) -> list[tuple[TensorBatch, Targets, torch.Tensor]]:
        """:meth:`targets`, with each seed's rows and its advantage-learning map (:meth:`gaps`),
        which the statistics of incremental mode reuse."""
        features = {
            prefix: self.next_features(
                inputs[prefix + "next_obs_B"], inputs.get(prefix + "phi_next_target_BD")
            )
            for prefix in ("", "one_")
            if prefix + "next_obs_B" in inputs
        }
        gaps = self.gaps(t)
        out = []
        for s, p in enumerate(self.parts):
            mine, draws = self.seed_inputs(inputs, s)
            t_s = TensorBatch.of(mine)
            nxt = (features[""][0][s], features[""][1][s])
            one = None
            if "one_" in features and uses_one_step(p.k_target):  # same s and a: s', r, gamma
                one_nxt = (features["one_"][0][s], features["one_"][1][s])
                one = (one_step_batch(t_s, mine), one_step_draws(draws), one_nxt)
            out.append((t_s, gaps[s], gaps[s](p.targets(t_s, draws, nxt, one))))
        return out

    @torch.no_grad()
    def gaps(self, t: TensorBatch) -> list[Targets]:
        """Each seed's targets -> the same under ``blr.advantage_learning`` once it is
        calibrated (else as given), with its target torso's features of the rows' starts."""
        start = None
        if any(p.advantage_alpha for p in self.parts):
            start = online_and_target_seeds(self.torso_target, None, t.obs_B)[0]
        actions_S = self.torso.by_seed(t.actions_B)
        return [
            p.advantage(None if start is None else start[s], actions_S[s])
            for s, p in enumerate(self.parts)
        ]

    @torch.no_grad()
    def posterior_targets(self, t: TensorBatch, draws: Tensors, s: int = 0) -> torch.Tensor:
        """Seed ``s``'s regression targets of a posterior refresh: Eq. 8's
        (``blr.posterior_target = double``, with its draws) or y = r^k + gamma^k max_a
        phi_target(s')^T mean_target_a (``max``, the BDQN code; no draws)."""
        p = self.parts[s]
        if p.blr.posterior_target == "double":
            return p.y(t, member_pair(self.torso, self.torso_target, t.next_obs_B, s), draws)
        return max_targets(t, self.torso_target.member_forward(t.next_obs_B, s), p.target_mean_AD)

    def __call__(self, inputs: Tensors) -> Tensors:
        """The loss of a minibatch (inputs: :class:`TensorBatch`'s fields, each seed's draws,
        and where a seed's ``k_target`` compares them the one-step windows' ``one_*`` fields):
        ``loss`` to differentiate, each seed's ``loss_S``; in incremental mode also each seed's
        features and regression targets, which the posterior's statistics add
        (``phi_BD@s``, ``y_post_B@s``)."""
        t = TensorBatch.of(inputs)
        seeds = self.seed_targets(t, inputs)
        phi_S = self.torso.each_seed(t.obs_B)
        losses = [
            td_loss(q_taken(phi_S[s], p.head.mean_AD, t_s.actions_B), y_B, self.kind)
            for s, (p, (t_s, _, y_B)) in enumerate(zip(self.parts, seeds, strict=True))
        ]
        loss_S = torch.stack(losses)
        out = {"loss": losses[0] if self.S == 1 else loss_S.sum(), "loss_S": loss_S.detach()}
        if self.parts[0].cfg.blr.mode == "incremental":  # the statistics are added outside
            posterior = None  # max (the BDQN code's regression): the target torso's values
            if self.parts[0].cfg.blr.posterior_target != "double":
                posterior = online_and_target_seeds(self.torso_target, None, t.next_obs_B)[0]
            for s, (p, (t_s, gap, y_B)) in enumerate(zip(self.parts, seeds, strict=True)):
                out[seed_key("phi_BD", s)] = phi_S[s].detach()
                if posterior is not None:
                    y_B = gap(max_targets(t_s, posterior[s], p.target_mean_AD))
                out[seed_key("y_post_B", s)] = y_B
        return out
