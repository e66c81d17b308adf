"""Tracking (issue #64 item 4): ``farsighter train --track`` logs what TensorBoard gets, the
config and the evaluation videos to Weights & Biases (offline here: nothing leaves the
machine), and training callbacks receive the same scalars (the README's example)."""

from __future__ import annotations

import csv
import json
import re
import struct
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from conftest import tiny
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

import farsighter
from farsighter.cli import main
from farsighter.envs.video import moviepy_installed
from farsighter.seeds import batchable, seed_configs, train_seeds
from farsighter.tracking import WANDB_ID_FILE

try:
    import wandb  # noqa: F401

    NO_WANDB = False
except ImportError:
    NO_WANDB = True

needs_wandb = pytest.mark.skipif(NO_WANDB, reason="wandb missing: the refusal is tested instead")

TINY = [
    "--algo", "ddqn", "--env", "CartPole-v1", "--preset", "control", "--device", "cpu",
    "--learning-starts", "100", "--buffer-size", "1000", "--batch-size", "16",
    "--hidden-sizes", "32", "32", "--eval-every", "200", "--eval-episodes", "2",
    "--eval-max-steps", "40", "--log-every", "100", "--checkpoint-every", "200", "--no-progress",
]  # fmt: skip


@pytest.fixture(autouse=True)
def offline_wandb(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """W&B offline, silent, and with every folder of its own in tmp_path."""
    monkeypatch.setenv("WANDB_MODE", "offline")
    monkeypatch.setenv("WANDB_SILENT", "true")
    monkeypatch.setenv("WANDB_CONSOLE", "off")
    for name in ("WANDB_DIR", "WANDB_CONFIG_DIR", "WANDB_CACHE_DIR", "WANDB_DATA_DIR"):
        monkeypatch.setenv(name, str(tmp_path / "wandb-home"))
    monkeypatch.delenv("WANDB_API_KEY", raising=False)


# --------------------------------------------------------------------------------------------
# Reading an offline run back: its .wandb file is a LevelDB-style log of protobuf records
# (7-byte file header, 32 KiB blocks, each chunk with a 7-byte header: crc32, length, type).
# --------------------------------------------------------------------------------------------

BLOCK = 32768
FULL, FIRST, LAST = 1, 2, 4


def wandb_records(file: Path) -> Iterator[Any]:
    from wandb.proto import wandb_internal_pb2

    data = file.read_bytes()
    ident, magic, _ = struct.unpack("<4sHB", data[:7])
    assert ident == b":W&B" and magic == 0xBEE1, (ident, magic)
    pos, pending = 7, b""
    while pos + 7 <= len(data):
        if BLOCK - pos % BLOCK < 7:  # a block's tail too short for a header is padding
            pos += BLOCK - pos % BLOCK
            continue
        _, length, kind = struct.unpack("<IHB", data[pos : pos + 7])
        if kind == 0 and length == 0:
            break
        pending += data[pos + 7 : pos + 7 + length]
        pos += 7 + length
        if kind in (FULL, LAST):
            record = wandb_internal_pb2.Record()
            record.ParseFromString(pending)
            pending = b""
            yield record


def offline_runs(run_dir: Path) -> list[Path]:
    """The .wandb files of a run directory's offline W&B runs, oldest first, once each is
    complete (its exit record written)."""
    files = sorted((run_dir / "wandb").glob("offline-run-*/run-*.wandb"))
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and not all(
        any(r.WhichOneof("record_type") == "exit" for r in wandb_records(f)) for f in files
    ):
        time.sleep(0.2)
    return files


def wandb_run(file: Path) -> tuple[Any, dict[str, Any], list[dict[str, Any]]]:
    """(the run record, its config, its history rows) of an offline run."""
    run, config, history = None, {}, []
    for record in wandb_records(file):
        kind = record.WhichOneof("record_type")
        if kind == "run":
            run = record.run
            config.update({i.key: json.loads(i.value_json) for i in run.config.update})
        elif kind == "config":
            config.update({i.key: json.loads(i.value_json) for i in record.config.update})
        elif kind == "history":
            row = {
                i.key or "/".join(i.nested_key): json.loads(i.value_json)
                for i in record.history.item
            }
            history.append(row)
    assert run is not None
    return run, config, history


def tensorboard_scalars(run_dir: Path) -> dict[str, list[tuple[int, float]]]:
    events = EventAccumulator(str(run_dir))
    events.Reload()
    return {
        tag: [(e.step, e.value) for e in events.Scalars(tag)] for tag in events.Tags()["scalars"]
    }


def wandb_scalars(history: list[dict[str, Any]], tags: Any) -> dict[str, list[tuple[int, float]]]:
    return {
        tag: [(int(row["global_step"]), float(row[tag])) for row in history if tag in row]
        for tag in tags
    }


# --------------------------------------------------------------------------------------------


@needs_wandb
def test_track_logs_the_tensorboard_scalars_and_the_config_to_a_wandb_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run_dir = tmp_path / "cartpole"
    video = ["--capture-video"] if moviepy_installed() else []
    flags = ["--track", "--wandb-project", "farsighter-tests", "--wandb-entity", "someone"]
    args = ["train", *TINY, "--total-steps", "400", "--run-dir", str(run_dir), *flags, *video]
    assert main(args) == 0
    assert json.loads(capsys.readouterr().out)["global_step"] == 400
    files = offline_runs(run_dir)
    assert len(files) == 1, files
    run, config, history = wandb_run(files[0])
    assert (run.project, run.entity, run.display_name) == (
        "farsighter-tests",
        "someone",
        "cartpole",
    )
    assert run.run_id == (run_dir / WANDB_ID_FILE).read_text().strip()
    # the config: the resolved one, as config.json holds it
    saved = json.loads((run_dir / "config.json").read_text())
    assert {key: config[key] for key in saved} == saved
    assert config["runtime"]["track"] is True and config["algo"] == "ddqn"
    # the scalars: every TensorBoard tag, with its steps and values
    tb = tensorboard_scalars(run_dir)
    assert {"charts/episodic_return", "charts/SPS", "losses/td_loss", "eval/mean_return"} <= set(tb)
    logged = wandb_scalars(history, tb)
    for tag, points in tb.items():
        assert [s for s, _ in logged[tag]] == [s for s, _ in points], tag
        assert [v for _, v in logged[tag]] == pytest.approx([v for _, v in points], rel=1e-5), tag
    assert len(logged["charts/episodic_return"]) >= 5  # CartPole's random episodes: many
    assert {s for s, _ in logged["eval/mean_return"]} == {200, 400}
    if video:  # each evaluation's video, at its step
        videos = [row for row in history if "videos/eval/_type" in row]
        assert [int(row["global_step"]) for row in videos] == [200, 400]
        assert {row["videos/eval/_type"] for row in videos} == {"video-file"}
        copied = list((files[0].parent / "files" / "media" / "videos").rglob("*.mp4"))
        assert len(copied) == 2, copied


def test_track_without_wandb_is_one_line_naming_the_extra(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "wandb", None)  # `import wandb` raises ImportError
    run_dir = tmp_path / "run"
    assert main(["train", *TINY, "--run-dir", str(run_dir), "--track"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert (
        err[0].startswith("farsighter: error: --track")
        and "pip install 'farsighter[track]'" in err[0]
    )
    assert not run_dir.exists()  # refused before the run directory is made


@needs_wandb
def test_track_may_be_turned_on_at_a_resume_and_continues_the_wandb_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run_dir = tmp_path / "run"
    assert main(["train", *TINY, "--total-steps", "200", "--run-dir", str(run_dir)]) == 0
    assert not (run_dir / "wandb").exists()
    resume = ["train", "--run-dir", str(run_dir), "--resume"]
    assert main([*resume, "--total-steps", "300", "--track", "--wandb-project", "p2"]) == 0
    assert main([*resume, "--total-steps", "400"]) == 0  # tracked still: config.json says so
    capsys.readouterr()
    assert json.loads((run_dir / "config.json").read_text())["runtime"]["track"] is True
    files = offline_runs(run_dir)
    assert len(files) == 2, files
    runs = [wandb_run(f) for f in files]
    assert {run.run_id for run, _, _ in runs} == {(run_dir / WANDB_ID_FILE).read_text().strip()}
    assert {run.project for run, _, _ in runs} == {"p2"}
    steps = [[int(r["global_step"]) for r in history] for _, _, history in runs]
    assert min(steps[0]) > 200 and max(steps[0]) == 300  # each part logs its own steps
    assert min(steps[1]) > 300 and max(steps[1]) == 400


@needs_wandb
def test_track_gives_each_seed_of_a_batch_its_own_wandb_run(tmp_path: Path) -> None:
    cfg = tiny("ddqn", tmp_path / "seeds", total_steps=200, eval_every=0, track=True)
    assert batchable(cfg)  # the seeds train as one batch: two W&B runs open at once
    cfgs = seed_configs(cfg, [1, 2])
    summaries = train_seeds(cfgs)
    names = []
    for summary in summaries:
        path = Path(summary["run_dir"])
        (file,) = offline_runs(path)
        run, config, history = wandb_run(file)
        names.append(run.display_name)
        assert config["seed"] == summary["seed"]
        tb = tensorboard_scalars(path)["charts/episodic_return"]
        logged = wandb_scalars(history, ["charts/episodic_return"])["charts/episodic_return"]
        assert logged == tb and tb  # CartPole's returns are whole numbers: exact in float32
    assert names == ["s1", "s2"]


# --------------------------------------------------------------------------------------------
# The callback API, as the README shows it.
# --------------------------------------------------------------------------------------------


def readme_callback_example() -> str:
    """The README's callback example, without its last lines (the run it starts)."""
    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", readme, flags=re.DOTALL)
    (block,) = [b for b in blocks if "farsighter.BaseCallback" in b]
    return block.split("\ncfg = ")[0]


def test_the_readme_callback_example_receives_the_scalars(tmp_path: Path) -> None:
    assert "Callback" in farsighter.__all__ and "BaseCallback" in farsighter.__all__
    namespace: dict[str, Any] = {}
    exec(compile(readme_callback_example(), "README.md", "exec"), namespace)
    out = tmp_path / "scalars.csv"
    run_dir = tmp_path / "run"
    callback = namespace["CsvScalars"](out)
    assert isinstance(callback, farsighter.BaseCallback)
    farsighter.train(tiny("ddqn", run_dir, total_steps=400, eval_every=200), callbacks=[callback])
    with out.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    tb = tensorboard_scalars(run_dir)
    got: dict[str, list[tuple[int, float]]] = {}
    for row in rows:
        got.setdefault(row["tag"], []).append((int(row["step"]), float(row["value"])))
    assert set(got) == set(tb)  # every TensorBoard scalar, with its steps and values
    for tag, points in tb.items():
        assert [s for s, _ in got[tag]] == [s for s, _ in points], tag
        assert [v for _, v in got[tag]] == pytest.approx([v for _, v in points], rel=1e-5), tag
