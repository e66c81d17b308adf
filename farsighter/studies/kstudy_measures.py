"""The k study's sweep (its fixed k and their labels), what it measures of each run and each
environment x agent, and the paper's claims decided on those per-seed values, from the saved
files only (:mod:`farsighter.studies.kstudy`, which re-exports them, writes the report)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from farsighter.envs.maze import DEFAULT_MAX_EPISODE_STEPS, ENV_ID, SMALL_ENV_ID
from farsighter.studies import runner
from farsighter.studies.claims import NOT_TESTED, Claim, Measure, compare, fmt
from farsighter.studies.explore.families import FAMILIES, TASKS
from farsighter.studies.runner import Runs

KS: tuple[int, ...] = (1, 10, 50, 150, 500)
"""The fixed k of Figure 4 (k = 1, one-step uncertainty as BDQN, is the left end)."""
ADAPTIVE = "adaptive k"

K_OF: dict[str, int] = {f"k={k}": k for k in KS}
"""The fixed k of each fixed-k label (adaptive k is not in it)."""
FIRST, LAST = f"k={KS[0]}", f"k={KS[-1]}"


# ------------------------------------------------------------------------------------------------
# Measures: per run, then per environment x agent (from the saved files only).
# ------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Solved:
    """When a final greedy evaluation solves an environment."""

    threshold: float
    strict: bool
    """Solved above the threshold (else: at least the threshold)."""
    text: str
    success: bool = False
    """The threshold applies to the final evaluation's success rate (eval_success.csv), not its
    mean return (an exploration family measured by success: stochastic deep sea)."""

    def __call__(self, value: float) -> bool:
        return bool(value > self.threshold if self.strict else value >= self.threshold)

    def comparison(self) -> str:
        return f"{'>' if self.strict else '>='} {fmt(float(self.threshold))}"

    def rule(self) -> str:
        """The comparison, named "success rate" where it applies to it (table.csv)."""
        return f"success rate {self.comparison()}" if self.success else self.comparison()


MAZE_SOLVED = Solved(
    -float(DEFAULT_MAX_EPISODE_STEPS),
    strict=True,
    text="the greedy episode reaches the apple, as the maze study's *greedy solves*; one that "
    "never does returns exactly -200",
)


def solved_rule(env: str) -> Solved | None:
    """The bridge mazes' (the maze study's), an exploration-suite task's (its family's
    threshold), or the environment's registered ``reward_threshold``; None where none is known."""
    if env in (ENV_ID, SMALL_ENV_ID):
        return MAZE_SOLVED
    if env in TASKS:
        name, size = TASKS[env]
        family = FAMILIES[name]
        return Solved(
            family.threshold_at(size),
            strict=False,
            text=family.solved,
            success=family.measured_by == "success",
        )
    import gymnasium as gym

    try:
        threshold = gym.spec(env).reward_threshold
    except gym.error.Error:
        return None
    if threshold is None:
        return None
    return Solved(
        float(threshold), strict=False, text="the environment's registered reward_threshold"
    )


def area(steps: np.ndarray, returns: np.ndarray) -> float:
    """The area under an evaluation curve per step (trapezoids over the evaluations, divided by
    the steps they span): the curve's mean height, in return units; one evaluation: its return."""
    s, r = np.asarray(steps, dtype=float), np.asarray(returns, dtype=float)
    if len(r) == 0:
        return float("nan")
    if len(r) == 1 or s[-1] == s[0]:
        return float(r[-1])
    return float(np.sum((r[1:] + r[:-1]) / 2 * np.diff(s)) / (s[-1] - s[0]))


def per_run(run: dict[str, Any], rule: Solved | None) -> dict[str, float]:
    """One run's final evaluation return, area under its evaluation curve, solved (1/0, NaN
    where no rule is known; a rule on the success rate reads the final one, from
    eval_success.csv) and final k (the last episode's, from metrics.csv)."""
    ev = run.get("eval") or {}
    steps = ev.get("global_step", np.array([]))
    returns = ev.get("eval_return_mean", np.array([]))
    final = float(returns[-1]) if len(returns) else float("nan")
    judged = final
    if rule and rule.success:
        rates = (run.get("eval_success") or {}).get("eval_success_rate", np.array([]))
        judged = float(rates[-1]) if len(rates) else float("nan")
    metrics = run.get("metrics") or {}
    k = metrics.get("k", np.array([]))
    return {
        "final": final,
        "auc": area(steps, returns),
        "solved": float(rule(judged)) if rule and np.isfinite(judged) else float("nan"),
        "final_k": float(k[-1]) if len(k) else float("nan"),
    }


