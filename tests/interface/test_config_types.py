"""Config values from Python keywords are read as their fields' types or refused in one line, and
a built config holding a value of the wrong type is refused before any check compares it."""

from __future__ import annotations

import dataclasses
import re

import gymnasium as gym
import pytest
import torch

import farsighter
from farsighter.agents import build_agent
from farsighter.config import BLRConfig, make_config, validate
from farsighter.errors import ConfigError


def test_keywords_are_read_as_their_fields_types() -> None:
    cfg = make_config(
        "farsighter",
        "CartPole-v1",
        total_steps=1e5,  # an integral float for an integer field
        hidden_sizes=[32, 32.0],  # a list for a tuple
        lr="3e-4",  # YAML 1.1 reads 3e-4 as a string
        blr={"prior_std": 2},  # a section as a dict of its fields
    )
    validate(cfg)
    assert cfg.total_steps == 100_000 and type(cfg.total_steps) is int
    assert cfg.hidden_sizes == (32, 32) and all(type(h) is int for h in cfg.hidden_sizes)
    assert cfg.lr == 3e-4 and cfg.blr.prior_std == 2
    # the rest of the section keeps the preset's values, which a whole section replaces
    default = make_config("farsighter", "CartPole-v1")
    assert cfg.blr.random_features == default.blr.random_features != BLRConfig().random_features
    whole = make_config("farsighter", "CartPole-v1", blr=BLRConfig(prior_std=3.0))
    assert whole.blr == BLRConfig(prior_std=3.0)


@pytest.mark.parametrize(
    ("values", "message"),
    [
        ({"k": "5"}, "k must be an integer (got '5')"),
        ({"k": 2.5}, "k must be an integer (got 2.5)"),
        ({"k": True}, "k must be an integer (got True)"),
        ({"seed": None}, "seed must be an integer (got None)"),
        ({"lr": "fast"}, "lr must be a number (got 'fast')"),
        ({"hidden_sizes": 64}, "hidden_sizes must be a list of integers (got 64)"),
        ({"optimizer": 1}, "optimizer must be a string (got 1)"),
        ({"lrr": 0.1}, "unknown config field 'lrr' (did you mean 'lr'?)"),
        ({"blr": {"prior_sd": 1}}, "unknown config field 'blr.prior_sd' (did you mean 'blr.prior"),
        ({"blr": 3}, "blr must be a BLRConfig or a dict of its fields (got 3)"),
    ],
)
def test_a_value_its_field_cannot_take_is_one_line(values: dict, message: str) -> None:
    with pytest.raises(ConfigError) as exc:
        make_config("farsighter", "CartPole-v1", **values)
    assert str(exc.value).startswith(message) and "\n" not in str(exc.value)


def test_named_choices_no_check_names_are_refused_and_a_registry_extends_its_own() -> None:
    """optimizer = 'sgd' trained with Adam before any check named it; blr.redraw takes the
    schedules registered in farsighter.exploration.SCHEDULES (tests/agents/test_exploration_rules
    trains with one), and its agent names them when the name is none of them."""
    with pytest.raises(ConfigError, match=r"^optimizer must be one of rmsprop, adam \(got 'sgd'\)"):
        validate(make_config("ddqn", "CartPole-v1", optimizer="sgd"))
    cfg = make_config("farsighter", "CartPole-v1", **{"blr.redraw": "nightly"})
    validate(cfg)  # the registry's to judge
    with pytest.raises(ConfigError, match=r"^blr.redraw 'nightly' is no schedule; accepted: step"):
        build_agent(
            cfg,
            gym.spaces.Box(-1, 1, (4,)),
            gym.spaces.Discrete(2),
            frame_stack=1,
            device=torch.device("cpu"),
        )


@pytest.mark.parametrize(
    ("values", "message"),
    [
        ({"total_steps": 1e5}, "total_steps must be an integer (got 100000.0)"),
        ({"hidden_sizes": [64]}, "hidden_sizes must be a tuple of integers (got [64])"),
        ({"lr": "0.01"}, "lr must be a number (got '0.01')"),
        ({"blr": {"prior_std": 2.0}}, "blr must be a BLRConfig (got {'prior_std': 2.0})"),
    ],
)
def test_a_built_config_of_the_wrong_type_is_refused(values: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=f"^{re.escape(message)}$"):
        validate(dataclasses.replace(make_config("farsighter", "CartPole-v1"), **values))


def test_the_model_api_takes_the_same_keywords() -> None:
    model = farsighter.DDQN("CartPole-v1", total_steps=2e3, hidden_sizes=[16])
    assert model.config.total_steps == 2000 and model.config.hidden_sizes == (16,)
    with pytest.raises(ConfigError, match="^k must be an integer"):
        farsighter.DDQN("CartPole-v1", k="3")
    with pytest.raises(ConfigError, match=r"^total_steps must be an integer >= 1 \(got 2.5\)"):
        model.learn(2.5)
