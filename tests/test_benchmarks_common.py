"""benchmarks/common.py records the command relative to the repository, not an absolute path."""

from __future__ import annotations

import importlib.util
from pathlib import Path, PurePath
from types import ModuleType

import pytest

ROOT = PurePath("/abs/repo")


@pytest.fixture(scope="module")
def common() -> ModuleType:
    file = Path(__file__).resolve().parent.parent / "benchmarks" / "common.py"
    spec = importlib.util.spec_from_file_location("benchmarks_common_under_test", file)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize(
    ("argv", "module", "expected"),
    [
        # python -m benchmarks.atari_sps: argv[0] is the absolute path of the module's file
        (
            ["/abs/repo/benchmarks/atari_sps.py", "--steps", "10"],
            True,
            "python -m benchmarks.atari_sps --steps 10",
        ),
        (["/abs/repo/benchmarks/learning.py"], None, "python -m benchmarks.learning"),
        (["/abs/repo/pkg/__main__.py"], True, "python -m pkg"),
        # python benchmarks/x.py (a script, not a module): its path relative to the repository
        (["/abs/repo/benchmarks/x.py", "--n", "1"], False, "python benchmarks/x.py --n 1"),
        (["benchmarks/x.py"], False, "python benchmarks/x.py"),
        # absolute paths inside the repository become relative, also after --flag=; others stay
        (
            [
                "/abs/repo/benchmarks/pool_rounds.py",
                "/abs/repo/docs/results/maze",
                "--out=/abs/repo/o",
            ],
            True,
            "python -m benchmarks.pool_rounds docs/results/maze --out=o",
        ),
        (
            ["/abs/repo/benchmarks/x.py", "/tmp/elsewhere", "/abs/repo"],
            True,
            "python -m benchmarks.x /tmp/elsewhere .",
        ),
        (["/abs/repository/x.py"], True, "python /abs/repository/x.py"),  # a sibling, not inside
        (["/abs/repo/benchmarks/x.py", "a b"], True, "python -m benchmarks.x 'a b'"),  # quoted
        (["-c"], None, "python -c"),
    ],
)
def test_relative_command(
    common: ModuleType, argv: list[str], module: bool | None, expected: str
) -> None:
    assert common.relative_command(argv, ROOT, module=module) == expected


def test_relative_command_keeps_the_interpreter_name(common: ModuleType) -> None:
    got = common.relative_command(["/abs/repo/benchmarks/x.py"], ROOT, executable="python3.11")
    assert got == "python3.11 -m benchmarks.x"


def test_pool_rounds_pairs_each_run_with_its_round(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import json

    from benchmarks import pool_rounds

    def run(rnd: int, sps: float) -> dict[str, object]:
        return {"algo": "farsighter", "num_envs": 1, "precision": "fp32", "round": rnd, "sps": sps}

    files = {
        "a": {
            "cleanrl": [{"sps": 100.0}, {"sps": 200.0}],
            "measurements": [run(1, 110), run(2, 180)],
        },
        "b": {"cleanrl": [{"sps": 150.0}], "measurements": [run(1, 300)]},
    }
    for name, data in files.items():
        (tmp_path / f"{name}.json").write_text(json.dumps(data))
    monkeypatch.setattr(pool_rounds, "RESULTS", tmp_path)
    out = pool_rounds.pool(["a", "b"])
    row = out["table"]["farsighter_E1_fp32"]
    assert out["cleanrl_median_sps"] == 150.0
    assert row["per_round_ratios"] == [1.1, 0.9, 2.0] and row["median_per_round_ratio"] == 1.1
    assert row["median_sps"] == 180.0 and row["median_over_cleanrl_median"] == 1.2
