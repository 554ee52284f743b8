"""The layers of femodes (docs/guide/architecture.md, "How the code is organised"; the design's
layer picture), read from the source: every import, including imports inside functions, points
down or stays inside its layer; no import loops; no module takes another module's private names;
the generic solvers import nothing of femodes; harmonic balance and time integration do not know
each other.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "femodes"

#: Layer of each module, from the bottom (0) to the top. A module is matched by the longest
#: prefix in this table; the package ``femodes`` itself (the public face) sits just below the
#: application, which is the only layer allowed to import it.
LAYERS = {
    "femodes.solvers": 0,
    "femodes.laws": 1,
    "femodes.eigen": 2,
    "femodes.dynamic_stiffness": 2,
    "femodes.sparse_direct": 2,
    "femodes.sparse_pardiso": 2,
    "femodes.sparse_schur": 2,
    "femodes.fe": 2,
    "femodes.model": 2,
    "femodes.linear": 2,
    "femodes.reduction": 2,
    "femodes.hbm": 3,
    "femodes.time": 3,
    "femodes.time.shooting": 3,
    "femodes.store": 4,
    "femodes.results": 4,
    "femodes.exact_branch": 4,
    "femodes.analyses": 5,
    "femodes.analysis_inputs": 5,
    "femodes.static_contact": 5,
    "femodes.exact_response": 5,
    "femodes.nonsmooth_modes": 5,
    "femodes.sweep_guide": 5,
    "femodes.resonance": 5,
    "femodes.tongues": 5,
    "femodes.runs": 5,
    "femodes.floquet": 5,
    "femodes.stability_methods": 5,
    "femodes.error_methods": 5,
    "femodes.predictors": 0,
    "femodes.branch_stability": 5,
    "femodes.accuracy": 5,
    "femodes.mesh_error": 5,
    "femodes.switching": 5,
    "femodes.branch_points": 5,
    "femodes.fields": 6,
    "femodes.solid_cells": 6,
    "femodes.plot": 6,
    "femodes.io": 6,
    "femodes.viz": 6,
    "femodes": 7,
    "femodes.app": 8,
}


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {_module_name(p): p for p in sorted(ROOT.rglob("*.py"))}


def layer(module: str) -> int:
    best = max((k for k in LAYERS if module == k or module.startswith(k + ".")), key=len, default=None)
    assert best is not None, f"{module} has no layer in tests/test_architecture.py: place it in the design's picture"
    return LAYERS[best]


def _imports(module: str):
    """``(line, target module, imported names)`` of every femodes import in ``module``."""
    path = MODULES[module]
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "femodes":
                    yield node.lineno, _existing(alias.name), ()
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != "femodes":
                continue
            names = tuple(a.name for a in node.names)
            submodules = [f"{target}.{n}" for n in names if f"{target}.{n}" in MODULES]
            if submodules:  # from package import submodule
                for sub in submodules:
                    yield node.lineno, sub, ()
                names = tuple(n for n in names if f"{target}.{n}" not in MODULES)
                if not names:
                    continue
            yield node.lineno, _existing(target), names


def _existing(name: str) -> str:
    while name not in MODULES and "." in name:
        name = name.rpartition(".")[0]
    return name


EDGES = {m: [(line, t, names) for line, t, names in _imports(m) if t != m] for m in MODULES}


def test_every_module_has_a_layer():
    for m in MODULES:
        layer(m)


def test_imports_point_down():
    bad = [f"{m}:{line} imports {t} (layer {layer(t)} above {layer(m)})"
           for m, edges in EDGES.items() for line, t, _ in edges
           if layer(t) > layer(m)]
    assert not bad, "upward imports:\n" + "\n".join(bad)


def find_loops(graph: dict[str, set[str]]) -> list[str]:
    """Every cycle met by a depth-first search, as ``a -> b -> ... -> a``."""
    state: dict[str, int] = {}
    stack: list[str] = []
    loops: list[str] = []

    def visit(m: str) -> None:
        state[m] = 1
        stack.append(m)
        for t in sorted(graph.get(m, ())):
            if state.get(t) == 1:
                loops.append(" -> ".join(stack[stack.index(t):] + [t]))
            elif t not in state:
                visit(t)
        stack.pop()
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m)
    return loops


def test_loop_finder_finds_loops():
    assert find_loops({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == ["a -> b -> c -> a"]
    assert find_loops({"a": {"b", "c"}, "b": {"c"}, "c": set()}) == []


def test_no_import_loops():
    loops = find_loops({m: {t for _, t, _ in edges} for m, edges in EDGES.items()})
    assert not loops, "import loops:\n" + "\n".join(loops)


def test_no_private_names_across_modules():
    bad = [f"{m}:{line} takes {', '.join(n for n in names if n.startswith('_'))} from {t}"
           for m, edges in EDGES.items() for line, t, names in edges
           if any(n.startswith("_") for n in names)]
    assert not bad, "private names imported:\n" + "\n".join(bad)


def test_solvers_know_nothing_of_femodes():
    bad = [f"{m}:{line} imports {t}" for m, edges in EDGES.items() if m.startswith("femodes.solvers")
           for line, t, _ in edges if not t.startswith("femodes.solvers")]
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("a, b", [("femodes.hbm", "femodes.time"), ("femodes.time", "femodes.hbm")])
def test_harmonic_balance_and_time_integration_are_independent(a, b):
    bad = [f"{m}:{line} imports {t}" for m, edges in EDGES.items() if m.startswith(a)
           for line, t, _ in edges if t.startswith(b)]
    assert not bad, "\n".join(bad)


def test_no_module_reads_log_records():
    """Log lines are for people: no femodes code subclasses logging.Handler to read them back."""
    bad = []
    for m, path in MODULES.items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ClassDef) and any(ast.unparse(b).endswith("Handler") for b in node.bases):
                bad.append(f"{m}:{node.lineno} class {node.name}")
    assert not bad, "\n".join(bad)
