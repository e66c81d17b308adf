"""Eq. 8 on given features: the math of Farsighter's loss (agents/farsighter_loss), which each
seed's parts (agents/farsighter_parts) apply under their own posterior: the targets, the larger
of the k-step and the one-step target, the one-step windows, and what the targets draw."""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

import torch

from farsighter.agents.common import TensorBatch, obs_tensor, to_device
from farsighter.agents.cuda_graph import Tensors
from farsighter.ops.blr import BLRHead
from farsighter.ops.targets import advantage_learning, centered_optimism, double_q_target
from farsighter.replay import Batch, ReplayBuffer


def uses_one_step(k_target: str) -> bool:
    """Whether ``Config.k_target`` compares the k-step target with the one-step target of the
    same start (max, max-mean), which needs the one-step windows."""
    return k_target in ("max", "max-mean")


SAMPLED_TARGETS = ("sample", "sample-greedy")
"""The ``blr.target`` values whose next-state value carries a posterior draw per row."""


def eq8_targets(
    head: BLRHead,
    target_mean_AD: torch.Tensor,
    kind: str,
    t: TensorBatch,
    phi_next: torch.Tensor,
    phi_next_target: torch.Tensor,
    draws: Tensors,
    centered: bool = False,
    noise_scale: float = 1.0,
) -> torch.Tensor:
    """y of Eq. 8 from the online and target features of s' (``kind``: ``blr.target``): the
    double-Q target under the posterior mean (or the acting draw ``w_online_AD``), with the
    per-row posterior noise of ``eps_BA`` added to both Q's for ``sample`` (the argmax over the
    drawn values), to the target Q alone for ``sample-greedy`` (the draw of the action greedy
    under the mean: zero-mean noise) (``centered``: ``blr.center_sample``, the minibatch's mean
    optimism taken out; ``noise_scale``: ``blr.target_noise_scale``, a factor on the draw)."""
    q_next_online = phi_next @ draws.get("w_online_AD", head.mean_AD).T
    q_next_target = phi_next_target @ target_mean_AD.T
    if kind not in SAMPLED_TARGETS:
        return double_q_target(t.returns_B, t.bootstrap_B, q_next_online, q_next_target)
    if kind == "sample-greedy":  # the noise of one action a row: a 1/A of every action's
        a_B1 = q_next_online.argmax(dim=1, keepdim=True)  # double_q_target's argmax
        noise_B = head.q_noise_rows_action(
            phi_next_target, a_B1[:, 0], draws["eps_BA"].gather(1, a_B1)[:, 0]
        )
        if noise_scale != 1.0:
            noise_B.mul_(noise_scale)
        y_B = t.returns_B + t.bootstrap_B * (q_next_target.gather(1, a_B1)[:, 0] + noise_B)
    else:
        noise_BA = head.q_noise_rows(phi_next_target, draws["eps_BA"])
        if noise_scale != 1.0:
            noise_BA.mul_(noise_scale)
        y_B = double_q_target(
            t.returns_B, t.bootstrap_B, q_next_online + noise_BA, q_next_target + noise_BA
        )
    if not centered:
        return y_B
    y_mean_B = double_q_target(t.returns_B, t.bootstrap_B, q_next_online, q_next_target)
    return centered_optimism(y_B, y_mean_B, t.bootstrap_B)


def k_or_one_step(
    y_B: torch.Tensor,
    one_B: torch.Tensor,
    mean_B: torch.Tensor | None = None,
    one_mean_B: torch.Tensor | None = None,
) -> torch.Tensor:
    """The k-step target ``y_B`` or the one-step target ``one_B`` of each start: the larger
    (``k_target = max``), or, given both targets under the posterior mean (``max-mean``), the
    one whose mean is larger, with its draw. Taking the larger of two noisy targets keeps the
    larger noise, an upward bias each update that bootstrapping adds up; choosing by the means
    lets no draw choose."""
    if mean_B is None or one_mean_B is None:
        return torch.maximum(y_B, one_B)
    return torch.where(one_mean_B > mean_B, one_B, y_B)


