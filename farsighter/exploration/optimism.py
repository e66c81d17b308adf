"""When the targets' optimism ends, and what the acting side records for the cut target.

``blr.optimism = until-reward`` keeps the targets' optimism (a posterior draw at the next state,
the larger of the k-step and the one-step target) until a run's first positive reward, then
trains on calibrated targets (:func:`calibrated`). ``k_target = cut`` stops a k-step window
before the first exploratory action (``ops.targets.nstep_returns``): the acting side flags
those actions (:func:`exploratory_actions`) and the replay keeps the flag with the row.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np
import torch

from farsighter.config import BLRConfig, Config
from farsighter.config.fields import KTarget
from farsighter.ops.blr import BLRHead
from farsighter.ops.refit import ReplayRows, refit


def calibrated(blr: BLRConfig, k_target: KTarget) -> tuple[BLRConfig, KTarget]:
    """``blr.optimism = until-reward``'s targets after its switch: the posterior mean's, and the
    k-step target alone (cut at exploratory actions where ``k_target`` or
    ``blr.calibrated_k_target`` is cut)."""
    cut = k_target == "cut" or blr.calibrated_k_target == "cut"
    return dataclasses.replace(blr, target="mean"), "cut" if cut else "k"


@torch.no_grad()
def exploratory_actions(
    head: BLRHead,
    phi_ED: torch.Tensor,
    actions_E: torch.Tensor,
    relative: float = 0.0,
) -> np.ndarray:
    """Which of the actions taken at features ``phi_ED`` were exploratory (``k_target = cut``):
    not the posterior mean's greedy action, and (``relative`` > 0: ``blr.cut_delay``
    (1 - gamma)) with a mean Q below the greedy action's by more than ``relative``
    |Q_greedy|."""
    q_EA = phi_ED @ head.mean_AD.T
    greedy_E = q_EA.argmax(dim=1)
    differs_E = actions_E != greedy_E
    if relative > 0 and bool(differs_E.any()):
        rows = differs_E.nonzero()[:, 0]
        best = q_EA[rows, greedy_E[rows]]
        differs_E[rows] = best - q_EA[rows, actions_E[rows]] > relative * best.abs()
    return differs_E.cpu().numpy()


def without_staying(
    draws: dict[str, torch.Tensor], obs_B: torch.Tensor, next_obs_B: torch.Tensor
) -> dict[str, torch.Tensor]:
    """``blr.stay_optimism = False``: the targets' normals (``eps_BA``) zeroed in the rows whose
    window ends where it began (``next_obs_B`` equal to ``obs_B``), so their draw at s' is 0
    (the noise is the normal times a width, per row and action)."""
    if "eps_BA" not in draws:
        return draws
    moved_B1 = (obs_B != next_obs_B).flatten(1).any(dim=1, keepdim=True)
    return {**draws, "eps_BA": draws["eps_BA"] * moved_B1}


def cut_relative(cfg: Config) -> float:
    """``blr.cut_delay`` as a share of the greedy value: a step's delay costs (1 - gamma) V."""
    return cfg.blr.cut_delay * (1.0 - cfg.gamma)


def restart_at_switch(
    cfg: Config,
    head: BLRHead,
    target_mean_AD: torch.Tensor,
    rows: Callable[[], ReplayRows] | None = None,
) -> None:
    """``blr.switch_restart`` at the switch: the posterior back to its prior
    (:meth:`BLRHead.restart`, ``prior``), its rows kept without their targets
    (:meth:`BLRHead.forget_targets`, ``zero-targets``), or refitted to the replay's ``rows``
    by fitted Q-iteration from the prior (:func:`farsighter.ops.refit.refit`, ``refit``: each
    row weighs a step's ``data_weight``; from the prior alone where ``rows`` is None, a switch
    before the features were trained, or the fit rejected; ``refit-zero``: the rows kept
    without their targets in those cases instead); the targets' mean with it, so every value
    the optimism inflated starts again from what the rewards give."""
    mode = cfg.blr.switch_restart
    if mode == "none" or cfg.blr.mode != "incremental":
        return
    if mode == "zero-targets" or (mode == "refit-zero" and rows is None):
        head.forget_targets()
    elif mode in ("refit", "refit-zero") and rows is not None:  # (None: no features trained yet)
        kept = head.state_dict() if mode == "refit-zero" else None
        head.restart()
        fit = refit(head, rows(), cfg.blr.data_weight, count=cfg.batch_size / cfg.train_every)
        if kept is not None and not fit.accepted:  # the rows without their targets instead
            head.load_state_dict(kept)
            head.forget_targets()
    else:
        head.restart()
    target_mean_AD.copy_(head.mean_AD)


def switch_at(cfg: Config, calibrated: bool, reward_E: np.ndarray) -> bool:
    """Whether ``blr.optimism = until-reward`` switches the run (or seed) to calibrated targets
    at a step that pays ``reward_E``: its first positive reward while optimistic."""
    if cfg.blr.optimism != "until-reward" or calibrated:
        return False
    return bool(np.any(np.asarray(reward_E) > 0))


def records_exploratory(cfg: Config) -> bool:
    """Whether a run records which of its actions were exploratory: it cuts k-step windows
    before them (``k_target = cut``) now or after ``blr.optimism``'s switch."""
    return cfg.k_target == "cut" or (
        cfg.blr.optimism == "until-reward" and cfg.blr.calibrated_k_target == "cut"
    )
