"""The Atari study (``farsighter atari``): game names, presets per suite, the per-game table with
human-normalised scores on synthetic runs, the claims, bad flags, and a tiny real MinAtar study
end to end with --plot-only."""

from __future__ import annotations

import csv
import shlex
from pathlib import Path

import numpy as np
import pytest
import torch

from farsighter.cli import main
from farsighter.config import make_config, resolve_preset_name
from farsighter.errors import FarsighterError
from farsighter.studies import atari
from farsighter.studies.atari import (
    AGENTS,
    STUDY,
    StudyConfig,
    aggregate,
    claims,
    env_id,
    expand_games,
    per_game,
    rliable_scores,
    run_config,
    tasks,
)
from farsighter.studies.runner import Runs, load_runs, parse, settings_from


def test_game_names_and_groups() -> None:
    assert env_id("Breakout") == "ALE/Breakout-v5"
    assert env_id("MontezumaRevenge") == "ALE/MontezumaRevenge-v5"
    assert env_id("MinAtar/Breakout") == "MinAtar/Breakout-v1"
    assert env_id("MinAtar/SpaceInvaders-v1") == "MinAtar/SpaceInvaders-v1"
    assert len(expand_games(["all"])) == 49
    assert expand_games(["minatar"]) == tuple(f"MinAtar/{g}" for g in atari.MINATAR_GAMES)
    # groups and names mix; a repeat is dropped and the order kept
    assert expand_games(["Pong", "all"])[:2] == ("Pong", "Alien")
    assert len(expand_games(["Pong", "all"])) == 49
    with pytest.raises(FarsighterError, match="did you mean Breakout"):
        env_id("breakout")
    with pytest.raises(FarsighterError, match="accepted: one of Table 2's 49"):
        env_id("Pitfall")
    with pytest.raises(FarsighterError, match="unknown game 'MinAtar/Pong'"):
        env_id("MinAtar/Pong")


def test_each_suite_gets_its_preset(tmp_path: Path) -> None:
    assert resolve_preset_name("auto", "MinAtar/Breakout-v1", "farsighter") == "minatar"
    assert resolve_preset_name("auto", "ALE/Breakout-v5", "farsighter") == "atari"
    study = StudyConfig(games=("MinAtar/Breakout", "Pong"), steps=50_000)
    (minatar_task, ale_task) = tasks(study)
    assert minatar_task == ("MinAtar/Breakout-v1", 50_000)
    far = AGENTS[2]
    cfg = run_config(far, study, 3, tmp_path, minatar_task)
    # Young & Tian's DQN settings, the general posterior, Farsighter's own k
    assert (cfg.train_every, cfg.target_update_every, cfg.lr) == (1, 1_000, 0.00025)
    assert (cfg.eps_end, cfg.learning_starts, cfg.loss) == (0.1, 5_000, "huber")
    assert (cfg.blr.mode, cfg.blr.redraw, cfg.k_target, cfg.k) == ("incremental", "step", "max", 10)
    assert cfg.buffer_size == 50_000  # the run is shorter than MinAtar's 100k buffer
    assert (cfg.seed, cfg.total_steps, cfg.eval_every) == (3, 50_000, study.eval_every)
    ale = run_config(far, study, 3, tmp_path, ale_task)
    assert (ale.target_update_every, ale.blr.posterior_every) == (10_000, 100_000)  # Table 1
    assert ale.eval_max_steps == 27_000 and ale.atari.max_frames_per_episode == 108_000
    assert ale.buffer_size == 50_000
    # same learning values for every agent on a game: only what defines the algorithm differs
    ddqn = run_config(AGENTS[0], study, 3, tmp_path, minatar_task)
    assert (ddqn.lr, ddqn.train_every, ddqn.buffer_size) == (cfg.lr, cfg.train_every, 50_000)
    # a long run keeps the preset's buffer
    long = run_config(far, StudyConfig(steps=2_000_000), 1, tmp_path, ("ALE/Pong-v5", 2_000_000))
    assert long.buffer_size == make_config("farsighter", "ALE/Pong-v5").buffer_size


