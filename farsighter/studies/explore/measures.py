"""The exploration study's measures: per run from its saved files (the greedy criterion, and on
deep sea bsuite's from the bad-episode log the runs record), then per family x size x agent with
unsolved seeds censored at the run's end.
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from farsighter.errors import FarsighterError
from farsighter.studies.explore.families import (
    BSUITE_FORGIVENESS,
    BSUITE_NUM_EPISODES,
    FAMILIES,
    TASKS,
    BsuiteCriterion,
)
from farsighter.studies.runner import Runs


def measure(
    run: dict[str, Any],
    threshold: float,
    goal: float,
    measured_by: Literal["return", "success"] = "return",
) -> dict[str, Any]:
    """One run's measures from its metrics.csv and eval.csv (NaN where a run never got there);
    ``measured_by="success"`` (:attr:`Family.measured_by`): from eval_success.csv and success.csv
    instead, the evaluations' success rates and the training episodes' success flags.

    solved: some evaluation's mean return (success rate) reached ``threshold``;
    episodes_to_solve and steps_to_solve: the training episodes finished and the step at the
    first such evaluation; held: the final evaluation is at the threshold;
    episodes_to_first_reward: the first training episode whose return (success) is above
    ``goal``; episodes: training episodes in all.
    """
    m, e = run["metrics"] or {}, run["eval"] or {}
    ep_steps = m.get("global_step", np.array([]))
    returns = m.get("episodic_return", np.array([]))
    ev_steps = e.get("global_step", np.array([]))
    ev = e.get("eval_return_mean", np.array([]))
    episode = np.arange(1.0, len(returns) + 1)
    reached = returns
    if measured_by == "success":
        if len(ev) and run.get("eval_success") is None:
            where = f" ({run['task']}, seed {run['seed']})" if "task" in run else ""
            raise FarsighterError(
                f"a run{where} has evaluations but no eval_success.csv: its environment reported "
                "no info['is_success'] (a deep sea run recorded before the adapter did); run it "
                "again"
            )
        e, s = run.get("eval_success") or {}, run.get("success") or {}
        ev_steps = e.get("global_step", np.array([]))
        ev = e.get("eval_success_rate", np.array([]))
        episode = s.get("episode", np.array([]))
        reached = s.get("success", np.array([]))
    hit = np.flatnonzero(ev >= threshold)
    first = float(ev_steps[hit[0]]) if len(hit) else float("nan")
    reward = np.flatnonzero(reached > goal)
    return {
        "solved": bool(len(hit)),
        "episodes_to_solve": float(np.sum(ep_steps <= first)) if len(hit) else float("nan"),
        "steps_to_solve": first,
        "held": bool(len(ev) and ev[-1] >= threshold),
        "episodes_to_first_reward": float(episode[reward[0]]) if len(reward) else float("nan"),
        "episodes": len(returns),
    }


def bsuite_solution(
    bad: Sequence[bool] | np.ndarray,
    threshold: float,
    min_episode: int = 1,
    max_episode: int = BSUITE_NUM_EPISODES,
) -> int | None:
    """bsuite's deep sea ``find_solution`` for one run: the first episode (counted from 1)
    between ``min_episode`` and ``max_episode`` where the running fraction of bad episodes, all
    bad episodes up to it (the earlier ones included) over its number, is below ``threshold``;
    None if there is none. bsuite logs (and so checks) only at logarithmically spaced episodes
    (1-10, 12, 14, 17, 20, 25, ...); this checks every episode, so it can find an episode a
    little earlier than bsuite's table would."""
    b = np.asarray(bad, dtype=float)
    episode = np.arange(1, len(b) + 1)
    below = (np.cumsum(b) / episode < threshold) & (episode >= min_episode)
    hit = np.flatnonzero(below & (episode <= max_episode))
    return int(episode[hit[0]]) if len(hit) else None


def beats_dithering(episode: int | None, size: int) -> bool:
    """bsuite's deep sea score of one run at side N: solved, at an episode below 2^N + 100."""
    return episode is not None and episode < 2**size + BSUITE_FORGIVENESS