def summarise(runs: Runs) -> list[dict[str, Any]]:
    """One row per environment x agent (environments in the order they ran, agents in the study's
    order): the per-seed values (``"per_seed"``, which the claims compare) and their summaries."""
    envs = list(dict.fromkeys(r["task"] for items in runs.values() for r in items))
    rows = []
    for env in envs:
        rule = solved_rule(env)
        for label, items in runs.items():
            mine = [r for r in items if r["task"] == env]
            if not mine:
                continue
            values = [per_run(r, rule) for r in mine]
            per_seed = {key: np.array([v[key] for v in values]) for key in values[0]}
            solved = per_seed["solved"]
            rows.append(
                {
                    "env": env,
                    "agent": label,
                    "k": K_OF.get(label, "adaptive"),
                    "seeds": len(mine),
                    "budget": mine[0]["steps"],
                    "final_return_mean": float(np.mean(per_seed["final"])),
                    "final_return_std": float(np.std(per_seed["final"])),
                    "auc_mean": float(np.mean(per_seed["auc"])),
                    "auc_std": float(np.std(per_seed["auc"])),
                    "solved_seeds": int(np.nansum(solved)) if rule else "",
                    "solved_fraction": float(np.mean(solved)) if rule else float("nan"),
                    "solved_rule": rule.rule() if rule else "n/a",
                    "final_k_mean": runner.nanmean(per_seed["final_k"]),
                    "finals": " ".join(f"{v:g}" for v in per_seed["final"]),
                    "per_seed": per_seed,
                }
            )
    return rows


# ------------------------------------------------------------------------------------------------
# The paper's claims, per environment, each one row against one other on per-seed values.
# ------------------------------------------------------------------------------------------------

FINAL = Measure("final", "mean final evaluation return", higher_is_better=True)
AUC = Measure("auc", "mean area under the evaluation curve", higher_is_better=True)

SHAPE = "Score rises then falls with k (Fig. 4): the best fixed k is interior, neither {a} nor {b}"
BEST = "Adaptive k is best (Fig. 4): it finishes higher than the best fixed k"
FASTEST = "Adaptive k's score rises fastest (Fig. 4): larger area under its curve than the best "
FASTEST += "fixed k's"


def _best(rows: list[dict[str, Any]], key: str) -> dict[str, Any]:
    """The row with the highest mean of ``key`` (the first of equals)."""
    return max(rows, key=lambda r: float(np.mean(r["per_seed"][key])))


def combine(verdicts: Sequence[str]) -> str:
    """A claim made of parts: holds when every part holds, does not hold when one does not,
    else undecided."""
    if all(v == "holds" for v in verdicts):
        return "holds"
    if any(v == "does not hold" for v in verdicts):
        return "does not hold"
    return "undecided"


@dataclass(frozen=True)
class Decided:
    """One claim of the report: its verdict and the comparisons that decide it."""

    claim: str
    verdict: str
    note: str
    parts: tuple[Claim, ...] = ()


def shape_claim(rows: list[dict[str, Any]]) -> Decided:
    """Claim (1) on one environment's rows: the best interior k (by mean final score) against
    each end of the sweep."""
    claim = SHAPE.format(a=FIRST, b=LAST)
    by = {r["agent"]: r for r in rows}
    interior = [r for r in rows if r["agent"] in K_OF and r["agent"] not in (FIRST, LAST)]
    missing = [label for label in (FIRST, LAST) if label not in by]
    if missing or not interior:
        need = ", ".join(missing) if missing else "an interior k (k=10, k=50 or k=150)"
        return Decided(claim, NOT_TESTED, f"Needs {need} in the study (--agents)")
    best = _best(interior, "final")
    fixed = [r for r in rows if r["agent"] in K_OF]
    top = _best(fixed, "final")["agent"]
    end = " (an end of the sweep)" if top in (FIRST, LAST) else ""
    note = f"Best interior k by mean final score: {best['agent']}; best fixed k overall: {top}{end}"
    parts = (
        compare(f"rises: {best['agent']} scores higher than {FIRST}", best, by[FIRST], FINAL),
        compare(f"falls: {best['agent']} scores higher than {LAST}", best, by[LAST], FINAL),
    )
    return Decided(claim, combine([p.verdict for p in parts]), note, parts)


def adaptive_claims(rows: list[dict[str, Any]]) -> list[Decided]:
    """Claim (2) on one environment's rows: adaptive k against the best fixed k by mean final
    score, and against the best fixed k by mean area under the curve."""
    by = {r["agent"]: r for r in rows}
    fixed = [r for r in rows if r["agent"] in K_OF]
    if ADAPTIVE not in by or not fixed:
        need = "adaptive k" if ADAPTIVE not in by else "a fixed k"
        why = f"Needs {need} in the study (--agents)"
        return [Decided(BEST, NOT_TESTED, why), Decided(FASTEST, NOT_TESTED, why)]
    out = []
    for claim, m in ((BEST, FINAL), (FASTEST, AUC)):
        best = _best(fixed, m.key)
        c = compare(f"{ADAPTIVE} against {best['agent']}", by[ADAPTIVE], best, m)
        note = f"Best fixed k by {m.name}: {best['agent']}"
        out.append(Decided(claim, c.verdict, note, (c,)))
    return out


def claims(rows: list[dict[str, Any]]) -> dict[str, list[Decided]]:
    """Per environment: claim (1) and claim (2) (:func:`shape_claim`, :func:`adaptive_claims`)."""
    out = {}
    for env in dict.fromkeys(r["env"] for r in rows):
        mine = [r for r in rows if r["env"] == env]
        out[env] = [shape_claim(mine), *adaptive_claims(mine)]
    return out
