"""Process settings a training run makes before it starts: torch's CPU threads and the C heap.

**The heap.** glibc's ``malloc`` serves blocks above a threshold with ``mmap`` and gives them back
to the operating system on ``free``, and it trims the top of the heap once enough of it is free.
An update on the CPU allocates and frees the same few megabytes of activations and gradients
every time (torch keeps no cache of CPU memory), so the training loop kept faulting the same
pages in again: 180 to 290 minor page faults per environment step in fp32 and 710 to 850 with
bf16 on Breakout. :func:`keep_heap` raises both thresholds once (``mallopt``), so freed blocks
stay in the process and are reused: 1 to 2 faults per step, and Farsighter's steps/s on
Breakout (E = 1, 2 threads) went from 135.7 to 150.2 in fp32 and from 147.1 to 178.5 with bf16
(medians of three interleaved rounds, ``benchmarks/results/keep_heap_ab.json``). It changes no
result, only where freed memory waits; peak RSS with a 1M buffer stayed at 515 MB
(``atari_sps_memory.json``). Other C libraries (musl, macOS, Windows) are left alone.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys

import torch

MMAP_THRESHOLD = 64 << 20
"""Blocks up to this size (64 MiB) come from the heap and stay there when freed (the replay's
arrays, far larger, are still mapped on their own)."""
TRIM_THRESHOLD = 512 << 20
"""Free memory at the top of the heap kept before it is handed back (512 MiB)."""
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # glibc's malloc.h


def keep_heap() -> bool:
    """Keep freed memory in the process (glibc only; idempotent). True where it was applied."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # not glibc (musl has no mallopt)
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(
        mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD)
    )


def prepare_process(torch_threads: int) -> None:
    """What :func:`farsighter.train.train` sets before it builds the agent: torch's threads
    (``RuntimeConfig.torch_threads``; 0 leaves torch's default) and :func:`keep_heap`."""
    if torch_threads:
        torch.set_num_threads(torch_threads)
    keep_heap()
