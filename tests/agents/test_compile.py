"""Config.compile: the update step compiled by torch.compile (farsighter.agents.cuda_graph).

A compiled agent makes the same updates as an eager one (to float rounding), repeats itself
exactly for a fixed seed, and a second agent in the same process reuses the compiled code."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

from farsighter import make_config
from farsighter.agents.cuda_graph import check_compiler
from farsighter.config import validate
from farsighter.errors import ConfigError
from tests.agents.test_cuda_graph import _agent, _params
from tests.agents.test_farsighter_agent import feed as _feed
from tests.conftest import inner, parts


def test_compile_setting_is_checked(monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(ConfigError, match="compile is supported by"):
        validate(make_config("ob2i", "CartPole-v1", compile=True))
    with pytest.raises(ConfigError, match="do not combine"):
        validate(make_config("ddqn", "CartPole-v1", compile=True, cuda_graph="on"))
    validate(make_config("farsighter", "CartPole-v1", compile=True))
    monkeypatch.setattr("shutil.which", lambda name: None)
    with pytest.raises(ConfigError, match="needs a C\\+\\+ compiler"):
        check_compiler(True, "cpu")
    check_compiler(False, "cpu")


def _run(tmp_path: Path, algo: str, compiled: bool, **kw: Any) -> tuple[Any, list[float]]:
    agent = _agent(
        tmp_path, algo, compile=compiled, target_update_every=25, blr__posterior_every=40, **kw
    )
    _feed(agent, 300)
    losses = []
    for step in range(1, 121):  # 60 updates, target copies and (farsighter) refreshes
        m = agent.learn(step)
        if "td_loss" in m:
            losses.append(float(m["td_loss"]))
    return agent, losses


@pytest.mark.parametrize(
    ("algo", "extra"),
    [
        ("ddqn", {}),
        ("rnd", {}),  # DDQN's loss through the learner, on returns with the bonus
        ("farsighter", {"k_target": "max", "blr__target": "sample"}),
    ],
)
def test_compiled_updates_equal_eager_updates(
    tmp_path: Path, algo: str, extra: dict[str, Any]
) -> None:
    eager, eager_losses = _run(tmp_path / "eager", algo, False, **extra)
    first, first_losses = _run(tmp_path / "c1", algo, True, **extra)
    second, second_losses = _run(tmp_path / "c2", algo, True, **extra)
    assert hasattr(inner(first).learner.step, "_torchdynamo_orig_callable")  # the step is compiled
    np.testing.assert_allclose(first_losses, eager_losses, rtol=1e-4, atol=1e-6)
    for a, b in zip(_params(first), _params(eager), strict=True):
        torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-5)
    # a fixed seed repeats exactly, and the second agent ran on the code compiled for the first
    assert second_losses == first_losses
    for a, b in zip(_params(second), _params(first), strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=0)


def test_a_compiled_run_trains_checkpoints_and_resumes(tmp_path: Path) -> None:
    """The whole loop with --compile: training, evaluation, checkpoints and a resume, whose
    continuation equals the uninterrupted compiled run's."""
    from farsighter import load_agent, train
    from tests.conftest import tiny

    full = train(tiny("farsighter", tmp_path / "full", compile=True))
    train(tiny("farsighter", tmp_path / "cut", compile=True, total_steps=1_000))
    resumed = train(tiny("farsighter", tmp_path / "cut", compile=True, resume=True))
    assert full["global_step"] == resumed["global_step"] == 1_500
    assert resumed["final_eval_return"] == full["final_eval_return"]
    a, b = (inner(load_agent(tmp_path / d).agent).torso.state_dict() for d in ("full", "cut"))
    for name in a:
        torch.testing.assert_close(a[name], b[name], rtol=0, atol=0)


def test_compiled_agents_of_other_shapes_in_one_process(tmp_path: Path) -> None:
    """Another batch size or network width in the same process compiles anew (static shapes),
    and each compiled agent still matches its eager twin."""
    for i, extra in enumerate(({"batch_size": 8}, {"hidden_sizes": (24, 24)})):
        eager, eager_losses = _run(tmp_path / f"e{i}", "ddqn", False, **extra)
        comp, comp_losses = _run(tmp_path / f"c{i}", "ddqn", True, **extra)
        np.testing.assert_allclose(comp_losses, eager_losses, rtol=1e-4, atol=1e-6)


def test_a_compiled_farsighter_follows_its_switch(tmp_path: Path) -> None:
    """``blr.optimism until-reward`` (the general preset's) changes the loss's branch mid-run: a
    compiled step (never a CUDA graph) compiles the new branch, and its updates on both sides of
    the switch still equal the eager agent's (the optimistic targets, then the calibrated ones)."""

    def run(sub: str, compiled: bool) -> tuple[Any, list[float]]:
        agent = _agent(
            tmp_path / sub,
            "farsighter",
            compile=compiled,
            target_update_every=25,
            blr__posterior_every=40,
            blr__optimism="until-reward",
            blr__target="sample",
            k_target="max",
        )
        _feed(agent, 300, positive=False)  # no positive reward yet: the optimistic branch
        assert not parts(agent).calibrated
        losses = []
        for step in range(1, 121):
            if step == 61:
                _feed(agent, 1, seed=1, positive=True)  # the first reward: the switch
                assert parts(agent).calibrated
            m = agent.learn(step)
            if "td_loss" in m:
                losses.append(float(m["td_loss"]))
        return agent, losses

    eager, eager_losses = run("eager", False)
    comp, comp_losses = run("compiled", True)
    learner = inner(comp).learner
    assert hasattr(learner.step, "_torchdynamo_orig_callable") and not learner.graphs
    assert parts(comp).calibrated and len(comp_losses) == len(eager_losses) > 40
    np.testing.assert_allclose(comp_losses, eager_losses, rtol=1e-4, atol=1e-6)
    for a, b in zip(_params(comp), _params(eager), strict=True):
        torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-5)
