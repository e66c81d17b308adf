"""The continuous agents through the one training loop on Pendulum-v1: outputs, determinism,
crash and resume, loading a policy."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

import farsighter
from farsighter.agents.naf import NAFAgent
from farsighter.config import Config
from farsighter.errors import RunDirError
from tests.conftest import tiny


def naf_tiny(algo: str, run_dir: Path, **kw: Any) -> Config:
    values: dict[str, Any] = {
        "total_steps": 900,
        "learning_starts": 200,
        "batch_size": 32,
        "train_every": 2,
        "eval_every": 450,
        "eval_episodes": 1,
        "checkpoint_every": 450,
        "naf.elbo_every": 150,
        "naf.elbo_steps": 3,
        "naf.elbo_batch": 32,
    }
    values.update(kw)
    return tiny(algo, run_dir, env="Pendulum-v1", preset="continuous", **values)


def rows(run_dir: Path) -> list[dict[str, str]]:
    with (run_dir / "metrics.csv").open() as fh:
        out = list(csv.DictReader(fh))
    for r in out:
        r.pop("SPS")
    return out


def weights(run_dir: Path) -> dict[str, torch.Tensor]:
    return torch.load(run_dir / "policy.pt", weights_only=False)["agent"]["net"]


@pytest.mark.parametrize("algo", ["naf", "knaf", "bnaf", "farsighter-naf"])
def test_pendulum_run_outputs(tmp_path: Path, algo: str) -> None:
    summary = farsighter.train(naf_tiny(algo, tmp_path / "run"))
    run = Path(summary["run_dir"])
    for name in ("config.json", "metrics.csv", "eval.csv", "policy.pt", "summary.json"):
        assert (run / name).exists(), name
    assert not (run / "success.csv").exists()  # Pendulum reports no is_success
    assert summary["global_step"] == 900 and summary["episodes"] == 4  # 200-step episodes
    assert np.isfinite(summary["final_eval_return"])
    policy = farsighter.load_agent(run)
    obs, _ = policy.make_env(seed=0).reset(seed=0)
    a1, a2 = policy.act(obs[None]), policy.act(obs[None])
    assert a1.shape == (1, 1) and np.array_equal(a1, a2) and abs(float(a1[0, 0])) <= 2.0


def test_same_seed_same_run(tmp_path: Path) -> None:
    for name, seed in (("a", 1), ("b", 1), ("c", 2)):
        farsighter.train(naf_tiny("farsighter-naf", tmp_path / name, total_steps=600, seed=seed))
    assert rows(tmp_path / "a") == rows(tmp_path / "b")
    wa, wb = weights(tmp_path / "a"), weights(tmp_path / "b")
    assert all(torch.equal(wa[k], wb[k]) for k in wa)
    assert rows(tmp_path / "a") != rows(tmp_path / "c")


@pytest.mark.parametrize("algo", ["knaf", "farsighter-naf"])
def test_crash_then_resume_equals_uninterrupted(
    tmp_path: Path, algo: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    extra = {"naf.noise": "ou"} if algo == "knaf" else {}
    full, crashed = tmp_path / "full", tmp_path / "crashed"
    farsighter.train(naf_tiny(algo, full, **extra))
    original = NAFAgent.learn

    def learn_then_crash(self: NAFAgent, global_step: int) -> dict[str, torch.Tensor]:
        if global_step == 700:
            raise KeyboardInterrupt  # killed after the checkpoint at 450
        return original(self, global_step)

    monkeypatch.setattr(NAFAgent, "learn", learn_then_crash)
    with pytest.raises(KeyboardInterrupt):
        farsighter.train(naf_tiny(algo, crashed, **extra))
    monkeypatch.setattr(NAFAgent, "learn", original)
    with pytest.raises(RunDirError):
        farsighter.train(naf_tiny(algo, crashed, **extra))
    farsighter.train(naf_tiny(algo, crashed, resume=True, **extra))
    assert rows(full) == rows(crashed)
    wf, wc = weights(full), weights(crashed)
    assert all(torch.equal(wf[k], wc[k]) for k in wf)
