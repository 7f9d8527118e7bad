"""The package's import arrows: no cycle among modules, and the layers point down."""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"


def _module_imports() -> dict[str, set[str]]:
    """Each loosefit module -> the loosefit modules it imports at module level (not inside functions);
    ``from package import module`` points at the module, not at the package."""
    files = {}
    for path in sorted((SRC / "loosefit").rglob("*.py")):
        parts = list(path.relative_to(SRC).with_suffix("").parts)
        files[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = (path, parts[:-1])
    graph = {}
    for name, (path, package) in files.items():
        targets = set()
        for node in ast.parse(path.read_text()).body:  # top level only: deferred imports do not load at import
            if isinstance(node, ast.Import):
                targets |= {a.name for a in node.names}
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    base = ".".join(package[: len(package) - node.level + 1] + ([base] if base else []))
                for a in node.names:
                    targets.add(f"{base}.{a.name}" if f"{base}.{a.name}" in files else base)
        graph[name] = {t for t in targets if t in files and t != name}
    return graph


def test_no_import_cycle():
    graph = _module_imports()
    state: dict[str, int] = {}
    cycles = []

    def visit(m, path):
        state[m] = 1
        for t in sorted(graph[m]):
            if state.get(t) == 1:
                cycles.append(path[path.index(t):] + [t])
            elif t not in state:
                visit(t, path + [t])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])
    assert not cycles, cycles


def test_train_sits_below_models_and_training_above_both():
    graph = _module_imports()
    def inside(m, package):
        return m == package or m.startswith(package + ".")

    train = [m for m in graph if inside(m, "loosefit.train")]
    assert all(not inside(t, "loosefit.models") for m in train for t in graph[m]), \
        {m: sorted(t for t in graph[m] if inside(t, "loosefit.models")) for m in train}
    assert any(inside(t, "loosefit.models") for t in graph["loosefit.training"])
    assert any(inside(t, "loosefit.train") for t in graph["loosefit.training"])
    models = [m for m in graph if inside(m, "loosefit.models")]
    assert all(t != "loosefit.training" for m in models for t in graph[m])
