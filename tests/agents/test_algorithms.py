"""The algorithm table is the one list of algorithms: config resolution, validation, the spaces
check, the presets listing and agent construction all derive from it."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

from farsighter import algorithms
from farsighter.agents import build_agent
from farsighter.cli import main
from farsighter.config import PRESETS, make_config
from farsighter.envs import check_spaces
from farsighter.errors import ConfigError, EnvError
from tests.conftest import inner

DISCRETE = gym.spaces.Discrete(2)
BOX_ACTIONS = gym.spaces.Box(-2.0, 2.0, (1,), np.float32)
OBS = gym.spaces.Box(-np.inf, np.inf, (4,), np.float32)


def test_the_table_imports_nothing_heavy() -> None:
    for module in (algorithms, importlib.import_module("farsighter.errors")):
        tree = ast.parse(Path(str(module.__file__)).read_text())
        imported = {
            (node.module or "") if isinstance(node, ast.ImportFrom) else alias.name
            for node in ast.walk(tree)
            if isinstance(node, ast.Import | ast.ImportFrom)
            for alias in node.names
        }
        assert imported <= {
            "__future__",
            "collections.abc",
            "dataclasses",
            "typing",
            "farsighter.errors",
        }


@pytest.mark.parametrize("algo", algorithms.NAMES)
def test_every_algorithm_builds_its_agent_from_the_table(algo: str) -> None:
    spec = algorithms.get(algo)
    cfg = make_config(algo, "Pendulum-v1" if spec.actions == "continuous" else "CartPole-v1")
    acts = BOX_ACTIONS if spec.actions == "continuous" else DISCRETE
    agent = build_agent(cfg, OBS, acts, frame_stack=1, device=torch.device("cpu"))
    module = importlib.import_module(f"farsighter.agents.{spec.agent}")
    assert type(inner(agent)) is getattr(module, "SEED_AGENTS", None) or module.AGENT
    assert agent.act(np.zeros((2, 4), np.float32), 0).shape[0] == 2
    assert agent.diagnostics().get("k", 1.0) == cfg.k


def test_unknown_algorithm_lists_the_table() -> None:
    with pytest.raises(ConfigError, match="accepted: " + ", ".join(algorithms.NAMES)):
        make_config("dqn")


def test_spaces_check_names_every_algorithm_of_the_other_kind() -> None:
    with pytest.raises(EnvError) as err:
        check_spaces("naf", OBS, DISCRETE)
    for name in algorithms.names_for("discrete"):  # ob2i, rnd and krnd included
        assert name in str(err.value)
    with pytest.raises(EnvError) as err:
        check_spaces("ob2i", OBS, BOX_ACTIONS)
    for name in algorithms.names_for("continuous"):
        assert name in str(err.value)


def test_preset_then_algorithm_then_flags() -> None:
    # the algorithm's defining values survive any generic preset; a flag still wins
    for preset in ("atari", "cartpole", "control", "maze"):
        assert make_config("ob2i", "CartPole-v1", preset=preset).eps_end == 0.1
        assert make_config("naf", "Pendulum-v1", preset=preset).loss == "mse"
    assert make_config("ddqn", "CartPole-v1", preset="cartpole").eps_end == 0.02
    assert make_config("ob2i", "CartPole-v1", preset="cartpole", eps_end=0.05).eps_end == 0.05
    # a preset made for one algorithm is its variant: applied over its values, refused elsewhere
    assert make_config("bdqn", "CartPole-v1", preset="control").blr.redraw == "every"
    assert make_config("bdqn", "CartPole-v1").blr.redraw == "episode"  # general, per algorithm
    assert make_config("bdqn", "CartPole-v1", preset="bdqn").blr.redraw == "step"
    with pytest.raises(ConfigError, match="preset 'bdqn' is made for --algo bdqn"):
        make_config("farsighter", "CartPole-v1", preset="bdqn")


def test_adaptive_k_support_comes_from_the_table() -> None:
    from farsighter.config import validate

    for spec in algorithms.TABLE:
        env = "Pendulum-v1" if spec.actions == "continuous" else "CartPole-v1"
        k = 1 if spec.episodic else 2
        cfg = make_config(
            spec.name, env, **{"adaptive_k.enabled": True, "k": k, "adaptive_k.k_min": 1}
        )
        if spec.adaptive_k:
            validate(cfg)
        else:
            with pytest.raises(ConfigError, match="only supported by --algo farsighter and"):
                validate(cfg)


def test_presets_command_lists_every_preset_and_algorithm(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["presets"]) == 0
    out = capsys.readouterr().out
    for name in PRESETS:
        assert f"\n{name}" in f"\n{out}"
    for spec in algorithms.TABLE:
        assert f"\n{spec.name} [{spec.actions} actions]" in out


def test_explained_values_are_the_values_a_run_gets_for_every_preset_and_algorithm() -> None:
    """explain_config (what `farsighter presets --algo X` prints) gives, for every (preset,
    algorithm) pair a config can be built for, exactly the fields of make_config's config, each
    attributed to the last layer that set it."""
    from farsighter.config import config_layers, explain_config

    checked = 0
    for preset in ["auto", *PRESETS]:
        for spec in algorithms.TABLE:
            env = "Pendulum-v1" if spec.actions == "continuous" else "CartPole-v1"
            try:
                cfg = make_config(spec.name, env, preset=preset)
            except ConfigError:  # a preset made for another algorithm
                continue
            layers = config_layers(spec.name, env, preset)
            for key, value, source in explain_config(spec.name, env, preset):
                obj = cfg
                for part in key.split("."):
                    obj = getattr(obj, part)
                assert obj == value, (preset, spec.name, key)
                setters = [name for name, layer in layers if key in layer]
                assert source == (setters[-1] if setters else "field default")
            checked += 1
    assert checked >= 2 * len(algorithms.TABLE)


def test_presets_with_algo_prints_the_resolved_values_and_their_source(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["presets", "--algo", "farsighter"]) == 0
    out = capsys.readouterr().out
    assert "resolves to general" in out
    lines = {line.split("=")[0].strip(): line for line in out.splitlines() if "=" in line}
    assert "'cut'" in lines["k_target"] and "(preset general, for farsighter)" in lines["k_target"]
    assert (
        "'k'" in lines["blr.redraw"] and "(preset general, for farsighter)" in lines["blr.redraw"]
    )
    assert "eval_max_steps" not in lines  # left at its default: only with --all
    assert main(["presets", "--algo", "bdqn", "--preset", "bdqn", "--all"]) == 0
    out = capsys.readouterr().out
    assert "blr.redraw" in out and "(preset bdqn)" in out and "(field default)" in out
