"""Deep sea growth from two explore studies: one agent's runs of a base study, with the sizes that
a second study ran (with a larger episode budget, say) taken from that one instead.

``farsighter explore`` gives every size the same budget rule (2^N + 100 episodes, at least 1,000
and at most 3,000), so at N = 30 a seed that has not solved by episode 3,000 leaves the median a
lower bound. A second study of the large sizes alone with ``--episodes`` (bsuite itself runs
10,000) measures them uncensored; this refits the growth of issue #25 item 4 over both with the
study's own functions (:func:`farsighter.studies.explore.growth`: least squares on the medians,
the bootstrap interval on p) and writes the per-size table and the fits as JSON.

    python -m benchmarks.deepsea_growth BASE EXTRA [--agent Farsighter] [--name deepsea_growth]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

from benchmarks.common import write_result


def _clean(value: Any) -> Any:
    return None if isinstance(value, float) and math.isnan(value) else value


def combined_rows(base: Path, extra: Path, agent: str) -> tuple[list[dict[str, Any]], list[int]]:
    """``agent``'s per-run rows of ``base`` at the sizes ``extra`` did not run, and those of
    ``extra``; and the sizes taken from ``extra``."""
    from farsighter.studies import explore, runner

    rows = {}
    for which, path in (("base", base), ("extra", extra)):
        _, runs = runner.load_runs(explore.STUDY, path)
        rows[which] = [r for r in explore.per_run(runs) if r["agent"] == agent]
    if not rows["extra"]:
        raise SystemExit(f"{extra} holds no finished runs of {agent!r}")
    replaced = sorted({r["size"] for r in rows["extra"]})
    kept = [r for r in rows["base"] if r["size"] not in replaced]
    return kept + rows["extra"], replaced


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("base", type=Path, help="an explore study directory")
    p.add_argument("extra", type=Path, help="a study whose sizes replace the base's")
    p.add_argument("--agent", default="Farsighter")
    p.add_argument("--name", default="deepsea_growth")
    args = p.parse_args()
    from farsighter.studies import explore

    rows, replaced = combined_rows(args.base, args.extra, args.agent)
    table = [
        {k: _clean(v) for k, v in t.items()}
        for t in explore.summarise(rows)
        if t["family"] == "deepsea"
    ]
    fits = [
        {k: _clean(v) for k, v in f.items()}
        for f in explore.growth(rows)
        if f["family"] == "deepsea"
    ]
    for t in table:
        print(
            f"N = {t['size']}: solved {t['seeds_solved']}/{t['seeds']}, "
            f"median episodes {'>' if t['episodes_censored'] else ''}"
            f"{t['median_episodes_to_solve']}; bsuite {t['seeds_bsuite_solved']}/{t['seeds']}"
        )
    for f in fits:
        print(
            f"{f['measure']}: p = {f['p']} [{f['p_lo']}, {f['p_hi']}] (R2 {f['r2_poly']}), "
            f"r = {f['r']} (R2 {f['r2_exp']}): {f['better']}"
        )
    write_result(
        args.name,
        {
            "base": str(args.base),
            "extra": str(args.extra),
            "agent": args.agent,
            "sizes_from_extra": replaced,
            "table": table,
            "growth": fits,
            "runs": [
                {k: _clean(v) for k, v in r.items()} for r in rows if r["family"] == "deepsea"
            ],
        },
    )


if __name__ == "__main__":
    main()
