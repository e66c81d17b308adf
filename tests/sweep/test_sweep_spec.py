"""Sweep files: grid expansion, value precedence, TOML and YAML alike, and one-line errors."""

from __future__ import annotations

import itertools
from pathlib import Path

import pytest

from farsighter.config import make_config
from farsighter.errors import FarsighterError
from farsighter.sweep import Resources, SweepError, SweepSpec, Trial, load_spec, parse_spec

K_STUDY_TOML = """
name = "k-study"
description = "k on two control tasks"

[grid]
agent = ["kddqn", "Farsighter-adaptive"]
env = ["CartPole-v1", "Acrobot-v1"]
k = [2, 10]
"blr.noise_std" = [0.5]
seed = [1, 2, 3]

[set]
preset = "cartpole"
total_steps = 20000
lr = 0.001
k = 99
hidden_sizes = [32, 32]

[agents.Farsighter-adaptive]
algo = "farsighter"
"adaptive_k.enabled" = true
lr = 0.002

[resources]
cpus = 0.5
gpus = 0.25
max_concurrent = 4
retries = 1
"""

K_STUDY_YAML = """
name: k-study
description: k on two control tasks
grid:
  agent: [kddqn, Farsighter-adaptive]
  env: [CartPole-v1, Acrobot-v1]
  k: [2, 10]
  blr.noise_std: [0.5]
  seed: [1, 2, 3]
set:
  preset: cartpole
  total_steps: 20000
  lr: 0.001
  k: 99
  hidden_sizes: [32, 32]
agents:
  Farsighter-adaptive:
    algo: farsighter
    adaptive_k.enabled: true
    lr: 0.002
resources: {cpus: 0.5, gpus: 0.25, max_concurrent: 4, retries: 1}
"""


