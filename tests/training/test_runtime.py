"""farsighter.runtime: the heap setting that keeps an update's freed memory in the process."""

from __future__ import annotations

import subprocess
import sys

import pytest

from farsighter.runtime import keep_heap

# Minor page faults per repetition of a workload in a fresh process, with glibc's thresholds
# ("default") or after keep_heap ("keep"): a 40 MiB array allocated and freed (above the largest
# threshold glibc picks by itself, so by default it is mapped and unmapped every time), and a
# Nature-CNN update of batch 32 (after 10 warm-up updates).
_PROBE = """
import resource, sys
import numpy as np
import torch
from farsighter.networks import NatureCNN
from farsighter.runtime import keep_heap
if sys.argv[1] == "keep":
    assert keep_heap()
def faults():
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt
def per_call(fn, n=10):
    fn()
    f0 = faults()
    for _ in range(n):
        fn()
    return (faults() - f0) / n
def big_array():
    a = np.ones(40 << 17)
    del a
torch.set_num_threads(2)
torch.manual_seed(0)
net = NatureCNN(4)
opt = torch.optim.RMSprop(net.parameters(), lr=1e-4, centered=True)
obs = torch.randint(0, 256, (32, 4, 84, 84), dtype=torch.uint8)
def update():
    loss = net(obs).square().mean()
    opt.zero_grad(set_to_none=True)
    loss.backward()
    opt.step()
for _ in range(10):
    update()
print(per_call(big_array), per_call(update))
"""


def _faults(heap: str) -> tuple[float, float]:
    out = subprocess.run(
        [sys.executable, "-c", _PROBE, heap], capture_output=True, text=True, check=True
    )
    array, update = out.stdout.strip().splitlines()[-1].split()
    return float(array), float(update)


@pytest.mark.skipif(not keep_heap(), reason="keep_heap needs glibc's mallopt (Linux)")
def test_keep_heap_stops_page_faults_of_repeated_allocations() -> None:
    default_array, default_update = _faults("default")
    kept_array, kept_update = _faults("keep")
    assert default_array > 100, default_array  # glibc maps and unmaps it every time
    assert kept_array < 0.1 * default_array, (kept_array, default_array)
    # glibc's own thresholds adapt with the allocation history, so an update's faults without
    # keep_heap vary between runs (0 to a few hundred); with it they stay near zero.
    assert kept_update < 5, (kept_update, default_update)


def test_keep_heap_is_idempotent() -> None:
    assert keep_heap() == keep_heap()