def test_device_threads_precision_and_compile_reach_every_run(tmp_path: Path) -> None:
    study = StudyConfig(games=("Pong",), device="cuda:1", threads=4, precision="bf16", compile=True)
    task = tasks(study)[0]
    for agent in AGENTS:
        cfg = run_config(agent, study, 1, tmp_path, task)
        assert (cfg.runtime.device, cfg.runtime.torch_threads, cfg.runtime.precision) == (
            "cuda:1",
            4,
            "bf16",
        )
        assert cfg.runtime.compile == (
            agent.label != "OB2I"
        )  # OB2I's update is not one step function
    flags = "--games Pong --device cuda:1 --threads 4 --precision bf16 --compile".split()
    assert settings_from(atari.STUDY, parse(atari.STUDY, flags)) == study
    default = run_config(AGENTS[2], StudyConfig(), 1, tmp_path, task)
    assert (default.runtime.device, default.runtime.torch_threads, default.runtime.precision) == (
        "cpu",
        1,
        "fp32",
    )
    assert default.runtime.compile is False


def _run(task: str, seed: int, finals: list[float]) -> dict[str, object]:
    steps = np.arange(1, len(finals) + 1) * 1_000.0
    return {
        "seed": seed,
        "steps": 1_000 * len(finals),
        "task": task,
        "eval": {"global_step": steps, "eval_return_mean": np.array(finals, dtype=float)},
    }


def test_per_game_rows_normalise_and_aggregate() -> None:
    # Breakout's random and human scores are 1.7 and 30.5 (DQN Zoo's atari_data.py)
    runs: Runs = {
        "DDQN": [
            _run("ALE/Breakout-v5", 1, [0.0, 1.7]),
            _run("ALE/Breakout-v5", 2, [0.0, 30.5]),
            _run("MinAtar/Breakout-v1", 1, [3.0]),
        ],
        "Farsighter": [
            _run("ALE/Breakout-v5", 1, [5.0, 59.3]),
            _run("ALE/Breakout-v5", 2, [2.0, 59.3]),
            _run("MinAtar/Breakout-v1", 1, [1.0]),
        ],
    }
    rows = per_game(runs)
    by = {(r["game"], r["agent"]): r for r in rows}
    ddqn = by[("Breakout", "DDQN")]
    assert ddqn["score_mean"] == pytest.approx(16.1) and ddqn["score_std"] == pytest.approx(14.4)
    assert ddqn["hns_mean"] == pytest.approx(0.5)  # seeds at random (0) and human (1)
    assert by[("Breakout", "Farsighter")]["hns_mean"] == pytest.approx(2.0)
    assert ddqn["paper"] == 385.5 and by[("Breakout", "Farsighter")]["paper"] == 597.2
    mini = by[("MinAtar/Breakout", "DDQN")]
    assert mini["score_mean"] == 3.0 and np.isnan(mini["hns_mean"]) and np.isnan(mini["paper"])
    agg = {a["agent"]: a for a in aggregate(rows)}
    assert agg["Farsighter"]["hns_mean"] == pytest.approx(2.0) and agg["DDQN"]["ale_games"] == 1
    assert (agg["Farsighter"]["games_best"], agg["DDQN"]["games_best"]) == (1, 1)
    found = {(game, verdict) for game, _, verdict in claims(rows)}
    # two seeds each: Farsighter's 59.3, 59.3 against DDQN's 1.7, 30.5 holds; one seed is undecided
    assert found == {("Breakout", "holds"), ("MinAtar/Breakout", "undecided")}
    # rliable's input: a MinAtar game among them has no human score, so min-max per game over
    # both agents' runs (seeds beyond the fewest any agent has on a game are dropped: 1 here)
    table, games, name = rliable_scores(rows)
    assert games == ["Breakout", "MinAtar/Breakout"] and name.startswith("min-max")
    np.testing.assert_allclose(table["DDQN"], [[0.0, 1.0]])
    np.testing.assert_allclose(table["Farsighter"], [[1.0, 0.0]])
    ale_only = [r for r in rows if r["game"] == "Breakout"]
    table, _, name = rliable_scores(ale_only)
    assert name.startswith("human")
    np.testing.assert_allclose(table["DDQN"], [[0.0], [1.0]])
    np.testing.assert_allclose(table["Farsighter"], [[2.0], [2.0]])