def _write(tmp_path: Path, text: str, name: str = "sweep.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_grid_expands_in_order_with_every_value(tmp_path: Path) -> None:
    spec = load_spec(_write(tmp_path, K_STUDY_TOML))
    assert spec.name == "k-study" and spec.description == "k on two control tasks"
    assert spec.resources == Resources(cpus=0.5, gpus=0.25, max_concurrent=4, retries=1)
    assert spec.default_dir == Path("sweeps/k-study")
    assert len(spec.trials) == 24
    # agents outermost, then envs, then the other grid fields in file order, seeds innermost
    expected = list(
        itertools.product(
            ["kddqn", "Farsighter-adaptive"], ["CartPole-v1", "Acrobot-v1"], [2, 10], [1, 2, 3]
        )
    )
    assert [(t.agent, t.env, dict(t.swept)["k"], t.seed) for t in spec.trials] == expected
    names = [t.name for t in spec.trials]
    assert len(set(names)) == 24
    assert names[0] == "cartpole-v1/kddqn__k-2__blr-noise-std-0-5__s1"
    assert names[-1] == "acrobot-v1/farsighter-adaptive__k-10__blr-noise-std-0-5__s3"

    for trial in spec.trials:
        assert trial.swept == (("k", dict(trial.swept)["k"]), ("blr.noise_std", 0.5))
        assert trial.preset == "cartpole"
        run_dir = f"sweeps/k-study/{trial.name}"
        cfg = trial.config(run_dir)
        assert cfg.k == dict(trial.swept)["k"]  # the grid beats [set]'s k = 99
        assert cfg.seed == trial.seed and cfg.env == trial.env
        assert cfg.blr.noise_std == 0.5
        assert cfg.total_steps == 20000
        assert cfg.hidden_sizes == (32, 32)  # a TOML list becomes the field's tuple
        assert cfg.preset == "cartpole" and cfg.run_dir == run_dir
        assert cfg.progress is False and cfg.runtime.torch_threads == 1
        if trial.agent == "Farsighter-adaptive":
            assert cfg.algo == "farsighter" and trial.algo == "farsighter"
            assert cfg.adaptive_k.enabled is True
            assert cfg.lr == 0.002  # the agent's value beats [set]'s
        else:
            assert cfg.algo == "kddqn" and not cfg.adaptive_k.enabled
            assert cfg.lr == 0.001

    # The trial's config is make_config with its overrides, seed and run directory.
    trial = spec.trials[5]
    assert trial.config("x") == make_config(
        trial.algo,
        trial.env,
        trial.preset,
        **{"torch_threads": 1, **dict(trial.overrides)},
        progress=False,
        seed=trial.seed,
        run_dir="x",
    )


def test_precedence_set_then_agent_then_grid(tmp_path: Path) -> None:
    text = """
name = "order"
[grid]
agent = ["A", "ddqn"]
env = ["CartPole-v1"]
seed = [0]
gamma = [0.9]
[set]
preset = "control"
gamma = 0.5
lr = 0.01
batch_size = 16
torch_threads = 2
[agents.A]
algo = "ddqn"
preset = "maze"
gamma = 0.7
lr = 0.02
"""
    a, plain = load_spec(_write(tmp_path, text)).trials
    assert dict(a.overrides) == {
        "gamma": 0.9,
        "lr": 0.02,
        "batch_size": 16,
        "runtime.torch_threads": 2,  # a runtime field by its plain name
    }
    assert a.preset == "maze" and plain.preset == "control"
    cfg_a, cfg_plain = a.config("a"), plain.config("b")
    assert cfg_a.gamma == cfg_plain.gamma == 0.9  # grid beats agent beats set
    assert (cfg_a.lr, cfg_plain.lr) == (0.02, 0.01)
    assert cfg_a.batch_size == cfg_plain.batch_size == 16
    assert cfg_a.runtime.torch_threads == 2  # [set] may choose the threads
    assert cfg_a.eval_max_steps == 200  # the maze preset's


def test_nested_tables_tuples_and_presets_in_the_grid(tmp_path: Path) -> None:
    text = """
name = "nested"
[grid]
agent = ["farsighter"]
env = ["CartPole-v1"]
blr.prior_std = [0.5, 2.0]
hidden_sizes = [[16], [32, 32]]
preset = ["general", "cartpole"]
seed = [7]
[set.blr]
noise_std = 3.0
"""
    spec = load_spec(_write(tmp_path, text))
    assert len(spec.trials) == 8
    first = spec.trials[0]
    assert first.name == (
        "cartpole-v1/farsighter__blr-prior-std-0-5__hidden-sizes-16__preset-general__s7"
    )
    assert first.swept == (("blr.prior_std", 0.5), ("hidden_sizes", (16,)), ("preset", "general"))
    assert "preset" not in dict(first.overrides)
    cfgs = [t.config("r") for t in spec.trials]
    assert [c.preset for c in cfgs[:2]] == ["general", "cartpole"]
    assert {c.hidden_sizes for c in cfgs} == {(16,), (32, 32)}
    assert {c.blr.prior_std for c in cfgs} == {0.5, 2.0}
    assert all(c.blr.noise_std == 3.0 for c in cfgs)


def test_yaml_and_toml_give_the_same_trials(tmp_path: Path) -> None:
    from_toml = load_spec(_write(tmp_path, K_STUDY_TOML, "k.toml"))
    from_yaml = load_spec(_write(tmp_path, K_STUDY_YAML, "k.yaml"))
    from_yml = load_spec(_write(tmp_path, K_STUDY_YAML, "k.yml"))
    assert from_toml.trials == from_yaml.trials == from_yml.trials
    assert from_toml.resources == from_yaml.resources
    assert from_yaml.source.endswith("k.yaml")
    assert isinstance(from_yaml, SweepSpec) and isinstance(from_yaml.trials[0], Trial)


def test_yaml_exponent_strings_are_numbers(tmp_path: Path) -> None:
    text = "name: e\ngrid: {agent: [ddqn], env: [CartPole-v1], seed: [1], lr: [1e-4]}\n"
    (trial,) = load_spec(_write(tmp_path, text, "e.yaml")).trials
    assert trial.config("r").lr == 0.0001 and trial.name == "cartpole-v1/ddqn__lr-0-0001__s1"


def test_environment_arguments_and_integral_floats(tmp_path: Path) -> None:
    """env_kwargs swept as lists of NAME=VALUE items; TOML's 1e3 for an integer field."""
    text = (
        'name = "lake"\n[grid]\nagent = ["ddqn"]\nenv = ["FrozenLake-v1"]\nseed = [1]\n'
        'env_kwargs = [["is_slippery=False"], ["is_slippery=True", "map_name=8x8"]]\n'
        "[set]\ntotal_steps = 1e3\n"
    )
    trials = load_spec(_write(tmp_path, text)).trials
    assert [t.config("r").env_kwargs for t in trials] == [
        ("is_slippery=False",),
        ("is_slippery=True", "map_name=8x8"),
    ]
    assert all(type(t.config("r").total_steps) is int for t in trials)
    assert trials[1].name == "frozenlake-v1/ddqn__env-kwargs-is-slippery-true-map-name-8x8__s1"


def test_parse_spec_takes_a_mapping() -> None:
    data = {"name": "m", "grid": {"agent": ["ddqn"], "env": ["CartPole-v1"], "seed": [1, 2]}}
    spec = parse_spec(data, "inline")
    assert [t.name for t in spec.trials] == ["cartpole-v1/ddqn__s1", "cartpole-v1/ddqn__s2"]
    assert spec.resources == Resources() and spec.source == "inline"
    with pytest.raises(SweepError, match=r"^inline: missing grid\.seed"):
        parse_spec({"name": "m", "grid": {"agent": ["ddqn"], "env": ["CartPole-v1"]}}, "inline")


def _toml(grid: str = "", rest: str = "", head: str = 'name = "t"\n') -> str:
    return f'{head}[grid]\nagent = ["ddqn"]\nenv = ["CartPole-v1"]\nseed = [1]\n{grid}\n{rest}'


BAD_FILES = [
    # the file
    ("malformed TOML", "sweep.toml", 'name = "t\n', r"malformed TOML: .*line 1"),
    (
        "malformed YAML",
        "sweep.yaml",
        "name: t\ngrid: [a, b\n",
        r"malformed YAML: .*\(at line 3, column 1\)",
    ),
    ("not a mapping", "sweep.yaml", "- a\n- b\n", r"top level must be a table"),
    ("extension", "sweep.json", _toml(), r"unknown sweep file type '\.json'; accepted: \.toml"),
    # the sections
    ("top-level key", "sweep.toml", _toml(rest="[grdi]\nk = [1]\n"), r"unknown top-level key "),
    ("missing name", "sweep.toml", _toml(head=""), r"missing 'name'"),
    ("empty name", "sweep.toml", _toml(head='name = ""\n'), r"name must be a non-empty string"),
    ("name type", "sweep.toml", _toml(head="name = 3\n"), r"name must be a non-empty string"),
    ("missing grid", "sweep.toml", 'name = "t"\n', r"missing \[grid\]"),
    (
        "missing grid.env",
        "sweep.toml",
        'name = "t"\n[grid]\nagent = ["ddqn"]\nseed = [1]\n',
        r"missing grid\.env",
    ),
    ("empty list", "sweep.toml", _toml("k = []"), r"grid\.k is empty: give at least one value"),
    ("not a list", "sweep.toml", _toml("k = 3"), r"grid\.k must be a list"),
    ("bad seed", "sweep.toml", _toml().replace("[1]", "[-1]"), r"seeds are integers >= 0"),
    ("seed type", "sweep.toml", _toml().replace("[1]", '["a"]'), r"seeds are integers >= 0"),
    # agents
    (
        "unknown agent",
        "sweep.toml",
        _toml().replace('["ddqn"]', '["nope"]'),
        r"grid\.agent: unknown agent 'nope'; accepted: algorithm names \(ddqn, .*\[agents\]",
    ),
    (
        "agent without algo",
        "sweep.toml",
        _toml(rest="[agents.A]\nlr = 0.1\n"),
        r"\[agents\.A\] has no algo: give algo = one of ddqn",
    ),
    (
        "agent with unknown algo",
        "sweep.toml",
        _toml(rest='[agents.A]\nalgo = "dqn"\n'),
        r"agents\.A\.algo: unknown algorithm 'dqn'; accepted: ddqn",
    ),
    # fields
    ("unknown grid field", "sweep.toml", _toml("kk = [1]"), r"grid: unknown config field 'kk'"),
    (
        "unknown set field",
        "sweep.toml",
        _toml(rest="[set]\nlrr = 0.1\n"),
        r"set: unknown config field 'lrr' \(did you mean 'lr'\?\)",
    ),
    (
        "unknown agent field",
        "sweep.toml",
        _toml(rest='[agents.A]\nalgo = "ddqn"\n"blr.prior" = 1.0\n'),
        r"agents\.A: unknown config field 'blr\.prior'",
    ),
    (
        "unknown nested field",
        "sweep.toml",
        _toml(rest="[set.blr]\nnoise = 1.0\n"),
        r"set: unknown config field 'blr\.noise'",
    ),
    ("group", "sweep.toml", _toml(rest="[set]\nblr = 1\n"), r"set\.blr is a group of fields"),
    ("run_dir", "sweep.toml", _toml('run_dir = ["x"]'), r"grid\.run_dir cannot be set"),
    ("algo", "sweep.toml", _toml('algo = ["ddqn"]'), r"grid\.algo cannot be .*grid\.agent"),
    ("resume", "sweep.toml", _toml(rest="[set]\nresume = true\n"), r"set\.resume cannot be"),
    ("env in set", "sweep.toml", _toml(rest='[set]\nenv = "x"\n'), r"set\.env cannot .*grid\.env"),
    # values
    ("type", "sweep.toml", _toml('k = ["ten"]'), r"grid\.k must be an integer \(got 'ten'\)"),
    ("literal", "sweep.toml", _toml('loss = ["l1"]'), r"grid\.loss must be one of huber, mse"),
    ("bool", "sweep.toml", _toml(rest="[set]\nstride = 1\n"), r"set\.stride must be true or"),
    ("invalid value", "sweep.toml", _toml("k = [0]"), r"trial cartpole-v1/ddqn__k-0__s1: k must"),
    (
        "preset for another algo",
        "sweep.toml",
        _toml(rest='[set]\npreset = "bdqn"\n'),
        r"trial cartpole-v1/ddqn__s1: preset 'bdqn' is made for --algo bdqn",
    ),
    (
        "collision",
        "sweep.toml",
        _toml().replace("seed = [1]", "seed = [1, 1]"),
        r"two trials have the same name 'cartpole-v1/ddqn__s1'",
    ),
    # resources
    (
        "resources key",
        "sweep.toml",
        _toml(rest="[resources]\nmemory = 4\n"),
        r"unknown key resources\.memory; accepted: cpus, gpus, max_concurrent, retries",
    ),
    ("cpus", "sweep.toml", _toml(rest="[resources]\ncpus = 0\n"), r"resources\.cpus must be a "),
    ("gpus", "sweep.toml", _toml(rest="[resources]\ngpus = -1\n"), r"resources\.gpus must be"),
    (
        "retries",
        "sweep.toml",
        _toml(rest="[resources]\nretries = 1.5\n"),
        r"resources\.retries must be an integer >= 0",
    ),
    (
        "max_concurrent",
        "sweep.toml",
        _toml(rest="[resources]\nmax_concurrent = -1\n"),
        r"resources\.max_concurrent must be an integer >= 0",
    ),
]


@pytest.mark.parametrize(
    ("file", "text", "match"), [case[1:] for case in BAD_FILES], ids=[c[0] for c in BAD_FILES]
)
def test_bad_files_raise_one_line(tmp_path: Path, file: str, text: str, match: str) -> None:
    path = _write(tmp_path, text, file)
    with pytest.raises(SweepError, match=match) as info:
        load_spec(path)
    message = str(info.value)
    assert message.startswith(f"{path}: ") and "\n" not in message
    assert isinstance(info.value, FarsighterError)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(SweepError, match=r"nope\.toml: no such sweep file"):
        load_spec(tmp_path / "nope.toml")
    with pytest.raises(SweepError, match=r"not a file"):
        load_spec(tmp_path)
