"""The Atari study (paper section 5.2, Figure 2 and Table 2), and MinAtar as its CPU-scale form.

Runs the paper's four discrete agents (DDQN, BDQN, Farsighter, OB2I; k-DDQN on request) on any
games x seeds x budget with the library's ``auto`` preset (``atari``: Table 1's Atari column and
Dopamine's protocol for ALE games; ``minatar``: Young & Tian's DQN settings for MinAtar), then
draws Figure 2-style curves (greedy evaluation return against environment steps, mean and std
over seeds), a table of final scores (raw, and human-normalised for ALE games) with the paper's
Table 2 beside ours, aggregates over games, and a report whose per-game comparisons of
Farsighter with each baseline are decided by a bootstrap confidence interval over seeds.
Everything is drawn from saved files, so ``--plot-only`` redraws it.

Games are named ``Breakout`` (-> ``ALE/Breakout-v5``, one of Table 2's 49), ``MinAtar/Breakout``
(-> ``MinAtar/Breakout-v1``), or by the groups ``all`` (Table 2's 49) and ``minatar`` (the five
MinAtar games).
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import tyro

from farsighter import algorithms
from farsighter.config import Config, is_minatar_id
from farsighter.envs.atari import ATARI_49, TABLE2, ale_id, game_of
from farsighter.envs.atari_scores import human_normalized
from farsighter.envs.minatar import MINATAR_GAMES, minatar_id
from farsighter.errors import FarsighterError
from farsighter.plots import band, figure, finish_axes, markdown_table
from farsighter.studies import runner
from farsighter.studies.claims import Measure, compare
from farsighter.studies.runner import Agent, Runs, StudyArgs, Task

AGENTS: tuple[Agent, ...] = (
    Agent("DDQN", "ddqn"),
    Agent("BDQN", "bdqn"),
    Agent("Farsighter", "farsighter"),
    Agent("OB2I", "ob2i"),
    Agent("k-DDQN", "kddqn"),
)
COMPILED = tuple(a.name for a in algorithms.TABLE if a.fast_step)
"""Algorithms whose update --compile compiles (the others run eagerly)."""
PAPER_COLUMN = {"DDQN": "ddqn", "BDQN": "bdqn", "Farsighter": "farsighter", "OB2I": "ob2i"}


@dataclass(frozen=True)
class StudyConfig:
    """What a study runs; saved as study.json."""

    games: tuple[str, ...] = ("Breakout", "Pong")
    seeds: tuple[int, ...] = (1, 2, 3)
    steps: int = 100_000  # agent steps per run (Atari 100k); an ALE step is 4 frames
    eval_every: int = 25_000
    eval_episodes: int = 10
    workers: int = 0  # 0: one per core
    agents: tuple[str, ...] = ("DDQN", "BDQN", "Farsighter", "OB2I")
    preset: str = "auto"  # auto: atari for ALE games, minatar for MinAtar
    device: str = "cpu"  # where every run trains: cpu, cuda or cuda:N (workers share a GPU)
    threads: int = 1  # torch threads of each run
    precision: str = "fp32"  # RuntimeConfig.precision of every run
    compile: bool = False  # RuntimeConfig.compile of the agents that support it


QUICK = StudyConfig(
    games=("MinAtar/Breakout",),
    seeds=(1, 2),
    steps=20_000,
    eval_every=5_000,
    eval_episodes=5,
    agents=("DDQN", "Farsighter"),
)


@dataclass(frozen=True)
class Args(StudyArgs):
    """The flags of ``farsighter atari``: the shared ones and the study's."""

    games: Annotated[tuple[str, ...] | None, runner.study_flag("GAME [GAME ...]")] = None
    """Games: Table 2 names (Breakout, MontezumaRevenge, ...), MinAtar/<Game>, or the groups
    'all' (Table 2's 49) and 'minatar' (MinAtar's five)."""
    steps: Annotated[int | None, runner.study_flag("N")] = None
    """Agent steps of each run (an ALE step is 4 frames)."""
    eval_every: Annotated[int | None, runner.study_flag("N")] = None
    """Steps between greedy evaluations (at most half of --steps)."""
    eval_episodes: Annotated[int | None, runner.study_flag("N")] = None
    """Episodes of each evaluation."""
    preset: Annotated[str | None, runner.study_flag("NAME")] = None
    """Preset of every run: auto (atari for ALE games, minatar for MinAtar), atari100k (the
    100k-step regime: schedules shrunk to the budget), or any of `farsighter presets`."""
    device: Annotated[str | None, runner.study_flag("DEVICE")] = None
    """Where every run trains: cpu, cuda or cuda:N (the worker processes share the GPU; on a GPU
    the updates of DDQN, BDQN and Farsighter run as CUDA graphs)."""
    threads: Annotated[int | None, runner.study_flag("N")] = None
    """torch threads of each run (each worker process runs one run at a time)."""
    precision: Annotated[str | None, runner.study_flag("fp32|bf16")] = None
    """Arithmetic of the torsos (RuntimeConfig.precision): fp32, or bf16 autocast."""
    compile: tyro.conf.FlagCreatePairsOff[bool] = False
    """torch.compile the updates (RuntimeConfig.compile) of the agents that support it (DDQN,
    k-DDQN, BDQN, Farsighter); OB2I runs eagerly."""