def max_targets(
    t: TensorBatch, phi_next_target: torch.Tensor, target_mean_AD: torch.Tensor
) -> torch.Tensor:
    """y = r^k + gamma^k max_a phi_target(s')^T mean_target_a (the BDQN code's regression)."""
    return t.returns_B + t.bootstrap_B * (phi_next_target @ target_mean_AD.T).max(dim=1).values


def q_taken(phi_BD: torch.Tensor, mean_AD: torch.Tensor, actions_B: torch.Tensor) -> torch.Tensor:
    """Q(s, a) = phi(s)^T mean_a at the actions taken, (B,)."""
    return (phi_BD @ mean_AD.T).gather(1, actions_B[:, None])[:, 0]


def one_step_batch(t: TensorBatch, inputs: Tensors) -> TensorBatch:
    """The one-step windows of ``k_target = max`` (the ``one_*`` inputs): the same s and a."""
    return TensorBatch(
        obs_B=t.obs_B,
        next_obs_B=inputs["one_next_obs_B"],
        actions_B=t.actions_B,
        returns_B=inputs["one_returns_B"],
        bootstrap_B=inputs["one_bootstrap_B"],
    )


def one_step_inputs(
    replay: ReplayBuffer, batch: Batch, gamma: float, device: torch.device
) -> tuple[Tensors, Batch]:
    """The ``one_*`` inputs of ``k_target = max``: the one-step windows of a minibatch's starts
    (the same s and a, so only s', r and gamma), and those windows."""
    one = replay.gather(batch.env_index, batch.index, 1, gamma)
    inputs = {
        "one_next_obs_B": obs_tensor(one.next_obs, device),
        "one_returns_B": to_device(one.returns, device),
        "one_bootstrap_B": to_device(one.bootstrap, device),
    }
    return inputs, one


def one_step_draws(draws: Tensors) -> Tensors:
    """The one-step target's draws: the same acting draw, its own normals."""
    named = (("w_online_AD", "w_online_AD"), ("eps_BA", "one_eps_BA"))
    return {key: draws[src] for key, src in named if src in draws}


def target_draws(
    kind: str,
    head: BLRHead,
    rows: int,
    one_step: bool,
    gen: torch.Generator,
    acting_draw: Callable[[], torch.Tensor],
) -> Tensors:
    """What the targets of ``rows`` rows draw, in the order the eager targets drew them: the
    acting draw (``blr.target = thompson``: ``acting_draw()``), or the normals of the k-step
    target and then of the one-step target (``sample``, from ``gen``)."""
    if kind == "thompson":
        return {"w_online_AD": acting_draw()}
    if kind not in SAMPLED_TARGETS:
        return {}
    draws = {"eps_BA": head.noise_eps(rows, gen)}
    if one_step:
        draws["one_eps_BA"] = head.noise_eps(rows, gen)
    return draws


Targets = Callable[[torch.Tensor], torch.Tensor]
"""Targets -> targets (``blr.advantage_learning``'s, or as given)."""


def same(y_B: torch.Tensor) -> torch.Tensor:
    """The targets as given."""
    return y_B


def advantage(
    alpha: float,
    phi_target_BD: torch.Tensor | None,
    target_mean_AD: torch.Tensor,
    actions_B: torch.Tensor,
) -> Targets:
    """Targets -> the same under the advantage-learning operator of ``alpha``
    (:func:`farsighter.ops.targets.advantage_learning`), with Q_target(s, .) from the target
    features ``phi_target_BD`` of the rows' start states and the target mean; as given where
    alpha is 0 or there are no features."""
    if not alpha or phi_target_BD is None:
        return same
    q_BA = phi_target_BD @ target_mean_AD.T
    return partial(advantage_learning, q_target_BA=q_BA, actions_B=actions_B, alpha=alpha)
