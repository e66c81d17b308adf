"""A linear layer on one-hot observations as a row gather, bit for bit the matrix product.

Tabular tasks reach the networks as one-hot vectors: deep sea's N x N grid, the chain's and
FrozenLake's state index. For such a row x = e_j, ``x W^T + b`` is ``b + W[:, j]``: every other
term of the product is an exact zero, so whatever order a gemm sums in, each output is the one
rounding fl(b_i + W_ij) (a zero row gives b). Gathering the column costs O(out) a row where the
product costs O(in x out): on deep sea N = 20 (400 inputs) the first layer and the random
features of a minibatch cost a gemm of 400 times the work.

:func:`one_hot_rows` recognises such input (CPU, float32, every row one exact 1.0 or all zero);
:func:`gathered_linear` and :func:`stacked_gathered_linear` compute the layer from it. Callers
use them only where the product's work is worth the check (:data:`MIN_WORK`) and where no
gradient flows through this product's autograd (the seed-stacked layer keeps its own backward,
which needs only x). ``tests/test_onehot.py`` checks the results equal ``F.linear`` bit for bit.
"""

from __future__ import annotations

import torch

MIN_WORK = 1 << 16
"""Rows x inputs x outputs below which the product is cheaper than checking for one-hot rows
(one acting row through a 400 x 128 layer: a few microseconds either way)."""


def worth_gathering(x: torch.Tensor, weight: torch.Tensor) -> bool:
    """Whether ``x`` (..., in) through ``weight`` (..., out, in) may take the gather: float32 on
    CPU outside autocast, with enough work (:data:`MIN_WORK`) to pay for the check."""
    return (
        x.device.type == "cpu"
        and x.dtype == torch.float32
        and weight.dtype == torch.float32
        and not torch.is_autocast_enabled("cpu")
        and x.numel() * weight.shape[-2] >= MIN_WORK
    )


def one_hot_rows(x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor] | None:
    """``(index, value)`` of each row of ``x`` (..., in) when every row holds at most one
    nonzero and it is exactly 1.0: the column of that 1 (0 for a zero row) and the row's value
    (1.0, or 0.0 for a zero row), both shaped ``x.shape[:-1]``; else None."""
    total = x.sum(-1)  # with at most one nonzero, exactly that entry (or 0)
    if not bool(((total == 1) | (total == 0)).all()):
        return None
    if not bool((torch.count_nonzero(x, dim=-1) <= 1).all()):
        return None
    return x.argmax(-1), total


def gathered_linear(
    hot: tuple[torch.Tensor, torch.Tensor], weight: torch.Tensor, bias: torch.Tensor
) -> torch.Tensor:
    """``F.linear(x, weight, bias)`` for the rows ``hot`` = :func:`one_hot_rows` (x), (B, out)."""
    index_B, value_B = hot
    columns_BO = weight.t().index_select(0, index_B)  # contiguous, as F.linear's result
    if bool((value_B == 1).all()):
        return bias + columns_BO
    return torch.addcmul(bias, value_B.unsqueeze(1), columns_BO)


def stacked_gathered_linear(
    hot: tuple[torch.Tensor, torch.Tensor], weight_SOI: torch.Tensor, bias_SO: torch.Tensor
) -> torch.Tensor:
    """Each seed's ``F.linear`` (:func:`farsighter.stacked.stacked_linear`) for its rows
    ``hot`` = :func:`one_hot_rows` (x_SBI), (S, B, out)."""
    index_SB, value_SB = hot
    S, B = index_SB.shape
    out = weight_SOI.shape[1]
    columns_SBO = torch.gather(  # contiguous, as the product's result
        weight_SOI.transpose(1, 2), 1, index_SB.unsqueeze(2).expand(S, B, out)
    )
    if bool((value_SB == 1).all()):
        return bias_SO.unsqueeze(1) + columns_SBO
    return torch.addcmul(bias_SO.unsqueeze(1), value_SB.unsqueeze(2), columns_SBO)
