"""Pool the rounds of several ``benchmarks.atari_sps`` result files (CPU, beside CleanRL).

Each round of ``atari_sps`` measures CleanRL's DQN first, then the configurations one after
another. This machine drifts by up to 10% within minutes, so rounds are pooled and two
statistics are given for each configuration: its median over all rounds against CleanRL's median
(the statistic each ``atari_sps`` file states), and the median of the per-round ratios (each
configuration against the CleanRL run of its own round).

    python -m benchmarks.pool_rounds atari_sps_s11 atari_sps_s11_r2 --name atari_sps_s11_pooled
"""

from __future__ import annotations

import argparse
import json
import statistics
from typing import Any

from benchmarks.common import RESULTS, write_result


def pool(files: list[str]) -> dict[str, Any]:
    cleanrl: list[float] = []
    runs: dict[str, list[tuple[float, float]]] = {}  # key -> (sps, CleanRL sps of its round)
    for name in files:
        data = json.loads((RESULTS / f"{name}.json").read_text())
        rounds = [c["sps"] for c in data["cleanrl"]]
        if not rounds:
            raise SystemExit(f"{name}: no CleanRL measurements to pool against")
        cleanrl += rounds
        for m in data["measurements"]:
            key = f"{m['algo']}_E{m['num_envs']}_{m['precision']}" + (
                "_compiled" if m.get("compile") else ""
            )
            runs.setdefault(key, []).append((m["sps"], rounds[m["round"] - 1]))
    base = statistics.median(cleanrl)
    table = {
        key: {
            "rounds": len(pairs),
            "sps": [sps for sps, _ in pairs],
            "median_sps": round(statistics.median(sps for sps, _ in pairs), 2),
            "median_over_cleanrl_median": round(
                statistics.median(sps for sps, _ in pairs) / base, 3
            ),
            "per_round_ratios": [round(sps / c, 3) for sps, c in pairs],
            "median_per_round_ratio": round(statistics.median(sps / c for sps, c in pairs), 3),
        }
        for key, pairs in runs.items()
    }
    out: dict[str, Any] = {"files": files, "cleanrl_sps": cleanrl, "cleanrl_median_sps": base}
    for key, prefix, goal in (
        ("farsighter_E1_fp32", "", 1.15),
        ("farsighter_E1_bf16", "bf16_", 1.4),
    ):
        if key in table:  # the headline figures (#13), by both statistics
            row = table[key]
            if not prefix:
                out["farsighter_breakout_cpu_sps"] = row["median_sps"]
            out[f"farsighter_{prefix}over_cleanrl"] = row["median_over_cleanrl_median"]
            out[f"farsighter_{prefix}over_cleanrl_per_round"] = row["median_per_round_ratio"]
            out[f"goal_{prefix or 'fp32_'}ratio"] = goal
    return {**out, "table": table}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("files", nargs="+", help="result names under benchmarks/results (no .json)")
    p.add_argument("--name", required=True, help="result file to write")
    args = p.parse_args()
    result = pool(args.files)
    print(json.dumps(result["table"], indent=1))
    write_result(args.name, result)


if __name__ == "__main__":
    main()
