"""The exploration suite's file (``suite.yaml`` beside this module), read and checked.

It is the one place that lists the task families of ``farsighter suite``
(:mod:`farsighter.studies.suite`), the set each family sits in (selection or validation; SPEC
section 6), their tasks with their step budgets, time limits and normalised-score references
(0: the uniform random policy's expected return; 1: the optimal or best known return; each with
its source), and the agents (a label, an algorithm and its overrides). ``scripts/
suite_references.py`` computes or measures the references and rewrites them in the file.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from farsighter.config.presets import (
    PREVIOUS_GENERAL_FARSIGHTER,
    PREVIOUS_GENERAL_FARSIGHTER_52,
    PREVIOUS_GENERAL_FARSIGHTER_53,
)
from farsighter.studies.runner import Agent

SUITE_FILE = Path(__file__).with_name("suite.yaml")
SETS = ("selection", "validation")
"""The sets a family sits in; ``--set all`` takes both."""


@dataclass(frozen=True)
class Reference:
    """A normalised-score reference: its return and where the number comes from."""

    value: float
    source: str


@dataclass(frozen=True)
class SuiteTask:
    """One task of the suite (see suite.yaml)."""

    env: str
    family: str
    steps: int
    """The full form's step budget."""
    time_limit: int
    """The most steps of one episode: no budget goes below it."""
    random: Reference
    best: Reference

    def normalise(self, value: float) -> float:
        """``(R - random) / (best - random)``: 0 for the uniform policy, 1 for the best."""
        return (value - self.random.value) / (self.best.value - self.random.value)


@dataclass(frozen=True)
class SuiteFamily:
    name: str
    set: str
    kind: str
    tasks: tuple[SuiteTask, ...]


@dataclass(frozen=True)
class Suite:
    """The suite file, read and checked."""

    families: dict[str, SuiteFamily]
    agents: tuple[Agent, ...]
    default_agents: tuple[str, ...]
    seeds: tuple[int, ...]
    quick_seeds: tuple[int, ...]
    quick_fraction: float

    def tasks(self) -> dict[str, SuiteTask]:
        """Environment id -> its task, family by family."""
        return {t.env: t for f in self.families.values() for t in f.tasks}


class _UniqueKeys(yaml.SafeLoader):
    """YAML's safe loader, refusing a key given twice in one mapping (PyYAML keeps the last one
    silently: a family listed twice would vanish)."""

    def construct_mapping(self, node: Any, deep: bool = False) -> Any:
        keys = [self.construct_object(k, deep=deep) for k, _ in node.value]
        twice = sorted({str(k) for k in keys if keys.count(k) > 1})
        if twice:
            line = node.start_mark.line + 1
            raise ValueError(f"{', '.join(twice)} given twice in one mapping (line {line})")
        return super().construct_mapping(node, deep=deep)


def _reference(task: dict[str, Any], key: str, where: str) -> Reference:
    source = task.get(f"{key}_source")
    if not isinstance(source, str) or not source.strip():
        raise ValueError(f"{where}: '{key}' needs a source ('{key}_source')")
    return Reference(float(task[key]), source)


BASES: dict[str, dict[str, Any]] = {
    "": {},
    "session-45": PREVIOUS_GENERAL_FARSIGHTER,
    "session-52": PREVIOUS_GENERAL_FARSIGHTER_52,
    "session-53": PREVIOUS_GENERAL_FARSIGHTER_53,
}
"""An agent's ``base`` in a study's file: overrides kept in the library, under its own."""
AGENT_KEYS = ("algo", "base", "overrides")
"""What an agent of a study's file may give: its algorithm (required), a :data:`BASES` name and
its overrides of the library's defaults (dotted config keys)."""


def read_yaml(path: Path) -> Any:
    """A study's YAML file, read with the safe loader and refused where one mapping gives a key
    twice (ValueError)."""
    return yaml.load(Path(path).read_text(), Loader=_UniqueKeys)  # a SafeLoader


def load_agents(data: dict[str, Any], path: Path) -> tuple[tuple[Agent, ...], tuple[str, ...]]:
    """The agents of a study's file (``agents``: label -> {algo, base, overrides}) and its
    ``default_agents``, checked (ValueError, naming what is wrong): the suite's and the
    exploration study's (``farsighter/studies/explore/agents.yaml``)."""
    from farsighter.algorithms import ALGORITHMS

    entries = data.get("agents")
    if not isinstance(entries, dict) or not entries:
        raise ValueError(f"{path}: 'agents' must map each label to its algorithm and overrides")
    for label, a in entries.items():
        if not isinstance(a, dict) or "algo" not in a or set(a) - set(AGENT_KEYS):
            raise ValueError(
                f"{path}: agent {label!r} takes 'algo' (required), 'base', 'overrides'"
            )
        if a["algo"] not in ALGORITHMS:
            raise ValueError(f"{path}: agent {label!r}: unknown algorithm {a['algo']!r}")
    unknown = [a["base"] for a in entries.values() if a.get("base", "") not in BASES]
    if unknown:
        raise ValueError(f"{path}: unknown agent base(s) {unknown}; accepted: {list(BASES)}")
    agents = tuple(
        Agent(str(label), a["algo"], {**BASES[a.get("base", "")], **(a.get("overrides") or {})})
        for label, a in entries.items()
    )
    default = tuple(data["default_agents"])
    stray = [a for a in default if a not in entries]
    if stray:
        raise ValueError(f"{path}: default_agents {stray} are not in agents")
    return agents, default


def load_suite(path: Path = SUITE_FILE) -> Suite:
    """Read and check a suite file (ValueError, naming what is wrong, on a malformed one)."""
    data = read_yaml(path)
    families: dict[str, SuiteFamily] = {}
    seen: set[str] = set()
    for name, fam in data["families"].items():
        if fam.get("set") not in SETS:
            raise ValueError(f"{path}: family {name}'s set must be one of {SETS}")
        tasks = []
        for t in fam["tasks"]:
            where = f"{path}: {name}/{t['env']}"
            if t["env"] in seen:
                raise ValueError(f"{where}: the task is listed twice")
            seen.add(t["env"])
            task = SuiteTask(
                t["env"],
                name,
                int(t["steps"]),
                int(t["time_limit"]),
                _reference(t, "random", where),
                _reference(t, "best", where),
            )
            if not task.random.value < task.best.value:
                raise ValueError(f"{where}: random ({task.random.value}) must be below best")
            if task.steps < task.time_limit:
                raise ValueError(f"{where}: the budget is shorter than one episode")
            tasks.append(task)
        families[name] = SuiteFamily(name, fam["set"], str(fam["kind"]), tuple(tasks))
    agents, default = load_agents(data, path)
    quick = data["quick"]
    return Suite(
        families,
        agents,
        default,
        tuple(data["seeds"]),
        tuple(quick["seeds"]),
        float(quick["fraction"]),
    )