def expand_games(names: Sequence[str]) -> tuple[str, ...]:
    """The groups ``all`` and ``minatar`` replaced by their games; order kept, repeats dropped."""
    out: list[str] = []
    for name in names:
        group = {
            "all": ATARI_49,
            "minatar": tuple(f"MinAtar/{g}" for g in MINATAR_GAMES),
        }.get(name.lower(), (name,))
        out += [g for g in group if g not in out]
    return tuple(out)


def env_id(game: str) -> str:
    """``Breakout`` -> ``ALE/Breakout-v5``; ``MinAtar/Breakout[-v1]`` -> ``MinAtar/Breakout-v1``.

    Raises FarsighterError with the accepted forms for any other name."""
    if game in TABLE2:
        return ale_id(game)
    if game.startswith("MinAtar/"):
        name = game.removeprefix("MinAtar/").split("-v")[0]
        if name in MINATAR_GAMES:
            return minatar_id(name)
    by_case = {g.lower(): g for g in (*TABLE2, *(f"MinAtar/{m}" for m in MINATAR_GAMES))}
    hint = f" (did you mean {by_case[game.lower()]}?)" if game.lower() in by_case else ""
    raise FarsighterError(
        f"unknown game '{game}'{hint}; accepted: one of Table 2's 49 ALE names (Breakout, Pong, "
        f"MontezumaRevenge, ...; `farsighter atari --help`), MinAtar/<Game> with Game one of "
        f"{', '.join(MINATAR_GAMES)}, or the groups all, minatar"
    )


def tasks(study: StudyConfig) -> tuple[Task, ...]:
    """(environment id, budget) per game."""
    return tuple((env_id(g), study.steps) for g in expand_games(study.games))


def run_config(agent: Agent, study: StudyConfig, seed: int, run_dir: Path, task: Task) -> Config:
    """The library's ``auto`` preset for the game (``atari`` or ``minatar``) and the agent's
    overrides, with the study's evaluation cadence. The replay is sized to the run when the run
    is shorter than the preset's buffer (it never wraps either way, so learning is identical and
    memory is not reserved for frames that never come), and the final checkpoint holds no
    replay."""
    env, steps = task
    preset = study.preset
    base = runner.run_config(agent, env, preset, seed, steps, run_dir)
    return runner.run_config(
        agent,
        env,
        preset,
        seed,
        steps,
        run_dir,
        eval_every=study.eval_every,
        eval_episodes=study.eval_episodes,
        buffer_size=min(base.buffer_size, max(steps, base.effective_recent_window)),
        checkpoint_every=0,
        save_replay=False,
        device=study.device,
        torch_threads=study.threads,
        precision=study.precision,
        compile=study.compile and agent.algo in COMPILED,
    )


