"""The package's folders depend on each other one way (issue #26 item 5): no folder imports a
folder that imports it, counting imports made inside functions too."""

from __future__ import annotations

import ast
import graphlib
from pathlib import Path

import farsighter

ROOT = Path(farsighter.__file__).parent


def _unit(module: str) -> str:
    """The layer a module belongs to: its folder under farsighter/, or the top-level module."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else parts[0]


def _module_of(file: Path) -> str:
    rel = file.relative_to(ROOT.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def import_graph() -> dict[str, set[str]]:
    """Folder -> the folders its modules import (anywhere in the file)."""
    graph: dict[str, set[str]] = {}
    for file in ROOT.rglob("*.py"):
        module = _module_of(file)
        if module == "farsighter":
            continue
        here = _unit(module)
        for node in ast.walk(ast.parse(file.read_text())):
            names: list[str] = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module == "farsighter":
                names = [f"farsighter.{a.name}" for a in node.names]  # from farsighter import x
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names = [node.module]
            for name in names:
                if name.startswith("farsighter."):
                    other = _unit(name)
                    if other != here:
                        graph.setdefault(here, set()).add(other)
    return graph


def test_sweeps_do_not_import_the_studies() -> None:
    graph = import_graph()
    assert "studies" in graph["cli"]  # the scan sees imports inside functions
    assert "sweep" in graph["studies"]  # studies run their grids through the sweep engine
    assert "studies" not in graph.get("sweep", set())


def test_the_package_graph_has_no_cycle() -> None:
    """Folders (agents, envs, ops, replay, studies, sweep) and top-level modules (config, train,
    session, ...) can be put in an order where each imports only those before it."""
    graph = import_graph()
    assert {"agents", "studies", "sweep", "config", "train"} <= set(graph)
    try:
        order = list(graphlib.TopologicalSorter(graph).static_order())
    except graphlib.CycleError as err:
        raise AssertionError(f"import cycle: {' -> '.join(err.args[1])}") from None
    assert order.index("sweep") < order.index("studies")


def test_no_function_of_the_package_is_over_80_lines() -> None:
    """Issue #26: a function that does not fit on a screen is split (docstring included)."""
    long = []
    for file in ROOT.rglob("*.py"):
        for node in ast.walk(ast.parse(file.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                length = (node.end_lineno or node.lineno) - node.lineno + 1
                if length > 80:
                    long.append(f"{file.relative_to(ROOT)}:{node.lineno} {node.name} ({length})")
    assert long == []


FAST_PATH = ("wrap_step", "GraphedStep", "graphs_enabled", "set_capturable", "torch.compile")
"""What belongs to the learner (farsighter/agents/learner.py), not to an agent's file."""


def test_agent_files_hold_their_math_only() -> None:
    """An agent is its networks and its loss: no agent file over 300 lines, and none building
    the fast path (CUDA graph, compile) or a target cache itself."""
    shared = {"__init__.py", "common.py", "cuda_graph.py", "learner.py", "protocol.py"}
    agents = sorted(p for p in (ROOT / "agents").glob("*.py") if p.name not in shared)
    assert len(agents) >= 7
    for path in agents:
        text = path.read_text()
        assert len(text.splitlines()) <= 300, f"{path.name}: {len(text.splitlines())} lines"
        for name in (*FAST_PATH, "TargetCache("):
            assert name not in text, f"{path.name} uses {name}"
