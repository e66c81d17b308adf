"""The learner: one owner of the update's fast path for every value-based agent.

An agent hands the learner its loss, ``loss(inputs) -> {"loss": ..., *extras}`` on a dictionary of
tensors already on the device (the minibatch, and any random draws made beforehand), and the
parameters the loss trains. The learner owns what makes an update fast and nothing of its math:

* the optimizer (Table 1's RMSProp, or Adam: :func:`farsighter.agents.common.make_optimizer`),
  gradient clipping and the optimizer step;
* the step as a CUDA graph (``RuntimeConfig.cuda_graph``) or compiled
  (``RuntimeConfig.compile``), the optimizer made capturable for it, and the graphs dropped
  after a checkpoint load rebinds state (:mod:`farsighter.agents.cuda_graph`).

The loss follows the rules a captured step needs (no host synchronisation, no random numbers,
state updated in place); the agent draws what the loss needs before the call. Its checkpoint is
the optimizer's state dict, the form agents saved before the learner existed.

The target cache (:func:`make_target_cache`) lives beside it: whether a run keeps one depends on
whether its step runs eagerly.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Iterable
from typing import Any

import torch
from torch import nn

from farsighter.agents.common import clip_and_step, make_optimizer
from farsighter.agents.cuda_graph import (
    Tensors,
    graphs_enabled,
    reset_step,
    set_capturable,
    wrap_step,
)
from farsighter.config import Config
from farsighter.replay.target_cache import TargetCache, target_cache_rows
from farsighter.stacked import load_member_optimizer_state, member_optimizer_state

LossFn = Callable[[Tensors], Tensors]


class Learner:
    """Gradient steps of ``loss`` on ``params``: eager, a replayed CUDA graph, or compiled."""

    def __init__(
        self,
        loss: LossFn,
        params: Iterable[nn.Parameter],
        cfg: Config,
        device: torch.device,
        optimizer: torch.optim.Optimizer | None = None,
        max_grad_norm: float | None = None,
        eager: bool = False,
        capture: bool = True,
        seeds: int = 1,
    ) -> None:
        self.loss = loss
        self.params = list(params)
        self.seeds = seeds  # > 1: stacked parameters, each seed's gradients clipped on their own
        eager = eager or seeds > 1  # a seed batch's step runs eagerly (stack_refusal)
        self.opt = optimizer if optimizer is not None else make_optimizer(self.params, cfg)
        self.max_grad_norm = cfg.max_grad_norm if max_grad_norm is None else max_grad_norm
        # eager: a loss that reads the host (never captured or compiled, whatever the config);
        # capture False: a loss that switches its branch mid-run is compiled where asked
        # (torch.compile guards on the branch and compiles the new one) but never captured
        self.graphs = (
            not eager
            and capture
            and graphs_enabled(cfg.runtime.cuda_graph, device, not cfg.runtime.compile)
        )
        set_capturable(self.opt, self.graphs)
        self.step = wrap_step(self._update, self.graphs, cfg.runtime.compile and not eager)

    def _update(self, inputs: Tensors) -> Tensors:
        out = dict(self.loss(inputs))
        clip_and_step(out["loss"], self.params, self.opt, self.max_grad_norm, self.seeds)
        out["loss"] = out["loss"].detach()
        return out

    def __call__(self, inputs: Tensors) -> Tensors:
        """One update on ``inputs``; returns the loss and the loss's extras (detached). Under a
        CUDA graph the returned tensors are overwritten by the next update."""
        return self.step(inputs)

    def state_dict(self) -> dict[str, Any]:
        return self.opt.state_dict()

    def load_state_dict(self, state: dict[str, Any]) -> None:
        # torch keeps the given state tensors (no copy on the same device): copy them, so that
        # this learner never shares its optimizer state with the one that saved it
        self.opt.load_state_dict(copy.deepcopy(state))
        set_capturable(self.opt, self.graphs)  # a loaded state brings the saver's flags
        reset_step(self.step)  # the optimizer's state tensors are new ones

    def member_state(self, s: int) -> dict[str, Any]:
        """Seed ``s``'s optimizer state, in the layout of its optimizer alone."""
        return self.state_dict() if self.seeds == 1 else member_optimizer_state(self.opt, s)

    def load_member(self, s: int, state: dict[str, Any]) -> None:
        """Inverse of :meth:`member_state`."""
        if self.seeds == 1:
            self.load_state_dict(state)
        else:
            load_member_optimizer_state(self.opt, s, state)

    def forget_graphs(self) -> None:
        """Capture the update again at its next calls: the loss changed a branch its inputs do
        not show (a captured CUDA graph replays the branches taken at capture; eager and
        compiled steps need nothing)."""
        reset_step(self.step)


def make_target_cache(cfg: Config, device: torch.device, width: int) -> TargetCache | None:
    """The target cache a run gets: with ``target_cache auto``, where next states repeat within
    a target period (minibatches from the latest N transitions: ``sample_recent``), and when the
    step runs eagerly (a captured or compiled step runs the target network inside it)."""
    fast = cfg.runtime.compile or graphs_enabled(
        cfg.runtime.cuda_graph, device, not cfg.runtime.compile
    )
    if cfg.runtime.target_cache != "auto" or not cfg.sample_recent or fast:
        return None
    return TargetCache(cfg.num_envs, target_cache_rows(cfg), width, device)
