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
which needs only x). ``tests/ops/test_onehot.py`` checks the results equal ``F.linear`` bit for bit.
"""

from __future__ import annotations

import torch

MIN_WORK = 1 << 16
"""Rows x inputs x outputs below which the product is cheaper than checking for one-hot rows
(one acting row through a 400 x 128 layer: a few microseconds either way)."""


def worth_gathering(x: torch.Tensor, weight: torch.Tensor) -> bool:
    """Whether ``x`` (..., in) through ``weight`` (..., out, in) may take the gather: float32 on
    CPU outside autocast, with enough work (:data:`MIN_WORK`) to pay for the check, and not
    inside a step being compiled (its checks read values, which would break the compiled graph
    in pieces; Inductor makes the product its own kernel there)."""
    return (
        not torch.compiler.is_compiling()
        and x.device.type == "cpu"
        and x.dtype == torch.float32
        and weight.dtype == torch.float32
        and not torch.is_autocast_enabled("cpu")
        and x.numel() * weight.shape[-2] >= MIN_WORK
    )


def hot_rows(x: torch.Tensor, *weights: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor] | None:
    """:func:`one_hot_rows` of ``x`` when gathering pays for a layer of any of ``weights``
    (:func:`worth_gathering`); None without the check otherwise."""
    if any(worth_gathering(x, w) for w in weights):
        return one_hot_rows(x)
    return None


ONE_BITS = 0x3F800000
"""The bits of float32 1.0 read as an int32."""


def one_hot_rows(x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor] | None:
    """``(index, value)`` of each row of ``x`` (..., in) when every row holds at most one
    nonzero and it is exactly 1.0: the column of that 1 (0 for a zero row) and the row's value
    (1.0, or 0.0 for a zero row), both shaped ``x.shape[:-1]``; else None.

    Made of sums, each a fast pass (count_nonzero and argmax take ten times as long on CPU):

    * no entry has its sign bit set (the bits read as int32 are all >= 0; so no negative
      number and no -0.0), and every row's float sum is 0 or 1 (NaN and inf fail here);
    * every row's bits, summed as integers, are 0 or those of 1.0. Two or more positive
      entries whose float sum rounds to 1 have bits summing to far more (bits grow as
      2^23 (127 + log2 v): an entry of at least 1/n and another of at least 1/(2n) give
      (253 - 2 log2 n) 2^23 > 127 x 2^23), and a zero row's sum 0 admits only +0.0;
    * the index is sum_i i x_i, exact in float32 for fewer than 2^24 columns."""
    if x.shape[-1] >= 1 << 24:
        return None
    bits = x.view(torch.int32)
    if int(bits.min()) < 0:  # a sign bit
        return None
    total = x.sum(-1)
    if not bool(((total == 1) | (total == 0)).all()):
        return None
    bit_sum = bits.sum(-1)
    if not bool(((bit_sum == ONE_BITS) | (bit_sum == 0)).all()):
        return None
    columns = torch.arange(x.shape[-1], dtype=x.dtype, device=x.device)
    return (x @ columns).long(), total


def gathered_linear(
    hot: tuple[torch.Tensor, torch.Tensor], weight: torch.Tensor, bias: torch.Tensor
) -> torch.Tensor:
    """``F.linear(x, weight, bias)`` for the rows ``hot`` = :func:`one_hot_rows` (x), (B, out)."""
    index_B, value_B = hot
    columns_BO = weight.t().index_select(0, index_B)  # contiguous, as F.linear's result
    # b + v W[:, j]: v is 1 (exactly b + W[:, j]) or 0 (a zero row: b)
    return torch.addcmul(bias, value_B.unsqueeze(1), columns_BO)


def stacked_gathered_linear(
    hot: tuple[torch.Tensor, torch.Tensor], weight_SOI: torch.Tensor, bias_SO: torch.Tensor
) -> torch.Tensor:
    """Each seed's ``F.linear`` (:func:`farsighter.stacked.stacked_linear`) for its rows
    ``hot`` = :func:`one_hot_rows` (x_SBI), (S, B, out)."""
    index_SB, value_SB = hot
    S, B = index_SB.shape
    out = weight_SOI.shape[1]
    # W[s, :, j] for each row: gathered along the contiguous input axis, then laid out (S, B, O)
    # contiguous, as the product's result
    columns_SOB = torch.gather(weight_SOI, 2, index_SB.unsqueeze(1).expand(S, out, B))
    result = torch.empty(S, B, out, dtype=weight_SOI.dtype, device=weight_SOI.device)
    return torch.addcmul(
        bias_SO.unsqueeze(1), value_SB.unsqueeze(2), columns_SOB.transpose(1, 2), out=result
    )
