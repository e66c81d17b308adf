"""Farsighter's and BDQN's loss on theta (Eq. 8) and the regression targets of the posterior.

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

The loss owns the target torso and the target mean, which move only at the hard copy (Algorithm
1 line 8: :meth:`FarsighterLoss.copy_target`). It draws nothing: the acting draw and the normals
come in its inputs (the agent draws them before the update, so a captured step can take them),
and the target features of s' may come from the target cache.
"""

from __future__ import annotations

import copy
from collections.abc import Callable

import numpy as np
import torch

from farsighter.agents.common import TensorBatch, td_loss
from farsighter.agents.cuda_graph import Tensors
from farsighter.agents.farsighter_targets import (
    Targets,
    advantage,
    eq8_targets,
    k_or_one_step,
    max_targets,
    one_step_batch,
    one_step_draws,
    q_taken,
    target_draws,
    uses_one_step,
)
from farsighter.agents.learner import CachedTarget
from farsighter.config import Config
from farsighter.exploration.optimism import calibrated, without_staying
from farsighter.networks import Torso, online_and_target
from farsighter.ops.blr import BLRHead
from farsighter.replay.target_cache import TargetCache


class FarsighterLoss:
    """Eq. 8's squared (or Huber) error of Q at the posterior mean (module docstring)."""

    def __init__(
        self, torso: Torso, head: BLRHead, cfg: Config, cache: TargetCache | None = None
    ) -> None:
        self.torso, self.head = torso, head
        self.torso_target = copy.deepcopy(torso).requires_grad_(False)
        # target features of s' kept per replay row until the next copy (eager runs only)
        self.target = CachedTarget(self.torso_target, cache)
        self.target_mean_AD = head.mean_AD.clone()
        self.kind, self.blr, self.k_target = cfg.loss, cfg.blr, cfg.k_target
        self.optimistic, self.calibrated = (cfg.blr, cfg.k_target), False  # blr.optimism

    def calibrate(self, on: bool = True) -> None:
        """``blr.optimism = until-reward``'s switch: from now on the posterior mean and the
        k-step target alone (no draw, no max with the one-step target; cut at exploratory
        actions where ``k_target = cut``); ``on = False``: the optimism again (rearmed)."""
        self.calibrated = on
        self.blr, self.k_target = calibrated(*self.optimistic, on)

    def copy_target(self) -> None:
        """Algorithm 1 line 8: target torso and target mean <- online ones (in place)."""
        self.torso_target.load_state_dict(self.torso.state_dict())  # clears the target cache
        self.target_mean_AD.copy_(self.head.mean_AD)

    @torch.no_grad()
    def targets(
        self, t: TensorBatch, draws: Tensors, phi_next_target: torch.Tensor | None = None
    ) -> torch.Tensor:
        """y of Eq. 8 with k-step returns; ``draws``: ``w_online_AD`` (thompson) or ``eps_BA``
        (sample); ``phi_next_target``: phi_target(s') when the cache gave it."""
        return self.target_and_mean(t, draws, phi_next_target, with_mean=False)[0]

    @torch.no_grad()
    def target_and_mean(
        self,
        t: TensorBatch,
        draws: Tensors,
        phi_next_target: torch.Tensor | None = None,
        with_mean: bool = True,
    ) -> tuple[torch.Tensor, torch.Tensor | None]:
        """:meth:`targets`, and (``with_mean``) the same target under the posterior mean, no
        draw added (``k_target = max-mean`` chooses by it); else None."""
        if not self.blr.stay_optimism:  # no draw where the window ends where it began
            draws = without_staying(draws, t.obs_B, t.next_obs_B)
        if phi_next_target is None:
            phi_next, phi_next_target = online_and_target(
                self.torso, self.torso_target, t.next_obs_B
            )
        else:
            phi_next = self.torso(t.next_obs_B)
        y_B = eq8_targets(
            self.head,
            self.target_mean_AD,
            self.blr.target,
            t,
            phi_next,
            phi_next_target,
            draws,
            self.blr.center_sample,
            self.blr.target_noise_scale,
        )
        if not with_mean:
            return y_B, None
        mean = eq8_targets(self.head, self.target_mean_AD, "mean", t, phi_next, phi_next_target, {})
        return y_B, mean

    @torch.no_grad()
    def posterior_targets(self, t: TensorBatch, draws: Tensors) -> torch.Tensor:
        """Regression targets of a posterior refresh: Eq. 8's (``blr.posterior_target =
        double``, with its draws) or y = r^k + gamma^k max_a phi_target(s')^T mean_target_a
        (``max``, the BDQN code; no draws)."""
        if self.blr.posterior_target == "double":
            return self.targets(t, draws)
        return max_targets(t, self.torso_target(t.next_obs_B), self.target_mean_AD)

    def __call__(self, inputs: Tensors) -> Tensors:
        """The loss of a minibatch (inputs: :class:`TensorBatch`'s fields, the draws, and with
        ``k_target = max`` the one-step windows' ``one_*`` fields); in incremental mode also the
        features and regression targets the posterior's statistics add."""
        t = TensorBatch.of(inputs)
        cached = inputs.get("phi_next_target_BD")
        if "one_next_obs_B" not in inputs or not uses_one_step(self.k_target):
            y_B = self.targets(t, inputs, cached)
        else:  # k_target max or max-mean: same s and a, so only s', r, gamma
            one = (
                one_step_batch(t, inputs),
                one_step_draws(inputs),
                inputs.get("one_phi_next_target_BD"),
            )
            if self.k_target == "max":
                y_B = k_or_one_step(self.targets(t, inputs, cached), self.targets(*one))
            else:  # max-mean: the one larger under the mean, with its draw
                y_B, mean_B = self.target_and_mean(t, inputs, cached)
                one_B, one_mean_B = self.target_and_mean(*one)
                y_B = k_or_one_step(y_B, one_B, mean_B, one_mean_B)
        gap = self.advantage(t)  # blr.advantage_learning, after the switch
        y_B = gap(y_B)
        phi_BD = self.torso(t.obs_B)
        out = {"loss": td_loss(q_taken(phi_BD, self.head.mean_AD, t.actions_B), y_B, self.kind)}
        if self.blr.mode == "incremental":  # the statistics are added outside the step
            double = self.blr.posterior_target == "double"
            out["phi_BD"] = phi_BD.detach()
            out["y_post_B"] = y_B if double else gap(self.posterior_targets(t, {}))
        return out

    @torch.no_grad()
    def advantage(self, t: TensorBatch) -> Targets:
        """Targets -> the same under ``blr.advantage_learning`` once calibrated (else as given),
        with the target network's values of the rows' start states."""
        alpha = self.blr.advantage_learning if self.calibrated else 0.0
        phi_BD = self.torso_target(t.obs_B) if alpha else None
        return advantage(alpha, phi_BD, self.target_mean_AD, t.actions_B)

    def draws(
        self,
        rows: int,
        one_step: bool,
        gen: torch.Generator,
        acting_draw: Callable[[], torch.Tensor],
    ) -> Tensors:
        """:func:`target_draws` of this loss's head and ``blr.target``."""
        return target_draws(self.blr.target, self.head, rows, one_step, gen, acting_draw)

    def target_features(
        self, e_B: np.ndarray, next_B: np.ndarray, next_obs_B: torch.Tensor, prefix: str = ""
    ) -> Tensors:
        """``{prefix + "phi_next_target_BD": phi_target(s')}`` of a minibatch's next states
        (logical rows ``next_B``) through the target cache; empty without one (the step then
        runs the target torso itself)."""
        if self.target.cache is None:
            return {}
        return {prefix + "phi_next_target_BD": self.target(next_obs_B, e_B, next_B)}