BAD = [
    ("--games Nope", "unknown game 'Nope'"),
    ("--games breakout", "did you mean Breakout?"),
    ("--agents Rainbow", "unknown atari agent(s) ['Rainbow']"),
    ("--eval-episodes 0", "--eval-episodes must be >= 1"),
    ("--steps 0", "--steps must be >= 1"),
    ("--threads 0", "--threads must be >= 1"),
    ("--precision fp16", "--precision must be fp32 or bf16"),
    *([] if torch.cuda.is_available() else [("--device cuda", "CUDA is not available")]),
    ("--device tpu", "unknown device 'tpu'"),
]


@pytest.mark.parametrize(("line", "message"), BAD)
def test_bad_flags_are_one_line_and_exit_2(
    line: str, message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "study"
    assert main(["atari", *shlex.split(line), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("farsighter: error: ") and err.count("\n") == 1, err
    assert message in err and "Traceback" not in err
    assert not out.exists()


def test_tiny_minatar_study_end_to_end_and_plot_only(tmp_path: Path) -> None:
    out = tmp_path / "m"
    line = (
        "--games MinAtar/Breakout --seeds 1 2 --agents DDQN Farsighter --steps 600 "
        "--eval-every 300 --eval-episodes 1 --workers 1"
    )
    assert main(["atari", *line.split(), "--out", str(out), "--no-progress"]) == 0
    run_dir = out / "runs" / "minatar-breakout-v1" / "farsighter__s2"
    assert (run_dir / "summary.json").exists()
    for name in ("report.md", "table.csv", "table.md", "aggregate.csv", "study.json"):
        assert (out / name).exists(), name
    for name in ("aggregate.csv", "probability_of_improvement.csv", "figures/profiles.png"):
        assert (out / "rliable" / name).exists(), name
    _, runs = load_runs(STUDY, out)
    assert sorted(runs) == ["DDQN", "Farsighter"]
    assert [len(r["eval"]["global_step"]) for r in runs["DDQN"]] == [2, 2]
    rows = list(csv.DictReader((out / "table.csv").open()))
    assert [(r["game"], r["agent"]) for r in rows] == [
        ("MinAtar/Breakout", "DDQN"),
        ("MinAtar/Breakout", "Farsighter"),
    ]
    finals = [float(r["eval"]["eval_return_mean"][-1]) for r in runs["DDQN"]]
    assert float(rows[0]["score_mean"]) == pytest.approx(np.mean(finals))
    report = (out / "report.md").read_text()
    assert "Farsighter scores higher than DDQN" in report
    figure = out / "figures" / "curves.png"
    figure.unlink()
    assert main(["atari", "--plot-only", str(out)]) == 0
    assert figure.stat().st_size > 10_000


def test_the_frame_cap_is_a_config_value() -> None:
    from farsighter.envs import make_env

    cfg = make_config(
        "ddqn", "ALE/Pong-v5", **{"atari.max_frames_per_episode": 400, "atari.noop_max": 0}
    )
    env = make_env(cfg, seed=0, training=False)
    env.reset(seed=0)
    steps, ended = 0, (False, False)
    while not any(ended):
        _, _, *ended, _ = env.step(0)
        steps += 1
    env.close()
    # 400 emulator frames at frame skip 4: truncated (not terminated) after 100 agent steps
    assert steps == 100 and ended == [False, True]
