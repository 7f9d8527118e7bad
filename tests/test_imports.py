"""The package's import arrows: the layers point down, no cycle among modules or across packages, no module over
600 lines.

Every package and top-level module of ``loosefit`` (a *unit*) sits in one of :data:`LAYERS`, lowest first. A unit
may import from its own layer and the layers below; an import from a higher layer, at module level or deferred into
a function, fails :func:`test_imports_point_down_the_layers`. The layers, as the code has them:

- the foundations (errors, paths, configs, optional extras, devices, threads, signals);
- ``geometry``, then ``io`` (mesh files, on geometry), then ``motion`` (motions, their files and the heading frame);
- ``body`` (bodies posed by motions), then ``sim`` (the cloth simulator, colliding with a posed body);
- ``garment`` (garments made, imported and draped on a body with the simulator), then ``data`` (the dataset store
  of garments, bodies, motions and simulated sequences);
- what reads or fills a store: ``metrics``, ``rig`` (the ``prepare`` stage and its readers), ``simulate`` (plans
  run into a store), ``motion_range``;
- ``train`` (the training loop, losses, checkpoints: it knows no model), then ``models``, then ``training`` (a
  method's training run: a model on the train loop) and ``pretrained``;
- ``animate``, then what animates: ``animate_any``, ``export_rig``, ``export_onnx``, ``quantize``; then ``viz``, ``report``, ``demo``;
- the command line.
"""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"

#: Units of the package, lowest layer first (see the module docstring). A new module or package goes into the
#: lowest layer that holds everything it imports.
LAYERS = [
    ("loosefit", "errors", "paths", "config", "extras", "device", "threads", "interrupts", "quiet"),
    ("geometry",),
    ("io",),
    ("motion",),
    ("body",),
    ("sim",),
    ("garment",),
    ("data",),
    ("metrics", "rig", "simulate", "motion_range"),
    ("train",),
    ("models",),
    ("training", "pretrained"),
    ("animate",),
    ("animate_any", "export_rig", "export_onnx", "quantize"),
    ("viz",),
    ("report",),
    ("demo",),
    ("cli_args", "cli_commands", "cli_parser", "cli"),
]
#: The most lines a module may have.
MAX_LINES = 600


def _modules() -> dict[str, tuple[Path, list[str]]]:
    """Every loosefit module -> its file and the package it is in (its name's parts)."""
    files = {}
    for path in sorted((SRC / "loosefit").rglob("*.py")):
        parts = list(path.relative_to(SRC).with_suffix("").parts)
        if parts[-1] == "__init__":
            files[".".join(parts[:-1])] = (path, parts[:-1])
        else:
            files[".".join(parts)] = (path, parts[:-1])
    return files


def _module_imports(deferred: bool) -> dict[str, dict[str, int]]:
    """Each loosefit module -> ``{imported loosefit module: line}``, at module level only or (``deferred``) also
    inside functions and classes. ``from package import module`` points at the module, not at the package."""
    files = _modules()
    graph = {}
    for name, (path, package) in files.items():
        tree = ast.parse(path.read_text())
        nodes = ast.walk(tree) if deferred else tree.body  # module level: what loads when the module loads
        targets: dict[str, int] = {}
        for node in nodes:
            found = []
            if isinstance(node, ast.Import):
                found = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    base = ".".join(package[: len(package) - node.level + 1] + ([base] if base else []))
                found = [f"{base}.{a.name}" if f"{base}.{a.name}" in files else base for a in node.names]
            for target in found:
                if target in files and target != name:
                    targets.setdefault(target, node.lineno)
        graph[name] = targets
    return graph


def unit(module: str) -> str:
    """The layer unit of a module: its top-level package or module under ``loosefit`` (``loosefit`` itself for the
    package's ``__init__``)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else parts[0]


def _layer_of() -> dict[str, int]:
    return {u: i for i, layer in enumerate(LAYERS) for u in layer}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The cycles a depth-first search meets in ``graph`` (each as the path that closes it)."""
    state: dict[str, int] = {}
    cycles = []

    def visit(m, path):
        state[m] = 1
        for t in sorted(graph.get(m, ())):
            if state.get(t) == 1:
                cycles.append(path[path.index(t):] + [t])
            elif t not in state:
                visit(t, path + [t])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])
    return cycles


def test_every_unit_has_a_layer():
    layer_of = _layer_of()
    assert sum(len(layer) for layer in LAYERS) == len(layer_of), "a unit is declared in two layers"
    missing = sorted({unit(m) for m in _modules()} - set(layer_of))
    assert not missing, f"declare {missing} in LAYERS (tests/test_imports.py): the lowest layer holding its imports"
    stale = sorted(set(layer_of) - {unit(m) for m in _modules()})
    assert not stale, f"LAYERS names units the package no longer has: {stale}"


def test_imports_point_down_the_layers():
    """No module imports from a unit of a higher layer, at module level or inside a function."""
    layer_of = _layer_of()
    upward = []
    for module, targets in _module_imports(deferred=True).items():
        for target, line in targets.items():
            src, dst = unit(module), unit(target)
            if src in layer_of and dst in layer_of and layer_of[dst] > layer_of[src]:
                upward.append(f"{module}:{line} imports {target} (layer {layer_of[src]} -> {layer_of[dst]})")
    assert not upward, "\n".join(upward)


def test_no_import_cycle_across_packages():
    """The units' graph (deferred imports included) has no cycle: two packages never import each other, however
    lazily."""
    graph: dict[str, set[str]] = {}
    for module, targets in _module_imports(deferred=True).items():
        graph.setdefault(unit(module), set()).update(unit(t) for t in targets if unit(t) != unit(module))
    cycles = _cycles(graph)
    assert not cycles, cycles


def test_no_import_cycle_among_modules():
    """Module-level imports (what loads when a module loads) form no cycle."""
    graph = {m: set(targets) for m, targets in _module_imports(deferred=False).items()}
    cycles = _cycles(graph)
    assert not cycles, cycles


def test_no_module_over_the_line_limit():
    long = {str(path.relative_to(SRC)): n for path, _ in _modules().values()
            if (n := len(path.read_text().splitlines())) > MAX_LINES}
    assert not long, f"modules over {MAX_LINES} lines (split them by concept): {long}"


def test_the_checks_catch_an_upward_import_and_a_cycle():
    """The checks themselves, on a made-up graph: an arrow from a lower layer up and a two-unit loop."""
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c", "a"]]
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": set()}) == []
    layer_of = _layer_of()
    assert layer_of["geometry"] < layer_of["models"] < layer_of["cli"]
    assert unit("loosefit.models.layers.gat_ln") == "models" and unit("loosefit") == "loosefit"
    assert unit("loosefit.cli") == "cli"


def test_train_sits_below_models_and_training_above_both():
    graph = _module_imports(deferred=False)

    def inside(m, package):
        return m == package or m.startswith(package + ".")

    train = [m for m in graph if inside(m, "loosefit.train")]
    assert all(not inside(t, "loosefit.models") for m in train for t in graph[m]), \
        {m: sorted(t for t in graph[m] if inside(t, "loosefit.models")) for m in train}
    assert any(inside(t, "loosefit.models") for t in graph["loosefit.training"])
    assert any(inside(t, "loosefit.train") for t in graph["loosefit.training"])
    models = [m for m in graph if inside(m, "loosefit.models")]
    assert all(t != "loosefit.training" for m in models for t in graph[m])
