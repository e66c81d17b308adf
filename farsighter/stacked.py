"""Networks with a seed axis: S independent MLP Q-networks computed as one.

Several seeds of one config train in one process (:mod:`farsighter.seeds`) by stacking their
networks' parameters along a leading seed axis S and running each layer as one batched matrix
product over all seeds. Each seed's slice is computed exactly as its own network would compute it
alone: :class:`StackedLinear` runs ``x W^T + b`` forward and its three gradients backward with the
same operand order as ``torch.nn.functional.linear`` and its autograd formula, so on CPU a seed's
outputs and gradients are bit-for-bit those of ``F.linear`` (checked for every layer shape of the
suite's networks in ``tests/test_seeds.py``).

A :class:`StackedQNetwork` is built from S :class:`farsighter.networks.QNetwork` s (each built
under its own seed, so the initial weights are each seed's own) and hands back any seed's weights
in ``QNetwork``'s ``state_dict`` layout, so a seed's checkpoint is the checkpoint its run alone
would write.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
from torch import nn

from farsighter.networks import MLPTorso, QNetwork


class StackedLinear(torch.autograd.Function):
    """``y[s] = x[s] W[s]^T + b[s]`` for each seed s; x (S, B, in), W (S, out, in), b (S, out).

    Backward gives ``dx = dy W``, ``dW = dy^T x`` and ``db = sum_B dy`` per seed: the products
    ``F.linear``'s own backward forms, in the same order (autograd's default for a batched
    product would form ``dW^T = x^T dy`` instead, whose rounding differs)."""

    # forward(ctx, ...) rather than forward + setup_context: with setup_context, every apply
    # binds its arguments through inspect.signature (tens of microseconds per layer).
    @staticmethod
    def forward(
        ctx: Any, x_SBI: torch.Tensor, w_SOI: torch.Tensor, b_SO: torch.Tensor
    ) -> torch.Tensor:  # type: ignore[override]
        ctx.save_for_backward(x_SBI, w_SOI)
        return torch.baddbmm(b_SO.unsqueeze(1), x_SBI, w_SOI.transpose(1, 2))

    @staticmethod
    def backward(ctx: Any, dy_SBO: torch.Tensor) -> tuple[torch.Tensor | None, ...]:  # type: ignore[override]
        x_SBI, w_SOI = ctx.saved_tensors
        dx = torch.bmm(dy_SBO, w_SOI) if ctx.needs_input_grad[0] else None
        dw = torch.bmm(dy_SBO.transpose(1, 2), x_SBI) if ctx.needs_input_grad[1] else None
        db = dy_SBO.sum(1) if ctx.needs_input_grad[2] else None
        return dx, dw, db


def stacked_linear(x_SBI: torch.Tensor, w_SOI: torch.Tensor, b_SO: torch.Tensor) -> torch.Tensor:
    """:class:`StackedLinear`; without autograd (acting, targets) its forward alone."""
    if torch.is_grad_enabled() and (w_SOI.requires_grad or x_SBI.requires_grad):
        return StackedLinear.apply(x_SBI, w_SOI, b_SO)  # type: ignore[no-any-return]
    return torch.baddbmm(b_SO.unsqueeze(1), x_SBI, w_SOI.transpose(1, 2))


def stackable(net: nn.Module) -> bool:
    """Whether :class:`StackedQNetwork` can stack this network: a QNetwork with an MLP torso in
    fp32 (the image torsos and bf16 autocast keep their own path)."""
    return (
        isinstance(net, QNetwork)
        and isinstance(net.torso, MLPTorso)
        and net.torso.precision == "fp32"
    )


class StackedQNetwork(nn.Module):
    """S QNetworks with MLP torsos, one parameter per layer with a leading seed axis.

    ``forward(obs_SB...)`` gives Q (S, B, A). Parameters are listed in ``QNetwork.parameters()``'s
    order (each layer's weight, then its bias; the head last), so an optimizer over them holds, at
    each index, the state of the same parameter of every seed."""

    def __init__(self, nets: Sequence[QNetwork]) -> None:
        super().__init__()
        if not nets or not all(stackable(net) for net in nets):
            raise ValueError("StackedQNetwork stacks QNetworks with fp32 MLP torsos")
        self.names = [name for name, _ in nets[0].named_parameters()]
        self.weights = nn.ParameterList(
            nn.Parameter(torch.stack([dict(net.named_parameters())[name].detach() for net in nets]))
            for name in self.names
        )

    @property
    def seeds(self) -> int:
        return int(self.weights[0].shape[0])

    def forward(self, obs_SB: torch.Tensor, members: slice = slice(None)) -> torch.Tensor:
        """Q (S, B, A) of each seed on its own rows; ``members`` picks some seeds' networks
        (``obs_SB`` then holds their rows only)."""
        x = obs_SB.float().flatten(2)
        params = [p[members] for p in self.weights]
        layers = [(params[i], params[i + 1]) for i in range(0, len(params), 2)]
        for weight, bias in layers[:-1]:  # the torso: ReLU after each layer
            x = torch.relu(stacked_linear(x, weight, bias))
        weight, bias = layers[-1]  # the linear head
        return stacked_linear(x, weight, bias)

    def member_state(self, s: int) -> dict[str, torch.Tensor]:
        """Seed ``s``'s weights as its QNetwork's ``state_dict`` (copies)."""
        return {
            name: p[s].detach().clone() for name, p in zip(self.names, self.weights, strict=True)
        }

    def load_member(self, s: int, state: dict[str, torch.Tensor]) -> None:
        """Write a QNetwork ``state_dict`` into seed ``s``'s slices."""
        missing = set(self.names) ^ set(state)
        if missing:
            raise KeyError(f"a QNetwork state of another shape: keys {sorted(missing)} differ")
        with torch.no_grad():
            for name, p in zip(self.names, self.weights, strict=True):
                p[s].copy_(state[name])


def member_optimizer_state(opt: torch.optim.Optimizer, s: int) -> dict[str, Any]:
    """Seed ``s``'s part of an optimizer over stacked parameters, in the layout of the same
    optimizer over that seed's network alone: each per-element state tensor sliced at ``s``,
    scalars (Adam's step count) as they are."""
    full = opt.state_dict()
    state = {
        index: {
            key: (value[s].clone() if value.dim() > 0 else value.clone())
            if isinstance(value, torch.Tensor)
            else value
            for key, value in entry.items()
        }
        for index, entry in full["state"].items()
    }
    return {"state": state, "param_groups": full["param_groups"]}


def load_member_optimizer_state(opt: torch.optim.Optimizer, s: int, member: dict[str, Any]) -> None:
    """Write one seed's optimizer state (the layout of its network alone) into slice ``s``. The
    per-element tensors are written; a scalar (the step count) must equal the batch's, since the
    seeds of a batch update together (the loop groups seeds by where they resume)."""
    params = [p for group in opt.param_groups for p in group["params"]]
    for index, entry in member["state"].items():
        target = opt.state[params[int(index)]]
        for key, value in entry.items():
            if not isinstance(value, torch.Tensor):
                target[key] = value
            elif value.dim() == 0:
                if key in target and not torch.equal(target[key], value):
                    raise ValueError(f"seed {s}'s optimizer {key} {value} differs from the batch's")
                target[key] = value.clone()
            else:
                if key not in target:
                    target[key] = torch.zeros_like(params[int(index)])
                target[key][s].copy_(value)