def bsuite_measure(
    run: dict[str, Any], size: int, criterion: BsuiteCriterion | None
) -> dict[str, Any]:
    """bsuite's criterion on one run's bad_episodes.csv: bsuite_solved (beats dithering; None
    where the family has no bsuite criterion or the run recorded no bad flags) and
    bsuite_episode (:func:`bsuite_solution`'s episode; NaN where none)."""
    flags = run.get("bad_episodes")
    if criterion is None or flags is None:
        return {"bsuite_solved": None, "bsuite_episode": float("nan")}
    episode = bsuite_solution(flags.get("bad", []), criterion.threshold, criterion.min_episode)
    return {
        "bsuite_solved": beats_dithering(episode, size),
        "bsuite_episode": float("nan") if episode is None else float(episode),
    }


BAD_EPISODES_FILE = "bad_episodes.csv"


def ended_bad_flags(info: dict[str, Any]) -> list[bool] | None:
    """The bad flags (``info["bad_episode"]``) of the episodes that ended at this vector step,
    in environment order; None where the environments report no such flag. The loop's vector
    environment resets an ended episode in the same step (Gymnasium's SAME_STEP autoreset), so
    the ended episode's info is ``info["final_info"]``; without it (NEXT_STEP) it is ``info``
    itself. Either way ``_episode`` marks the environments whose episode ended."""
    src = info["final_info"] if "final_info" in info else info
    if "bad_episode" not in src and "bad_episode" not in info:
        return None
    ended = src.get("_episode")
    if ended is None or "bad_episode" not in src:
        return []
    return [bool(src["bad_episode"][i]) for i in np.flatnonzero(ended)]


