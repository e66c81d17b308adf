"""How much of a new deep sea cell's random features no visited cell explains: why a fixed
width of random features caps how far the posterior's optimism reaches.

The defaults' posterior is over [learned features, psi(s)] with psi(s) = relu(W s + b) /
sqrt(width) (``farsighter.networks.RandomFeatureTorso``). On one-hot observations each cell's
psi is a random vector of ``width`` entries. A Bayesian linear head that has seen some cells
often keeps its prior width only along the part of a new cell's psi outside the span of the
visited cells' psi: the novel fraction ||P_perp psi_new||^2 / ||psi_new||^2. Once the visited
cells are as many as the width, that span is everything, and a new cell looks known before it
is visited. This script measures it for deep sea's frontier: the visited cells are the reachable
cells of the columns left of column c (cell (r, c') with c' <= r, c' < c) and the new cell is
(c, c), the first cell of column c, for c = 0.5, 0.75 and 0.9 of N. It also reports the
posterior standard deviation of Q at the new cell against that at the visited cells, for a
posterior whose prior and noise are 1 (the defaults' ratio) after ``--visits`` visits of each
visited cell.

Pure arithmetic on the library's own random feature layer (no training; seconds):

    python -m benchmarks.feature_novelty [--sizes 10 14 20 24 30 40] [--widths 512 1024 2048]
        [--kinds relu fourier]

Writes ``benchmarks/results/<name>.json``.
"""

from __future__ import annotations

import argparse
import itertools
from typing import Any

import numpy as np
import torch

from benchmarks.common import write_result

FRONTIERS = (0.5, 0.75, 0.9)


def deep_sea_psi(n: int, width: int, seed: int, kind: str = "relu") -> np.ndarray:
    """psi of every cell of deep sea N = ``n`` (rows: cells in row-major order), from the
    library's random feature layer of ``kind`` (``blr.random_features_kind``) as seed ``seed``
    draws it."""
    from farsighter.networks import MLPTorso, RandomFeatureTorso

    torch.manual_seed(seed)
    obs = n * n
    layer = RandomFeatureTorso(MLPTorso(obs, (8,)), obs, width, kind)  # type: ignore[arg-type]
    with torch.no_grad():
        return layer.random_features(torch.eye(obs)).double().numpy()


def novelty(psi_new: np.ndarray, psi_seen: np.ndarray, visits: int) -> dict[str, float]:
    """The novel fraction of ``psi_new`` (its squared norm outside the span of the rows of
    ``psi_seen``), and the posterior sd of Q at the new row against the mean at the seen rows,
    for prior N(0, I), unit noise and ``visits`` observations of each seen row."""
    basis, _ = np.linalg.qr(psi_seen.T)  # (width, rank) orthonormal basis of the seen span
    rest = psi_new - basis @ (basis.T @ psi_new)
    precision = visits * psi_seen.T @ psi_seen + np.eye(psi_seen.shape[1])
    cov = np.linalg.inv(precision)
    sd_new = float(np.sqrt(psi_new @ cov @ psi_new))
    sd_seen = float(np.sqrt(np.einsum("nd,de,ne->n", psi_seen, cov, psi_seen)).mean())
    return {
        "novel_fraction": float(rest @ rest / (psi_new @ psi_new)),
        "sd_new_over_seen": sd_new / sd_seen,
    }


def frontier_novelty(
    n: int, width: int, seed: int, visits: int, kind: str = "relu"
) -> dict[str, Any]:
    psi = deep_sea_psi(n, width, seed, kind)
    out: dict[str, Any] = {}
    for f in FRONTIERS:
        c = int(f * n)
        seen = [r * n + col for r in range(n) for col in range(min(r + 1, c))]
        out[str(f)] = {"column": c, "visited_cells": len(seen)} | novelty(
            psi[c * n + c], psi[seen], visits
        )
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[10, 14, 20, 24, 30, 40])
    p.add_argument("--widths", type=int, nargs="+", default=[256, 512, 1024, 2048])
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    p.add_argument("--visits", type=int, default=10)
    p.add_argument("--kinds", nargs="+", default=["relu"], choices=["relu", "fourier"])
    p.add_argument("--name", default="feature_novelty")
    a = p.parse_args()
    rows = []
    for n, width, kind in itertools.product(a.sizes, a.widths, a.kinds):
        per_seed = [frontier_novelty(n, width, s, a.visits, kind) for s in a.seeds]
        row: dict[str, Any] = {
            "size": n,
            "width": width,
            "kind": kind,
            "reachable_cells": n * (n + 1) // 2,
        }
        for f in FRONTIERS:
            key = str(f)
            row[key] = {
                "column": per_seed[0][key]["column"],
                "visited_cells": per_seed[0][key]["visited_cells"],
                **{
                    m: round(float(np.mean([r[key][m] for r in per_seed])), 4)
                    for m in ("novel_fraction", "sd_new_over_seen")
                },
            }
        rows.append(row)
        cells = "  ".join(
            f"c={row[str(f)]['column']:>2} ({row[str(f)]['visited_cells']:>3} seen): "
            f"novel {row[str(f)]['novel_fraction']:.3f}, sd x{row[str(f)]['sd_new_over_seen']:.2f}"
            for f in FRONTIERS
        )
        print(f"N={n:>2} width={width:>4} {kind:>7}  {cells}", flush=True)
    path = write_result(
        a.name, {"seeds": a.seeds, "visits": a.visits, "frontiers": FRONTIERS, "rows": rows}
    )
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
