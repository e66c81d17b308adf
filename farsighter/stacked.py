"""Networks with a seed axis: S independent MLP Q-networks computed as one.

Several seeds of one config train in one process (:mod:`farsighter.seeds`) by stacking their
networks' parameters along a leading seed axis S and running each layer as one batched matrix
product over all seeds. Each seed's slice is computed exactly as its own network would compute it
alone: :class:`StackedLinear` runs ``x W^T + b`` forward and its three gradients backward with the
same operand order as ``torch.nn.functional.linear`` and its autograd formula, and products too
small for gemm go through ``F.linear`` seed by seed (:data:`SMALL_PRODUCT`), so on CPU a seed's
outputs and gradients are bit-for-bit those of ``F.linear`` (checked over a grid of layer shapes
in ``tests/training/test_seeds.py``).

A :class:`StackedQNetwork` is built from S :class:`farsighter.networks.QNetwork` s (each built
under its own seed, so the initial weights are each seed's own) and hands back any seed's weights
in ``QNetwork``'s ``state_dict`` layout, so a seed's checkpoint is the checkpoint its run alone
would write.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, cast

import torch
import torch.nn.functional as F
from torch import nn

from farsighter.networks import (
    MLPTorso,
    QNetwork,
    RandomFeatureTorso,
    online_and_target,
    random_feature_map,
)
from farsighter.ops.onehot import hot_rows, stacked_gathered_linear

ALIGN = 16
"""Floats (64 bytes) that every seed's slice starts at a multiple of. A tensor alone starts at an
address aligned so (torch's CPU allocator), and a small gemm's rounding depends on where its
operands start: seed s's slice of a plain (S, ...) tensor starts wherever s times its size puts
it, and its products round otherwise than the same matrix alone."""


def _strides(shape: Sequence[int]) -> tuple[int, ...]:
    """Row-major strides of ``shape``."""
    out, step = [], 1
    for size in reversed(shape):
        out.append(step)
        step *= size
    return tuple(reversed(out))


def aligned_empty(shape: Sequence[int], like: torch.Tensor) -> torch.Tensor:
    """An uninitialised (S, ...) tensor whose seed slices are each contiguous and start on an
    :data:`ALIGN` boundary (a padded seed stride)."""
    S, *rest = shape
    inner = _strides(rest)
    size = inner[0] * rest[0] if rest else 1
    stride = -(-size // ALIGN) * ALIGN
    buf = torch.empty(S * stride + ALIGN, dtype=like.dtype, device=like.device)
    start = (-buf.data_ptr() // buf.element_size()) % ALIGN if buf.device.type == "cpu" else 0
    return buf.as_strided((S, *rest), (stride, *inner), start)


def aligned(t: torch.Tensor) -> torch.Tensor:
    """``t`` when each seed's slice is contiguous and starts on an :data:`ALIGN` boundary, else a
    copy laid out so (CPU only: elsewhere ``t``)."""
    if t.is_cuda:
        return t
    shape, strides = t.shape, t.stride()
    ok = strides[0] % ALIGN == 0 and (t.data_ptr() // t.element_size()) % ALIGN == 0
    if ok:
        step = 1
        for i in range(len(shape) - 1, 0, -1):  # each slice contiguous (size-1 axes any stride)
            if shape[i] != 1 and strides[i] != step:
                ok = False
                break
            step *= shape[i]
    if ok:
        return t
    out = aligned_empty(t.shape, t)
    out.copy_(t)
    return out


class StackedLinear(torch.autograd.Function):
    """``y[s] = x[s] W[s]^T + b[s]`` for each seed s; x (S, B, in), W (S, out, in), b (S, out).

    Backward gives ``dx = dy W``, ``dW = dy^T x`` and ``db = sum_B dy`` per seed: the products
    ``F.linear``'s own backward forms, in the same order (autograd's default for a batched
    product would form ``dW^T = x^T dy`` instead, whose rounding differs)."""

    # forward(ctx, ...) rather than forward + setup_context: with setup_context, every apply
    # binds its arguments through inspect.signature (tens of microseconds per layer).
    @staticmethod
    def forward(
        ctx: Any,
        x_SBI: torch.Tensor,
        w_SOI: torch.Tensor,
        b_SO: torch.Tensor,
        hot: tuple[torch.Tensor, torch.Tensor] | None = None,
    ) -> torch.Tensor:  # type: ignore[override]
        x_SBI, w_SOI = aligned(x_SBI), aligned(w_SOI)
        ctx.save_for_backward(x_SBI, w_SOI)
        if hot is not None:  # one-hot rows: the product's values by a gather (ops.onehot)
            return stacked_gathered_linear(hot, w_SOI, b_SO)
        return _affine(x_SBI, w_SOI, b_SO)

    @staticmethod
    def backward(ctx: Any, dy_SBO: torch.Tensor) -> tuple[torch.Tensor | None, ...]:  # type: ignore[override]
        x_SBI, w_SOI = ctx.saved_tensors
        dy_SBO = aligned(dy_SBO)
        dx = _product(dy_SBO, w_SOI) if ctx.needs_input_grad[0] else None
        dw = _product(dy_SBO.transpose(1, 2), x_SBI) if ctx.needs_input_grad[1] else None
        db = dy_SBO.sum(1) if ctx.needs_input_grad[2] else None
        return dx, dw, db, None


SMALL_PRODUCT = 400
"""On CPU, torch's batched product takes a plain loop kernel for matrices of fewer multiply-adds
than this (rows x inner x columns; ``baddbmm`` in ATen's LinearAlgebra.cpp), whose rounding
differs from the gemm that ``F.linear`` and larger batched products use."""


def stacked_linear(
    x_SBI: torch.Tensor,
    w_SOI: torch.Tensor,
    b_SO: torch.Tensor,
    hot: tuple[torch.Tensor, torch.Tensor] | None = None,
) -> torch.Tensor:
    """:class:`StackedLinear`; without autograd (acting, targets) its forward alone. A product
    below :data:`SMALL_PRODUCT` per seed (a small head acting on one observation) is ``F.linear``
    seed by seed, with autograd's own backward. ``hot``: :func:`farsighter.ops.onehot.one_hot_rows`
    of ``x_SBI`` when its rows are one-hot (the forward is then a gather, same values)."""
    rows, inner = x_SBI.shape[1], x_SBI.shape[2]
    if hot is not None:
        if torch.is_grad_enabled() and (w_SOI.requires_grad or x_SBI.requires_grad):
            return StackedLinear.apply(x_SBI, w_SOI, b_SO, hot)  # type: ignore[no-any-return]
        return stacked_gathered_linear(hot, w_SOI, b_SO)
    if rows * inner * w_SOI.shape[1] < SMALL_PRODUCT:
        x_SBI, w_SOI = aligned(x_SBI), aligned(w_SOI)  # each slice where a tensor alone starts
        slices = zip(x_SBI.unbind(0), w_SOI.unbind(0), b_SO.unbind(0), strict=True)
        return torch.stack([F.linear(x, w, b) for x, w, b in slices])
    if torch.is_grad_enabled() and (w_SOI.requires_grad or x_SBI.requires_grad):
        return StackedLinear.apply(x_SBI, w_SOI, b_SO)  # type: ignore[no-any-return]
    return _affine(aligned(x_SBI), aligned(w_SOI), b_SO)


UNIT_ROUNDOFF = 2.0**-24
"""float32's unit roundoff u: a sum of m products rounds, in any order, with or without fused
multiply-adds, within gamma_m = m u / (1 - m u) of the exact sum of their magnitudes."""
SMALLEST_NORMAL = 2.0**-126
"""float32's smallest normal number: the most a product or a sum loses when flushed to zero."""


def certain_argmax(
    h_SBI: torch.Tensor, w_SOI: torch.Tensor, b_SO: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """The argmax over outputs of ``h W^T + b`` per seed and row, as any float32 evaluation of
    it ranks them, and where that is certain, (S, B) each. Any evaluation of output o (the
    batched kernel's here, ``F.linear``'s alone) is within gamma_{I+1} (|h| |W_o| + |b_o|) of
    the exact value, so two differ by at most twice that, ``e_o``; the batched argmax o* is every
    evaluation's where ``q_o* - e_o* > q_o + e_o`` for every other o (a tie or a NaN is never
    certain). The bound is doubled again for the rounding of the bound's own product, and each
    of the I + 1 operations may add float32's smallest normal (a kernel that flushes subnormal
    results to zero)."""
    q = torch.baddbmm(b_SO.unsqueeze(1), h_SBI, w_SOI.transpose(1, 2))
    magnitude = torch.baddbmm(b_SO.abs().unsqueeze(1), h_SBI.abs(), w_SOI.abs().transpose(1, 2))
    m = h_SBI.shape[2] + 1
    e = magnitude.mul_(4 * m * UNIT_ROUNDOFF / (1 - m * UNIT_ROUNDOFF)).add_(
        4 * m * SMALLEST_NORMAL
    )
    top = q.argmax(dim=2, keepdim=True)
    low = q.gather(2, top) - e.gather(2, top)
    high = (q + e).scatter_(2, top, float("-inf"))
    return top.squeeze(2), (low > high.amax(dim=2, keepdim=True)).squeeze(2)


def _affine(x_SBI: torch.Tensor, w_SOI: torch.Tensor, b_SO: torch.Tensor) -> torch.Tensor:
    """``x W^T + b`` per seed (the bias first, then the product added), into an aligned result
    when its plain layout is aligned. Otherwise the result is plain (contiguous): on CPU a batched
    product into a padded layout takes a kernel several times slower for a few rows (an acting
    step's: 36 against 8 microseconds for 16 seeds of one row by 120), with the same rounding;
    a next layer aligns its input itself (:func:`stacked_linear`)."""
    S, rows, cols = x_SBI.shape[0], x_SBI.shape[1], w_SOI.shape[1]
    if (rows * cols) % ALIGN and x_SBI.device.type == "cpu":
        return torch.baddbmm(b_SO.unsqueeze(1), x_SBI, w_SOI.transpose(1, 2))
    out = aligned_empty((S, rows, cols), x_SBI)
    out.copy_(b_SO.unsqueeze(1).expand_as(out))
    return out.baddbmm_(x_SBI, w_SOI.transpose(1, 2))


def _product(a_SMK: torch.Tensor, b_SKN: torch.Tensor) -> torch.Tensor:
    """``a b`` per seed into an aligned result."""
    out = aligned_empty((a_SMK.shape[0], a_SMK.shape[1], b_SKN.shape[2]), a_SMK)
    return torch.bmm(a_SMK, b_SKN, out=out)


def stackable(net: nn.Module) -> bool:
    """Whether :class:`StackedQNetwork` can stack this network: a QNetwork with an MLP torso in
    fp32, or such a torso alone, bare or with fixed random features beside it
    (:class:`~farsighter.networks.RandomFeatureTorso`; the image torsos and bf16 autocast keep
    their own path)."""
    torso = net.torso if isinstance(net, QNetwork) else net
    if isinstance(torso, RandomFeatureTorso):  # a torso of the posterior's, never under a head
        if isinstance(net, QNetwork) or torso.precision != "fp32":
            return False
        torso = torso.torso
    return isinstance(torso, MLPTorso) and torso.precision == "fp32"


class StackedQNetwork(nn.Module):
    """S QNetworks with MLP torsos (or S MLP torsos), one parameter per layer with a leading
    seed axis.

    ``forward(obs_SB...)`` gives Q (S, B, A), or the features phi (S, B, D) of stacked torsos
    (a ReLU after every layer, the last included; random-feature torsos add each seed's own
    fixed psi(s) after them, stacked as buffers). Parameters are listed in the networks'
    ``parameters()`` order (each layer's weight, then its bias; the head last), so an optimizer
    over them holds, at each index, the state of the same parameter of every seed."""

    rf_weight: torch.Tensor
    rf_bias: torch.Tensor

    def __init__(self, nets: Sequence[nn.Module]) -> None:
        super().__init__()
        if not nets or not all(stackable(net) for net in nets):
            raise ValueError("StackedQNetwork stacks QNetworks with fp32 MLP torsos, or the torsos")
        first = nets[0]
        # a torso: features, no linear head
        self.relu_last = isinstance(first, MLPTorso | RandomFeatureTorso)
        self.rf_width = first.width if isinstance(first, RandomFeatureTorso) else 0
        self.buffer_names: list[str] = []
        if self.rf_width:  # each seed's random layer, drawn under its own seed (never trained)
            for name in ("rf_weight", "rf_bias"):
                self.register_buffer(name, stack_aligned([getattr(net, name) for net in nets]))
                self.buffer_names.append(name)
        self.names = [name for name, _ in nets[0].named_parameters()]
        self.weights = nn.ParameterList(
            nn.Parameter(
                stack_aligned([dict(net.named_parameters())[name].detach() for net in nets])
            )
            for name in self.names
        )
        self._params = list(self.weights)

    def _apply(self, fn: Any, recurse: bool = True) -> StackedQNetwork:
        super()._apply(fn, recurse)
        self._params = list(self.weights)  # a move may replace the tensors
        return self

    def forward(self, obs_SB: torch.Tensor, psi_SBW: torch.Tensor | None = None) -> torch.Tensor:
        """Q (S, B, A) (features (S, B, D) of torsos) of each seed on its own rows (one seed's
        network alone: :meth:`member_forward`). ``psi_SBW``: the random features of these rows
        when already computed (:meth:`psi`; an online torso and its target share them)."""
        inputs = obs_SB.float().flatten(2)
        # one check of the inputs for the first layer and the random layer (ops.onehot)
        wide = (self.rf_weight,) if self.rf_width and psi_SBW is None else ()
        hot = hot_rows(inputs, self._params[0], *wide)
        x = self._hidden(inputs, hot)
        weight, bias = self._params[-2:]  # the linear head, or the torso's last layer
        x = stacked_linear(x, weight, bias, hot if len(self._params) == 2 else None)
        relu = torch.relu if torch.is_grad_enabled() else torch.relu_  # in place: stays aligned
        if self.rf_width:  # RandomFeatureTorso.body: [learned features, psi(s)]
            psi = self.random_features(inputs, hot) if psi_SBW is None else psi_SBW
            return aligned(torch.cat([relu(x), psi], dim=2))
        # features: each seed's slice aligned as a tensor alone (the seeds' own products with
        # them round as the agent alone's do)
        return aligned(relu(x)) if self.relu_last else x

    def _hidden(
        self, x: torch.Tensor, hot: tuple[torch.Tensor, torch.Tensor] | None
    ) -> torch.Tensor:
        """The layers before the last, each a ReLU after its product (``x``: the flat inputs)."""
        relu = torch.relu if torch.is_grad_enabled() else torch.relu_  # in place: stays aligned
        params = self._params[:-2]
        for i, (weight, bias) in enumerate(zip(params[0::2], params[1::2], strict=True)):
            x = relu(stacked_linear(x, weight, bias, hot if i == 0 else None))
        return x

    @torch.no_grad()
    def greedy(self, obs: torch.Tensor) -> torch.Tensor:
        """argmax_a Q(s, a) of each seed's network on its rows of ``obs`` (laid seed after seed),
        (S * B,): the actions each network alone picks (:meth:`member_forward`, ties to the
        first). A head product too small for gemm (:data:`SMALL_PRODUCT`: one row by a
        narrow head, an acting step) is made for every seed at once in the batched kernel, whose
        rounding differs from ``F.linear``'s, and its argmax kept where it is certain
        (:func:`certain_argmax`); the seeds with an uncertain row take ``F.linear``, as
        :func:`stacked_linear` does. Off a CPU (CUDA may round a product in TF32) the
        forward itself."""
        weight, bias = self._params[-2:]
        obs_SB = self.by_seed(obs)
        rows, inner, A = obs_SB.shape[1], weight.shape[2], weight.shape[1]
        if self.relu_last or weight.device.type != "cpu" or rows * inner * A >= SMALL_PRODUCT:
            return self(obs_SB).argmax(dim=2).flatten()
        inputs = obs_SB.float().flatten(2)
        h = self._hidden(inputs, hot_rows(inputs, self._params[0]))
        actions_SB, sure_SB = certain_argmax(h, weight, bias)
        unsure = (~sure_SB).any(dim=1).nonzero().flatten().tolist()
        if unsure:
            h, weight = aligned(h), aligned(weight)  # as stacked_linear's seed-by-seed path
            for s in unsure:
                actions_SB[s] = F.linear(h[s], weight[s], bias[s]).argmax(dim=1)
        return actions_SB.flatten()

    def rows(self, obs: torch.Tensor) -> torch.Tensor:
        """:meth:`forward` on the seeds' rows laid end to end, seed 0's first: (S * B, ...) in,
        (S * B, ...) out (the layout of a seed-axis agent's minibatch)."""
        return self(self.by_seed(obs)).flatten(0, 1)

    @property
    def seeds(self) -> int:
        return int(self._params[0].shape[0])

    def by_seed(self, rows: torch.Tensor) -> torch.Tensor:
        """Rows laid seed after seed as (S, B, ...) (a view)."""
        return rows.view(self.seeds, -1, *rows.shape[1:])

    def each_seed(self, obs: torch.Tensor) -> list[torch.Tensor]:
        """Each seed's outputs on its rows of ``obs`` (laid seed after seed), one tensor a seed
        (slices of one forward: each seed's backward gives its slice's gradient alone, where
        indexing S times would give S zero-filled (S, B, D) gradients to add)."""
        return list(self(self.by_seed(obs)).unbind(0))

    def psi(self, obs_SB: torch.Tensor) -> torch.Tensor | None:
        """The random features of observations (None without a random layer), for
        :meth:`forward` of this network and of its target."""
        if not self.rf_width:
            return None
        x = obs_SB.float().flatten(2)
        return self.random_features(x, hot_rows(x, self.rf_weight))

    def random_features(
        self, x_SBO: torch.Tensor, hot: tuple[torch.Tensor, torch.Tensor] | None = None
    ) -> torch.Tensor:
        """Each seed's psi(s) on its own rows, (S, B, width)
        (:meth:`RandomFeatureTorso.random_features`, in place: nothing in it is trained).
        ``hot``: the rows' :func:`one_hot_rows`, when known."""
        with torch.no_grad():
            psi = stacked_linear(x_SBO, self.rf_weight, self.rf_bias, hot)
        return random_feature_map(psi, self.rf_width)

    def member_forward(self, obs_B: torch.Tensor, s: int) -> torch.Tensor:
        """Seed ``s``'s network alone on ``obs_B`` (B rows): the operations of its QNetwork or
        MLPTorso (``F.linear`` and ReLU per layer) on its slices of the weights."""
        x = obs_B.float().flatten(1)
        params = [p[s] for p in self._params]
        last = len(params) // 2 - 1
        inputs = x
        for i in range(0, len(params), 2):
            x = F.linear(x, params[i], params[i + 1])
            if i // 2 < last or self.relu_last:
                x = torch.relu(x)
        if self.rf_width:
            psi = F.linear(inputs, self.rf_weight[s], self.rf_bias[s])
            return torch.cat([x, random_feature_map(psi, self.rf_width)], dim=1)
        return x

    def member_state(self, s: int) -> dict[str, torch.Tensor]:
        """Seed ``s``'s weights as its QNetwork's (or torso's) ``state_dict`` (copies)."""
        state = {name: getattr(self, name)[s].clone() for name in self.buffer_names}
        for name, p in zip(self.names, self.weights, strict=True):
            state[name] = p[s].detach().clone()
        return state

    def load_member(self, s: int, state: dict[str, torch.Tensor]) -> None:
        """Write a QNetwork (or torso) ``state_dict`` into seed ``s``'s slices."""
        missing = set(self.names + self.buffer_names) ^ set(state)
        if missing:
            raise KeyError(f"a QNetwork state of another shape: keys {sorted(missing)} differ")
        with torch.no_grad():
            for name, p in zip(self.names, self.weights, strict=True):
                p[s].copy_(state[name])
            for name in self.buffer_names:
                getattr(self, name)[s].copy_(state[name])


class OneSeed(nn.Module):
    """One network as a seed axis of one: ``forward`` takes (1, B, ...) and gives (1, B, ...),
    through the network alone (any architecture or precision, compiled or captured), so that an
    agent written over the seed axis runs a single seed as the network alone runs it. Its
    ``member_*`` methods are :class:`StackedQNetwork`'s for seed 0."""

    def __init__(self, net: nn.Module) -> None:
        super().__init__()
        self.net = net

    def forward(self, obs_SB: torch.Tensor) -> torch.Tensor:
        return self.net(obs_SB[0]).unsqueeze(0)  # type: ignore[no-any-return]

    def rows(self, obs: torch.Tensor) -> torch.Tensor:
        """The network alone on the seed's rows (:meth:`StackedQNetwork.rows`): no seed axis
        to add or take away, so an update or an action costs what the network alone costs."""
        return self.net(obs)  # type: ignore[no-any-return]

    seeds = 1

    @torch.no_grad()
    def greedy(self, obs: torch.Tensor) -> torch.Tensor:
        """argmax_a Q(s, a) of the network alone on ``obs``, (B,)."""
        return self.net(obs).argmax(dim=1)  # type: ignore[no-any-return]

    def by_seed(self, rows: torch.Tensor) -> torch.Tensor:
        return rows.unsqueeze(0)

    def each_seed(self, obs: torch.Tensor) -> list[torch.Tensor]:
        return [self.net(obs)]

    def member_forward(self, obs_B: torch.Tensor, s: int) -> torch.Tensor:
        return self.net(obs_B)  # type: ignore[no-any-return]

    def member_state(self, s: int) -> dict[str, torch.Tensor]:
        return {name: t.clone() for name, t in self.net.state_dict().items()}

    def load_member(self, s: int, state: dict[str, torch.Tensor]) -> None:
        self.net.load_state_dict(state)


SeedNetwork = OneSeed | StackedQNetwork
"""A network with a seed axis (:func:`seed_network`)."""


def seed_network(nets: Sequence[nn.Module]) -> SeedNetwork:
    """S networks (each built under its own seed) as one with a seed axis: the network alone
    for one seed (:class:`OneSeed`), stacked for several (:class:`StackedQNetwork`, which
    refuses networks it cannot stack)."""
    return OneSeed(nets[0]) if len(nets) == 1 else StackedQNetwork(nets)


def online_and_target_seeds(
    online: SeedNetwork, target: SeedNetwork | None, obs: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor | None]:
    """Every seed's ``online`` and ``target`` (None: not computed) on its rows of ``obs`` (laid
    seed after seed), (S, B, ...) each: for one seed the networks alone, the observations
    prepared once (:func:`farsighter.networks.online_and_target`); for several one stacked
    forward each over the same random features (a random layer is never trained, so an online
    network and its target share it)."""
    if isinstance(online, OneSeed):
        if target is None:
            return online.net(obs).unsqueeze(0), None
        assert isinstance(target, OneSeed)
        pair = online_and_target(cast(Any, online.net), cast(Any, target.net), obs)
        return pair[0].unsqueeze(0), pair[1].unsqueeze(0)
    obs_SB = online.by_seed(obs)
    psi = online.psi(obs_SB)
    return online(obs_SB, psi), None if target is None else target(obs_SB, psi)


def member_pair(
    online: SeedNetwork, target: SeedNetwork, obs_B: torch.Tensor, s: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """Seed ``s``'s ``online`` and ``target`` networks alone on ``obs_B``."""
    if isinstance(online, OneSeed) and isinstance(target, OneSeed):
        return online_and_target(cast(Any, online.net), cast(Any, target.net), obs_B)
    return online.member_forward(obs_B, s), target.member_forward(obs_B, s)


def stack_aligned(tensors: Sequence[torch.Tensor]) -> torch.Tensor:
    """The tensors stacked along a new seed axis, each seed's slice aligned (:data:`ALIGN`)."""
    out = aligned_empty((len(tensors), *tensors[0].shape), tensors[0])
    with torch.no_grad():
        for s, t in enumerate(tensors):
            out[s].copy_(t)
    return out


def member_optimizer_state(opt: torch.optim.Optimizer, s: int) -> dict[str, Any]:
    """Seed ``s``'s part of an optimizer over stacked parameters, in the layout of the same
    optimizer over that seed's network alone: each per-element state tensor sliced at ``s``,
    scalars (Adam's step count) as they are."""
    full = opt.state_dict()
    state = {
        index: {
            key: (value[s] if value.dim() else value).clone()
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


def clip_per_seed(params: Sequence[torch.Tensor], seeds: int, max_norm: float) -> None:
    """Each seed's gradients clipped by its own total norm, as
    :func:`farsighter.agents.common.clip_gradients` clips them alone: the norm of each seed's
    slice of each gradient, their norm per seed, and a factor of 1 (exact) for the seeds under
    the limit."""
    grads = [p.grad for p in params if p.grad is not None]
    if not grads:
        return
    S = seeds
    norms = torch._foreach_norm([g[s] for s in range(S) for g in grads])
    total_S = torch.stack(
        [
            torch.linalg.vector_norm(torch.stack(norms[s * len(grads) : (s + 1) * len(grads)]))
            for s in range(S)
        ]
    )
    coef_S = max_norm / (total_S + 1e-6)
    coef_S = torch.where(coef_S < 1.0, coef_S, torch.ones_like(coef_S))
    torch._foreach_mul_(grads, [coef_S.view(S, *[1] * (g.dim() - 1)) for g in grads])