class BadEpisodeLog:
    """Read-only callback: the bad flag of every training episode, written to
    bad_episodes.csv (global_step, episode, bad) at the end of a run whose environment reports
    ``bad_episode`` (deep sea); other runs write nothing."""

    def __init__(self) -> None:
        self.rows: list[dict[str, int]] = []
        self.reported = False

    def on_step(self, global_step: int, info: dict[str, Any], agent: Any) -> None:
        flags = ended_bad_flags(info)
        if flags is None:
            return
        self.reported = True
        for bad in flags:
            row = {"global_step": global_step, "episode": len(self.rows) + 1, "bad": int(bad)}
            self.rows.append(row)

    def on_finish(self, run_dir: Path, agent: Any) -> None:
        if not self.reported:
            return
        with (run_dir / BAD_EPISODES_FILE).open("w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=["global_step", "episode", "bad"])
            writer.writeheader()
            writer.writerows(self.rows)


def censored_median(values: Sequence[float], censored: Sequence[bool]) -> tuple[float, bool]:
    """The median of ``values`` where a censored value is a lower bound (the run ended first),
    and whether the median is itself only a lower bound (raising the censored values would
    raise it)."""
    v, c = np.asarray(values, dtype=float), np.asarray(censored, dtype=bool)
    median = float(np.median(v))
    return median, float(np.median(np.where(c, np.inf, v))) != median


def per_run(runs: Runs) -> list[dict[str, Any]]:
    """One row per finished run: where it ran, its :func:`measure` and its
    :func:`bsuite_measure`."""
    rows = []
    for label, items in runs.items():
        for run in items:
            name, size = TASKS[run["task"]]
            family = FAMILIES[name]
            rows.append(
                {
                    "family": name,
                    "size": size,
                    "env": run["task"],
                    "agent": label,
                    "seed": run["seed"],
                    "budget": run["steps"],
                    **measure(run, family.threshold_at(size), family.goal, family.measured_by),
                    **bsuite_measure(run, size, family.bsuite),
                }
            )
    return rows


@dataclass(frozen=True)
class SolveMeasure:
    """One way to count the episodes a run took to solve, and its columns in the table."""

    name: str
    text: str
    """What it counts (the report)."""
    solved: str
    """Table column: seeds solved."""
    median: str
    """Table column: the censored median episode."""
    censored: str
    """Table column: whether that median is only a lower bound."""


SOLVE_MEASURES = {
    "greedy": SolveMeasure(
        "greedy",
        "training episodes to the first greedy evaluation at the threshold",
        "seeds_solved",
        "median_episodes_to_solve",
        "episodes_censored",
    ),
    "bsuite": SolveMeasure(
        "bsuite",
        "bsuite's episode to solve (bad-episode fraction)",
        "seeds_bsuite_solved",
        "median_bsuite_episode",
        "bsuite_censored",
    ),
}


def measures_of(family: str) -> tuple[str, ...]:
    """The solve measures of a family: greedy, and bsuite's where it has a criterion."""
    return ("greedy", "bsuite") if FAMILIES[family].bsuite else ("greedy",)


def primary_measure(family: str) -> str:
    """The measure the claims use: bsuite's for deep sea, the greedy one elsewhere."""
    return measures_of(family)[-1]


def seed_values(rs: Sequence[dict[str, Any]], measure: str) -> tuple[list[float], list[bool]]:
    """Per run of ``rs`` (:func:`per_run` rows), the episode it solved at by ``measure`` or,
    unsolved, its episodes in all (a lower bound), and whether it is such a bound. bsuite's
    measure leaves out the runs without bad flags."""
    if measure == "greedy":
        solved = [bool(r["solved"]) for r in rs]
        key = "episodes_to_solve"
    else:
        rs = [r for r in rs if r["bsuite_solved"] is not None]
        solved = [bool(r["bsuite_solved"]) for r in rs]
        key = "bsuite_episode"
    values = [
        float(r[key]) if ok else float(r["episodes"]) for r, ok in zip(rs, solved, strict=True)
    ]
    return values, [not ok for ok in solved]


def by_cell(rows: list[dict[str, Any]]) -> dict[tuple[str, int, str], list[dict[str, Any]]]:
    """Rows by (family, size, agent): families and agents in their order in ``rows``, sizes
    ascending."""
    families = list(dict.fromkeys(r["family"] for r in rows))
    agents = list(dict.fromkeys(r["agent"] for r in rows))
    cells: dict[tuple[str, int, str], list[dict[str, Any]]] = {}
    for r in sorted(
        rows, key=lambda r: (families.index(r["family"]), r["size"], agents.index(r["agent"]))
    ):
        cells.setdefault((r["family"], r["size"], r["agent"]), []).append(r)
    return cells


def summarise(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per family x size x agent (families and agents in their order in ``rows``, sizes
    ascending): seeds solved and held, and the median episodes and steps to solve with unsolved
    seeds censored at the run's end; on deep sea, the seeds that beat dithering by bsuite's
    criterion and the median of bsuite's episode to solve, censored likewise (NaN, None
    elsewhere)."""
    table = []
    for (family, size, agent), rs in by_cell(rows).items():
        unsolved = [not r["solved"] for r in rs]
        episodes, _ = seed_values(rs, "greedy")
        steps = [r["budget"] if not r["solved"] else r["steps_to_solve"] for r in rs]
        no_reward = [not np.isfinite(r["episodes_to_first_reward"]) for r in rs]
        first = [
            r["episodes"] if c else r["episodes_to_first_reward"]
            for r, c in zip(rs, no_reward, strict=True)
        ]
        med_ep, ep_cens = censored_median(episodes, unsolved)
        med_st, st_cens = censored_median(steps, unsolved)
        med_fr, fr_cens = censored_median(first, no_reward)
        bs_values, bs_unsolved = seed_values(rs, "bsuite")
        med_bs, bs_cens = (
            censored_median(bs_values, bs_unsolved) if bs_values else (float("nan"), None)
        )
        table.append(
            {
                "family": family,
                "size": size,
                "env": rs[0]["env"],
                "budget": rs[0]["budget"],
                "agent": agent,
                "seeds": len(rs),
                "seeds_solved": sum(r["solved"] for r in rs),
                "seeds_held": sum(r["held"] for r in rs),
                "median_episodes_to_solve": med_ep,
                "episodes_censored": ep_cens,
                "median_steps_to_solve": med_st,
                "steps_censored": st_cens,
                "median_episodes_to_first_reward": med_fr,
                "first_reward_censored": fr_cens,
                "seeds_bsuite": len(bs_values) if bs_values else None,
                "seeds_bsuite_solved": bs_unsolved.count(False) if bs_values else None,
                "median_bsuite_episode": med_bs,
                "bsuite_censored": bs_cens,
            }
        )
    return table
