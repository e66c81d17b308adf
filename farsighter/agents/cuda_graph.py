"""The update step as a CUDA graph: captured once, replayed every update.

A Double-DQN update on a batch of 32 Atari frames launches about 150 small kernels (convolutions
forward and backward for s and twice for s', the loss, gradient clipping, RMSProp). On a GPU each
launch costs the host a few microseconds of Python and driver work, which adds up to about 3 ms
per update on an H100 while the GPU computes for a fraction of that (benchmarks/results/
update_profile_gpu.json): the update is bound by the host, not the device. A CUDA graph records
the kernels of one update once and replays them with a single launch.

:class:`GraphedStep` wraps an agent's step function ``fn(inputs) -> outputs`` (dictionaries of
tensors; forward, loss, backward and optimizer step inside). Per input signature (names, shapes
and dtypes) it runs ``warmup`` real updates eagerly on a side stream (cuDNN picks its algorithms,
the optimizer creates its state), then captures the next call and replays it for that call and
every later one: the inputs are copied into the graph's static input tensors, and the outputs are
the graph's static output tensors, overwritten by the next replay. Every call is a real update on
its own batch, so a graphed run makes the same updates as an eager one.

What a captured step may do (the agents that use it keep to this, and tests check the parts that
do not need a GPU): read parameters, buffers and other tensors that are only ever updated in place
(a target copy through ``load_state_dict`` is; rebinding an attribute to a new tensor is not, and
:meth:`GraphedStep.reset` must follow it); use an optimizer made with ``capturable=True``
(:func:`set_capturable`); no host synchronisation (``.item()``, ``.cpu()``), no data-dependent
Python control flow and no random numbers inside.

**Compiled instead** (``RuntimeConfig.compile``; measured and tested on CPU only): :func:`wrap_step`
hands the same step function to ``torch.compile``. Dynamo compiles the forward, target and loss
with their backward as one graph and the gradient clip with the optimizer step as others (the
``zero_grad`` and ``backward()`` calls between them break the graph), and Inductor fuses their
element-wise work (on CPU into C++ loops; the convolutions stay oneDNN's). The rules above keep
it from recompiling: tensors updated in place, draws made outside. The first update of each
input signature compiles (about 20 s on a 2-core CPU; Inductor caches the kernels on disk). A
second agent in the same process compiles its own guards again (quickly, from the cache). Every
agent's step is the one function of :class:`farsighter.agents.learner.Learner`, and torch
recompiles one function at most ``torch._dynamo.config.recompile_limit`` times per process
before it runs it eagerly: a compiled run raises that limit from torch's 8 to
:data:`RECOMPILE_LIMIT` (64), so a process that builds compiled agents in turn (a study with
``--workers 1``) keeps its first 64 compiled. Graphs and compilation are not combined.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from typing import cast

import torch

from farsighter.errors import ConfigError

Tensors = dict[str, torch.Tensor]
Signature = tuple[tuple[str, tuple[int, ...], torch.dtype], ...]


def _signature(inputs: Tensors) -> Signature:
    return tuple((k, tuple(v.shape), v.dtype) for k, v in sorted(inputs.items()))


class _Captured:
    def __init__(self) -> None:
        self.graph: torch.cuda.CUDAGraph | None = None
        self.inputs: Tensors = {}
        self.outputs: Tensors = {}
        self.warmups = 0


class GraphedStep:
    """``fn`` run eagerly ``warmup`` times per input signature, then as a replayed CUDA graph."""

    def __init__(self, fn: Callable[[Tensors], Tensors], warmup: int = 3) -> None:
        if warmup < 1:
            raise ValueError(f"warmup must be >= 1 (got {warmup})")
        self.fn = fn
        self.warmup = warmup
        self._by_signature: dict[Signature, _Captured] = {}
        self.captures = 0  # graphs captured (one per signature, again after reset)
        self.replays = 0  # calls served by a graph replay

    def __call__(self, inputs: Tensors) -> Tensors:
        entry = self._by_signature.setdefault(_signature(inputs), _Captured())
        if entry.graph is None and entry.warmups < self.warmup:
            entry.warmups += 1
            side = torch.cuda.Stream()
            side.wait_stream(torch.cuda.current_stream())
            with torch.cuda.stream(side):
                out = self.fn(inputs)
            torch.cuda.current_stream().wait_stream(side)
            return out
        if entry.graph is None:
            entry.inputs = {k: v.clone() for k, v in inputs.items()}
            entry.graph = torch.cuda.CUDAGraph()
            with torch.cuda.graph(entry.graph):
                entry.outputs = self.fn(entry.inputs)
            self.captures += 1
        else:  # the capture above recorded this batch already; a replay copies in the next one
            for name, value in inputs.items():
                entry.inputs[name].copy_(value, non_blocking=True)
        entry.graph.replay()  # capturing runs nothing: the first replay makes this update
        self.replays += 1
        return entry.outputs

    def reset(self) -> None:
        """Forget every graph (after state the graphs read was rebound, e.g. a checkpoint load):
        the next calls warm up and capture again."""
        self._by_signature.clear()


StepFn = Callable[[Tensors], Tensors]

RECOMPILE_LIMIT = 64
"""Compilations of the learner's step one process keeps (torch's default is 8 per function)."""


def wrap_step(fn: StepFn, graphs: bool, compiled: bool = False) -> StepFn:
    """``fn`` compiled by ``torch.compile`` when ``compiled`` (``RuntimeConfig.compile``), as a
    :class:`GraphedStep` when ``graphs``, else ``fn`` itself (eager)."""
    if compiled:  # static shapes: a new batch shape compiles anew rather than going symbolic
        # Every agent's step is the one learner's function, and each agent built in a process
        # compiles its own guards for it (its optimizer and networks are other objects): allow
        # many, so that a process building compiled agents in turn keeps them compiled.
        limit = torch._dynamo.config.recompile_limit
        torch._dynamo.config.recompile_limit = max(limit, RECOMPILE_LIMIT)
        return cast(StepFn, torch.compile(fn, dynamic=False))
    return GraphedStep(fn) if graphs else fn


def check_compiler(compiled: bool, device: torch.device | str) -> None:
    """``RuntimeConfig.compile`` on a CPU needs a C++ compiler for Inductor's kernels: refused up front
    (ConfigError) rather than at the first update."""
    if compiled and torch.device(device).type == "cpu" and not _cxx():
        raise ConfigError(
            "compile on a CPU needs a C++ compiler on PATH (g++, clang++ or c++); install one "
            "or drop --compile"
        )


def _cxx() -> str | None:
    return shutil.which("g++") or shutil.which("clang++") or shutil.which("c++")


def reset_step(step: StepFn) -> None:
    """Drop the graphs of a step made by :func:`wrap_step` (nothing to do for an eager one)."""
    if isinstance(step, GraphedStep):
        step.reset()


def graphs_enabled(setting: str, device: torch.device | str, supported: bool = True) -> bool:
    """Whether an agent captures its update: ``on`` always (the config check refused it where the
    update does not allow it), ``auto`` on CUDA when the update allows it, ``off`` never. A
    ``cuda_graph on`` run on a device other than CUDA is refused (ConfigError)."""
    device = torch.device(device)
    if setting == "on" and device.type != "cuda":
        raise ConfigError(
            f"cuda_graph on needs a CUDA device (the run is on {device}); use auto or off"
        )
    if setting == "off":
        return False
    return setting == "on" or (device.type == "cuda" and supported)


def set_capturable(opt: torch.optim.Optimizer, on: bool) -> None:
    """Make ``opt`` safe to capture (its step counters live on the parameters' device) or back to
    the default. Call it after building the optimizer and after loading its state, since a loaded
    state brings the param groups (and the ``capturable`` flag) of the run that saved it."""
    for group in opt.param_groups:
        if "capturable" not in group:
            continue
        group["capturable"] = on
        for p in group["params"]:
            state = opt.state.get(p)
            if state and torch.is_tensor(state.get("step")):
                step = state["step"]
                state["step"] = step.to(device=p.device if on else "cpu", dtype=torch.float32)
