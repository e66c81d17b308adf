"""What the posterior's own arithmetic costs per environment step, at the defaults' widths.

Issue #27 asks Farsighter to run CartPole at CleanRL DQN's speed. Its posterior is a Bayesian
linear regression per action over d features (the torso's last layer and, with the ``general``
preset, ``blr.random_features`` fixed random features: d = 84 + 512 = 596 with CleanRL's 120 x 84
network, 128 + 512 = 640 with the preset's own, 128 + 900 = 1,028 on deep sea N = 30, whose
900-entry observation widens the random layer). Its work per environment step is set by d alone:

* ``accumulate``: an update's minibatch added to the float64 statistics, B d^2 per update;
* ``refresh``: the Eq. 9 posterior from them every ``blr.posterior_every`` steps, a Cholesky
  factor and a triangular inverse per action, A d^3 (the float64 sums and factors are kept
  exact on purpose: see docs/design.md "The posterior's arithmetic is the floor");
* ``q_noise``: the targets' posterior noise ||U_a^T phi(s')|| for every row and action, B A d^2
  per target, two targets an update with ``k_target = max`` (the k-step and the one-step). The
  defaults pay it until the run's first positive reward only (then the targets are the
  posterior mean's: ``blr.switch``), so CartPole, rewarded from its first step, never does;
* ``draw``: an acting draw w = mean + U z, A d^2, every k steps (``blr.redraw = k``).

Each kernel is timed on a head filled with ReLU features like a run's, with the library's own
functions, one torch thread; the per-step figure is their sum at a config's rates (with the
targets' noise: ``until_first_reward_``), and ``max_steps_per_s`` what a loop doing nothing else
could reach. ``float32_gram`` measures what float32 minibatch products would do to the float64
statistics (kept: docs/design.md).

    python -m benchmarks.posterior_cost [--name posterior_cost]
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import torch

from benchmarks.common import write_result
from farsighter.ops.blr import BLRHead

# (name, d, actions, batch, train_every, posterior_every, k): the rates of the runs measured
CASES = (
    ("CartPole, CleanRL dqn.py's settings (120 x 84) + 512 random", 596, 2, 128, 10, 100, 10),
    ("CartPole, general preset (128 x 128) + 512 random", 640, 2, 64, 4, 100, 10),
    ("deep sea N = 20, defaults", 640, 2, 64, 4, 100, 10),
    ("deep sea N = 30, defaults (900 random)", 1028, 2, 64, 4, 100, 10),
    ("MiniGrid, defaults (7 actions)", 640, 7, 64, 4, 100, 10),
)


def _time_ms(fn: Any, repeats: int) -> float:
    fn()
    best = float("inf")
    for _ in range(3):  # the best of three means: the machine's own noise taken out
        start = time.perf_counter()
        for _ in range(repeats):
            fn()
        best = min(best, (time.perf_counter() - start) / repeats)
    return 1e3 * best


def measure(d: int, actions: int, batch: int) -> dict[str, float]:
    """Milliseconds per call of each kernel at width d."""
    gen = torch.Generator().manual_seed(0)
    head = BLRHead(num_actions=actions, dim=d, prior_std=1.0, noise_std=1.0, scale="residual")

    def minibatch() -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        phi = torch.relu(torch.randn(batch, d, generator=gen))
        return phi, torch.randint(0, actions, (batch,), generator=gen), torch.randn(batch)

    for _ in range(50):  # statistics of some thousands of rows, as a run's
        head.accumulate(*minibatch())
    head.refresh()
    phi, a, y = minibatch()
    eps = torch.randn(batch, actions, generator=gen)
    return {
        "accumulate_ms": _time_ms(lambda: head.accumulate(phi, a, y), 20),
        "refresh_ms": _time_ms(head.refresh, 3),
        "q_noise_ms": _time_ms(lambda: head.q_noise_rows(phi, eps), 20),
        "draw_ms": _time_ms(lambda: head.sample_weights(1, generator=gen), 20),
    }


def float32_gram_error(d: int = 596, rows: int = 64, updates: int = 10_000) -> dict[str, Any]:
    """What float32 minibatch products would cost the statistics: ``updates`` minibatches of ReLU
    rows scaled by the defaults' data weight (100 x 10 / 128 at CleanRL's rates), each x^T x
    formed in float32 and summed in float64, against the float64 products; the error's spectral
    norm (the prior's ridge is 1 in these units) and the two products' times."""
    gen = torch.Generator().manual_seed(0)
    root_w = (100 * 10 / 128) ** 0.5
    exact = torch.zeros(d, d, dtype=torch.float64)
    mixed = torch.zeros(d, d, dtype=torch.float64)
    for _ in range(updates):
        x = torch.relu(torch.randn(rows, d, generator=gen)) * root_w
        x64 = x.double()
        exact.addmm_(x64.T, x64)
        mixed += (x.T @ x).double()
    x = torch.relu(torch.randn(rows, d, generator=gen))
    x64 = x.double()
    return {
        "d": d,
        "rows": rows,
        "updates": updates,
        "error_spectral_norm": torch.linalg.matrix_norm(mixed - exact, ord=2).item(),
        "largest_entry": exact.abs().max().item(),
        "float64_product_ms": round(_time_ms(lambda: exact.addmm_(x64.T, x64), 50), 3),
        "float32_product_ms": round(_time_ms(lambda: x.T @ x, 50), 3),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--name", default="posterior_cost", help="results file name")
    args = parser.parse_args()
    torch.set_num_threads(1)
    rows = []
    for name, d, actions, batch, train_every, every, k in CASES:
        ms = measure(d, actions, batch)
        per_step_us = 1e3 * (
            ms["accumulate_ms"] / train_every + ms["refresh_ms"] / every + ms["draw_ms"] / k
        )
        noise_us = 1e3 * 2 * ms["q_noise_ms"] / train_every
        rows.append(
            {
                "case": name,
                "d": d,
                "actions": actions,
                "batch": batch,
                "train_every": train_every,
                "posterior_every": every,
                "k": k,
                **{key: round(value, 3) for key, value in ms.items()},
                "posterior_us_per_step": round(per_step_us, 1),
                "max_steps_per_s": round(1e6 / per_step_us),
                "until_first_reward_us_per_step": round(per_step_us + noise_us, 1),
                "until_first_reward_max_steps_per_s": round(1e6 / (per_step_us + noise_us)),
            }
        )
        print(rows[-1], flush=True)
    gram = float32_gram_error()
    print(gram, flush=True)
    write_result(args.name, {"threads": 1, "cases": rows, "float32_gram": gram})


if __name__ == "__main__":
    main()