def _resolve(study: StudyConfig, args: Args) -> StudyConfig:
    study = replace(study, games=expand_games(study.games))
    if args.eval_every is None:  # at least two evaluations
        return replace(study, eval_every=min(study.eval_every, max(1, study.steps // 2)))
    return study


def _check(study: StudyConfig) -> None:
    if not study.games:
        raise FarsighterError("--games must name at least one game")
    if study.steps < 1:
        raise FarsighterError(f"--steps must be >= 1 (got {study.steps})")
    for name, value in (
        ("eval-every", study.eval_every),
        ("eval-episodes", study.eval_episodes),
        ("threads", study.threads),
    ):
        if value < 1:
            raise FarsighterError(f"--{name} must be >= 1 (got {value})")
    if study.precision not in ("fp32", "bf16"):
        raise FarsighterError(f"--precision must be fp32 or bf16 (got {study.precision!r})")
    from farsighter.envs import make_env

    configs = [run_config(AGENTS[0], study, 1, Path("."), task) for task in tasks(study)]
    for cfg in configs:  # a missing extra fails here, before any run
        make_env(cfg, seed=0).close()
    from farsighter.config import validate
    from farsighter.train import resolve_device

    validate(configs[0])  # the device's spelling first
    resolve_device(study.device)  # then cuda without a GPU: refused before any run


# ------------------------------------------------------------------------------------------------
# Measures: everything below reads only saved files.
# ------------------------------------------------------------------------------------------------


def game_name(env: str) -> str:
    """How a game is shown: the Table 2 key for ALE ids, ``MinAtar/<Game>`` for MinAtar."""
    return game_of(env) or env.split("-v")[0]


def final_score(run: dict[str, Any]) -> float:
    """A run's score: the mean return of its last greedy evaluation (unclipped rewards, whole
    games: the evaluation environment has neither clipping nor life-loss terminals)."""
    ev = run["eval"]
    return (
        float(ev["eval_return_mean"][-1]) if ev is not None and len(ev["global_step"]) else np.nan
    )


def per_game(runs: Runs) -> list[dict[str, Any]]:
    """One row per game x agent: per-seed final scores, their mean and std, the human-normalised
    mean (ALE games), and the paper's Table 2 score."""
    rows = []
    envs = list(dict.fromkeys(r["task"] for items in runs.values() for r in items))
    for env in envs:
        game = game_of(env)
        for label, items in runs.items():
            mine = [r for r in items if r["task"] == env]
            if not mine:
                continue
            scores = np.array([final_score(r) for r in mine])
            paper = TABLE2[game] if game else None
            column = PAPER_COLUMN.get(label)
            normalised = (
                np.array([human_normalized(game, s) for s in scores])
                if game
                else np.full(1, np.nan)
            )
            rows.append(
                {
                    "game": game_name(env),
                    "env": env,
                    "agent": label,
                    "seeds": len(mine),
                    "budget": mine[0]["steps"],
                    "score_mean": float(np.mean(scores)),
                    "score_std": float(np.std(scores)),
                    "hns_mean": float(np.mean(normalised)),
                    "paper": float(getattr(paper, column)) if paper and column else np.nan,
                    "per_seed": {"score": scores, "hns": normalised},
                }
            )
    return rows


def aggregate(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per agent over the ALE games: mean and median human-normalised score and the number of
    games; per agent over all games: the games where it has the best mean score."""
    agents = list(dict.fromkeys(r["agent"] for r in rows))
    best: dict[str, int] = dict.fromkeys(agents, 0)
    for game in dict.fromkeys(r["game"] for r in rows):
        cell = [r for r in rows if r["game"] == game]
        top = max(r["score_mean"] for r in cell)
        winners = [r["agent"] for r in cell if r["score_mean"] == top]
        if len(winners) == 1:
            best[winners[0]] += 1
    out = []
    for agent in agents:
        hns = np.array([r["hns_mean"] for r in rows if r["agent"] == agent], dtype=float)
        hns = hns[np.isfinite(hns)]
        out.append(
            {
                "agent": agent,
                "ale_games": int(hns.size),
                "hns_mean": float(hns.mean()) if hns.size else np.nan,
                "hns_median": float(np.median(hns)) if hns.size else np.nan,
                "games_best": best[agent],
                "games": sum(1 for r in rows if r["agent"] == agent),
            }
        )
    return out


def claims(rows: list[dict[str, Any]]) -> list[tuple[str, str, str]]:
    """Per game, "Farsighter scores higher than B" for every other agent B: (game, claim text
    with its evidence, verdict), decided by a 95% bootstrap interval over seeds."""
    measure = Measure("score", "final evaluation return", higher_is_better=True)
    out = []
    for game in dict.fromkeys(r["game"] for r in rows):
        cell = {r["agent"]: r for r in rows if r["game"] == game}
        if "Farsighter" not in cell:
            continue
        for other, row in cell.items():
            if other == "Farsighter":
                continue
            c = compare(f"Farsighter scores higher than {other}", cell["Farsighter"], row, measure)
            out.append((game, f"{c.claim}: {c.evidence}", c.verdict))
    return out


# ------------------------------------------------------------------------------------------------
# Outputs.
# ------------------------------------------------------------------------------------------------


def _num(v: float, digits: int = 1) -> str:
    if not np.isfinite(v):
        return "n/a"
    return f"{v:,.0f}" if abs(v) >= 1000 else f"{v:.{digits}f}"


def write_outputs(out: Path, study: dict[str, Any], runs: Runs) -> None:
    """figures/curves.png, table.csv/md, aggregate.csv and report.md."""
    rows = per_game(runs)
    _plot(study, runs, out / "figures" / "curves.png")
    fields = [k for k in rows[0] if k != "per_seed"]
    with (out / "table.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=[*fields, "scores"])
        writer.writeheader()
        for r in rows:
            scores = " ".join(f"{s:g}" for s in r["per_seed"]["score"])
            writer.writerow({**{k: r[k] for k in fields}, "scores": scores})
    agg = aggregate(rows)
    with (out / "aggregate.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(agg[0]))
        writer.writeheader()
        writer.writerows(agg)
    (out / "table.md").write_text(_table(rows) + "\n" + _aggregate_table(agg))
    rl = _rliable(rows, out / "rliable")
    _report(study, rows, agg, out, rl)


def rliable_scores(rows: list[dict[str, Any]]) -> tuple[dict[str, np.ndarray], list[str], str]:
    """Per agent a (seeds x games) array for rliable: human-normalised when every game is an
    ALE game, else min-max normalised per game over all agents' runs (MinAtar has no human
    reference); agents that lack a game, and seeds beyond the fewest any agent has, are left
    out. Returns the scores, the games and what the normalisation was."""
    from farsighter.aggregate import minmax_normalized

    games = list(dict.fromkeys(r["game"] for r in rows))
    human = all(np.isfinite(r["hns_mean"]) for r in rows)
    cells = {(r["agent"], r["game"]): r["per_seed"]["hns" if human else "score"] for r in rows}
    agents = [
        a for a in dict.fromkeys(r["agent"] for r in rows) if all((a, g) in cells for g in games)
    ]
    if not agents:
        return {}, games, ""
    n = min(len(cells[(a, g)]) for a in agents for g in games)
    table = {a: np.array([cells[(a, g)][:n] for g in games], dtype=float).T for a in agents}
    if human:
        return table, games, "human-normalised score (random 0, human 1)"
    return minmax_normalized(table), games, "min-max normalised per game (lowest run 0, highest 1)"


def _rliable(rows: list[dict[str, Any]], out: Path) -> str:
    """rliable's aggregates (farsighter.aggregate) under ``out``; their Markdown table, or ""
    when the runs cannot be stacked or a score is missing."""
    from farsighter import aggregate

    table, games, name = rliable_scores(rows)
    if not table or any(not np.isfinite(x).all() for x in table.values()):
        return ""
    pairs = (
        [("Farsighter", a) for a in table if a != "Farsighter"] if "Farsighter" in table else None
    )
    paths = aggregate.write_outputs(out, table, games, normalized_name=name, pairs=pairs)
    return paths["aggregate_md"].read_text()


def _table(rows: list[dict[str, Any]]) -> str:
    head = ["game", "agent", "seeds", "final score (ours)", "human-normalised", "paper Table 2"]
    cells = [
        [
            r["game"],
            r["agent"],
            str(r["seeds"]),
            f"{_num(r['score_mean'])} ± {_num(r['score_std'])}",
            _num(r["hns_mean"], 3),
            _num(r["paper"]),
        ]
        for r in rows
    ]
    return markdown_table(head, cells)


def _aggregate_table(agg: list[dict[str, Any]]) -> str:
    head = ["agent", "games", "games led (best mean score)", "ALE games", "mean HNS", "median HNS"]
    cells = [
        [
            a["agent"],
            str(a["games"]),
            str(a["games_best"]),
            str(a["ale_games"]),
            _num(a["hns_mean"], 3),
            _num(a["hns_median"], 3),
        ]
        for a in agg
    ]
    return markdown_table(head, cells)


def _plot(study: dict[str, Any], runs: Runs, file: Path) -> None:
    envs = list(dict.fromkeys(r["task"] for items in runs.values() for r in items))
    cols = min(3, len(envs))
    rows = (len(envs) + cols - 1) // cols
    with figure(file, rows, cols, figsize=(4.6 * cols, 3.4 * rows), squeeze=False) as (_, axes):
        for ax, env in zip(axes.flat, envs, strict=False):
            for i, (label, items) in enumerate(runs.items()):
                mine = [r for r in items if r["task"] == env and r["eval"] is not None]
                if not mine:
                    continue
                n = min(len(r["eval"]["global_step"]) for r in mine)
                steps = mine[0]["eval"]["global_step"][:n]
                values = np.array([r["eval"]["eval_return_mean"][:n] for r in mine], dtype=float)
                band(ax, steps, values, f"C{i}", label)
            finish_axes(ax, "agent steps", "evaluation return", game_name(env))
        for ax in list(axes.flat)[len(envs) :]:
            ax.set_visible(False)


def _claims_section(rows: list[dict[str, Any]]) -> list[str]:
    """The report's claims: Farsighter against each other agent, per game."""
    lines: list[str] = []
    lines += [
        "## Claims",
        "",
        "Per game, Farsighter against each other agent, decided by a 95% bootstrap confidence "
        "interval of the difference of mean final scores over seeds (holds / does not hold / "
        "undecided at this budget).",
        "",
    ]
    found = claims(rows)
    counts = {v: sum(1 for *_, x in found if x == v) for v in ("holds", "does not hold")}
    for game, text, verdict in found:
        lines.append(f"- {game}: {text}: **{verdict}**")
    if found:
        lines += [
            "",
            f"In all: {counts['holds']} comparisons hold, {counts['does not hold']} do not, "
            f"{len(found) - sum(counts.values())} are undecided (the paper: Farsighter leads in "
            "36 of 49 games).",
        ]
    return lines


def _report(
    study: dict[str, Any],
    rows: list[dict[str, Any]],
    agg: list[dict[str, Any]],
    out: Path,
    rl: str = "",
) -> None:
    games = list(dict.fromkeys(r["game"] for r in rows))
    ale = any(np.isfinite(r["paper"]) for r in rows)
    lines = [
        "# Atari study (paper section 5.2, Figure 2, Table 2)",
        "",
        f"Agents: {', '.join(study['agents'])}; games: {', '.join(games)}; seeds "
        f"{list(study['seeds'])}; {study['steps']:,} agent steps per run"
        + (f" ({4 * study['steps']:,} frames on ALE games)" if ale else "")
        + f"; greedy evaluation every {study['eval_every']:,} steps over "
        f"{study['eval_episodes']} episodes. Every agent runs with the library's "
        f"`{study.get('preset', 'auto')}` preset (`auto` is `atari` for ALE games: Table 1's "
        "Atari column and Dopamine's protocol, and `minatar` for MinAtar: Young & Tian's DQN "
        "settings with the general preset's posterior; `atari100k` shrinks the Atari "
        "schedules to a 100k-step budget; `farsighter presets`).",
        "",
        "Score: the mean return of the last evaluation, with unclipped rewards over whole games "
        "(no life-loss terminals); human-normalised score (HNS) = (score - random) / (human - "
        "random) with the random and human scores in `farsighter/envs/atari_scores.py`.",
        "",
    ]
    if ale:
        lines += [
            "Budget: the paper's Table 2 comes from far longer training (its OB2I column is "
            "Bai et al.'s, at 20M frames); at a smaller budget our scores are not comparable "
            "with it, only with each other.",
            "",
        ]
    lines += [
        "## Scores",
        "",
        _table(rows),
        "## Aggregate",
        "",
        _aggregate_table(agg),
    ]
    if rl:
        lines += [
            "Across games with rliable (interquartile mean and the rest with stratified-bootstrap "
            "95% CIs; `rliable/` holds the CSVs, probability of improvement of Farsighter over "
            "each agent, and the figures `rliable/figures/aggregate.png`, "
            "`rliable/figures/profiles.png`):",
            "",
            rl.strip(),
            "",
        ]
    lines += _claims_section(rows)
    lines += [
        "",
        "## Figure",
        "",
        "![learning curves](figures/curves.png)",
        "",
        f"Redraw from the saved runs with `farsighter atari --plot-only {out}`.",
        "",
    ]
    (out / "report.md").write_text("\n".join(lines))


def _name(study: StudyConfig) -> str:
    games = expand_games(study.games)
    if all(is_minatar_id(env_id(g)) for g in games):
        return "minatar"
    return "atari"


STUDY = runner.Study(
    kind="atari",
    description="The Atari study of section 5.2 (Figure 2, Table 2), on ALE games or MinAtar.",
    agents=AGENTS,
    full=StudyConfig(),
    quick=QUICK,
    run_config=run_config,
    write_outputs=write_outputs,
    run_files=("eval.csv",),
    args=Args,
    resolve=_resolve,
    check=_check,
    name=_name,
    tasks=tasks,
)


def main(argv: Sequence[str]) -> int:
    """``farsighter atari ARGV``."""
    return runner.main(STUDY, argv)
