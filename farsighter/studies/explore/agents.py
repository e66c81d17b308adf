"""The exploration study's agents, read from ``agents.yaml`` beside this module.

The file lists each agent as ``label: {algo: ..., overrides: {...}}`` and the labels a study
runs by default; it is read and checked by the suite file's helpers
(:func:`farsighter.studies.suite_file.load_agents`), so the two studies' agent files have one
format. A variant is added to the file, not here.
"""

from __future__ import annotations

from pathlib import Path

from farsighter.studies.runner import Agent
from farsighter.studies.suite_file import load_agents, read_yaml

AGENTS_FILE = Path(__file__).with_name("agents.yaml")


def load(path: Path = AGENTS_FILE) -> tuple[tuple[Agent, ...], tuple[str, ...]]:
    """The agents of an agents file and its default list (ValueError on a malformed one)."""
    return load_agents(read_yaml(path), path)


AGENTS, DEFAULT_AGENTS = load()
"""Every agent the study can run (``--agents all``), and those it runs when none is named."""
COLORS = {a.label: f"C{i}" for i, a in enumerate(AGENTS)}
"""Each agent's colour in the figures, by its place in the file."""
