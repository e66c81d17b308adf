"""The library's shape (issue #63 item 5): checks that fail when it regresses. Module level, where
``test_layers`` checks folders: no import cycle between modules (imports under TYPE_CHECKING and
inside functions count), one training loop, no list of algorithms outside the algorithm table,
no protocol method left to raise NotImplementedError, no file over 600 lines."""

from __future__ import annotations

import ast
import graphlib
from pathlib import Path

import pytest

import farsighter
from farsighter import algorithms

ROOT = Path(farsighter.__file__).parent
MAX_LINES = 600
PROTOCOL_METHODS = {
    "act",
    "observe",
    "learn",
    "diagnostics",
    "q_estimate",
    "state_dict",
    "load_state_dict",
    "member",
}


def _modules() -> dict[str, Path]:
    out = {}
    for file in ROOT.rglob("*.py"):
        parts = list(file.relative_to(ROOT.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = file
    return out


def module_graph() -> dict[str, set[str]]:
    """Module -> the farsighter modules it imports, anywhere in the file (``from a.b import c``
    counts as an import of ``a.b.c`` when that is a module, else of ``a.b``)."""
    modules = _modules()

    def known(name: str) -> str:
        while name not in modules and "." in name:
            name = name.rsplit(".", 1)[0]
        return name

    graph: dict[str, set[str]] = {}
    for module, file in modules.items():
        package = module if file.name == "__init__.py" else module.rsplit(".", 1)[0]
        found = graph.setdefault(module, set())
        for node in ast.walk(ast.parse(file.read_text())):
            names: list[str] = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join([*up, base] if base else up)
                names = [f"{base}.{a.name}" for a in node.names]
            for name in names:
                if name.startswith("farsighter"):
                    other = known(name)
                    if other != module:
                        found.add(other)
    return graph


def test_no_import_cycle_between_modules() -> None:
    graph = module_graph()
    # the scan sees imports inside functions and under TYPE_CHECKING
    assert "farsighter.studies" in " ".join(graph["farsighter.cli"])
    try:
        tuple(graphlib.TopologicalSorter(graph).static_order())
    except graphlib.CycleError as exc:
        pytest.fail(f"import cycle between modules: {' -> '.join(exc.args[1])}")


def _trees() -> dict[Path, ast.Module]:
    return {file: ast.parse(file.read_text()) for file in ROOT.rglob("*.py")}


def test_one_training_loop() -> None:
    """One loop over environment steps (``while ... total_steps``), in farsighter/train.py."""
    loops = [
        (file.relative_to(ROOT.parent), node.lineno)
        for file, tree in _trees().items()
        for node in ast.walk(tree)
        if isinstance(node, ast.While)
        and any(
            isinstance(n, ast.Attribute) and n.attr == "total_steps" for n in ast.walk(node.test)
        )
    ]
    assert len(loops) == 1 and str(loops[0][0]) == "farsighter/train.py", loops


def test_no_algorithm_list_outside_the_table() -> None:
    """No tuple, list, set or dict literal names two or more algorithms, except in the table
    and in the presets (which hold per-algorithm settings of a preset: data, not a list of
    which algorithms can do something). Literals keyed by agent modules (``Algorithm.agent``:
    per-agent data such as what a policy file keeps) are allowed."""
    names = set(algorithms.NAMES)
    agents = {a.agent for a in algorithms.TABLE}
    allowed = {ROOT / "algorithms.py", ROOT / "config" / "presets.py"}
    found = []
    for file, tree in _trees().items():
        if file in allowed:
            continue
        for node in ast.walk(tree):
            if isinstance(node, ast.Tuple | ast.List | ast.Set):
                items = node.elts
            elif isinstance(node, ast.Dict):
                items = [k for k in node.keys if k is not None]
            else:
                continue
            listed = {i.value for i in items if isinstance(i, ast.Constant)} & names
            if len(listed) >= 2 and not listed <= agents:
                found.append(f"{file.relative_to(ROOT.parent)}:{node.lineno} {sorted(listed)}")
    assert not found, found


def test_no_protocol_method_raises_not_implemented() -> None:
    found = [
        f"{file.relative_to(ROOT.parent)}:{fn.lineno} {fn.name}"
        for file, tree in _trees().items()
        for fn in ast.walk(tree)
        if isinstance(fn, ast.FunctionDef) and fn.name in PROTOCOL_METHODS
        for node in ast.walk(fn)
        if isinstance(node, ast.Raise)
        and "NotImplementedError" in ast.unparse(node.exc if node.exc else node)
    ]
    assert not found, found


def test_no_file_over_the_line_bound() -> None:
    long = {
        str(file.relative_to(ROOT.parent)): n
        for file in ROOT.rglob("*.py")
        if (n := len(file.read_text().splitlines())) > MAX_LINES
    }
    assert not long, f"files over {MAX_LINES} lines: {long}"


def test_no_seed_batched_twin() -> None:
    twins = sorted(p.name for p in (ROOT / "agents").glob("*_seeds.py"))
    assert not twins, twins
