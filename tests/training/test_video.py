"""Watching an agent (issue #64 item 2): rendering environments from a policy, ``farsighter eval
--render/--video`` and ``--capture-video`` during training."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import tiny

import farsighter
from farsighter.cli import main, train_config
from farsighter.envs import video
from farsighter.envs.video import moviepy_installed

NO_MOVIEPY = not moviepy_installed()


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("watch")
    summary = farsighter.train(tiny("ddqn", root / "run", total_steps=400, eval_every=0))
    return Path(summary["run_dir"])


def test_a_policy_makes_environments_that_render_frames(run: Path) -> None:
    env = farsighter.load_agent(run).make_env(seed=0, render_mode="rgb_array")
    try:
        env.reset(seed=0)
        frame = env.render()
    finally:
        env.close()
    assert isinstance(frame, np.ndarray) and frame.dtype == np.uint8
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.shape[0] > 50


@pytest.mark.skipif(NO_MOVIEPY, reason="moviepy missing: the refusal is tested instead")
def test_eval_records_each_episode_as_an_mp4(
    run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    videos = tmp_path / "videos"
    args = ["eval", str(run), "--episodes", "2", "--seed", "3", "--video", str(videos)]
    assert main(args) == 0
    report = json.loads(capsys.readouterr().out)
    files = sorted(videos.glob("*.mp4"))
    assert len(files) == 2 and all(f.stat().st_size > 1_000 for f in files), files
    assert report["videos"] == [str(f) for f in files] and len(report["returns"]) == 2
    # the same greedy returns as the evaluation without a video
    assert main(["eval", str(run), "--episodes", "2", "--seed", "3"]) == 0
    assert json.loads(capsys.readouterr().out)["returns"] == report["returns"]


def test_eval_video_without_moviepy_is_one_line_naming_the_extra(
    run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    if not NO_MOVIEPY:
        monkeypatch.setattr(video, "moviepy_installed", lambda: False)
    assert main(["eval", str(run), "--video", str(tmp_path / "v")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "pip install 'farsighter[video]'" in err[0], err
    assert not (tmp_path / "v").exists()


@pytest.mark.parametrize(
    ("flags", "needle"),
    [
        (["--render", "window"], "unknown --render 'window'; accepted: human, rgb_array"),
        (["--render", "human", "--video", "v"], "give one of them"),
    ],
)
def test_eval_render_bad_input_is_one_line_exit_2(
    run: Path, capsys: pytest.CaptureFixture[str], flags: list[str], needle: str
) -> None:
    assert main(["eval", str(run), *flags]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0], err


def test_capture_video_is_a_training_flag() -> None:
    assert train_config(["--algo", "ddqn", "--capture-video"]).runtime.capture_video
    assert not train_config(["--algo", "ddqn"]).runtime.capture_video


@pytest.mark.skipif(NO_MOVIEPY, reason="moviepy missing: the refusal is tested instead")
def test_capture_video_records_each_evaluation(tmp_path: Path) -> None:
    cfg = tiny(
        "ddqn",
        tmp_path / "run",
        total_steps=400,
        eval_every=200,
        eval_max_steps=30,
        capture_video=True,
    )
    plain = farsighter.train(tiny("ddqn", tmp_path / "plain", total_steps=400, eval_every=200))
    summary = farsighter.train(cfg)
    files = sorted(p.name for p in (tmp_path / "run" / "videos").glob("*.mp4"))
    assert files == ["eval-step-200.mp4", "eval-step-400.mp4"], files
    assert summary["final_eval_return"] == plain["final_eval_return"]  # learning unchanged


def test_capture_video_without_moviepy_is_refused_before_the_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(video, "moviepy_installed", lambda: False)
    with pytest.raises(farsighter.FarsighterError, match=r"farsighter\[video\]"):
        farsighter.train(tiny("ddqn", tmp_path / "run", capture_video=True))
    assert not (tmp_path / "run").exists()


@pytest.mark.skipif(NO_MOVIEPY, reason="moviepy missing: the refusal is tested instead")
def test_a_video_folder_that_cannot_be_made_is_one_line(
    run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "afile").write_text("")
    assert main(["eval", str(run), "--video", str(tmp_path / "afile")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("farsighter: error: cannot record CartPole-v1"), err
