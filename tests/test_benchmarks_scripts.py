"""Every benchmark script finds the benchmark modules it imports from where it lives: the standing ones in
``benchmarks/``, the finished investigations in ``benchmarks/experiments/`` (which import ``_common`` and the
standing scripts from the folder above). Read statically: each script's ``sys.path.insert`` arguments are
evaluated with ``__file__`` set to the script, and each imported name that is a benchmark module must be in
the script's own folder or in one of the folders it inserts; nothing is imported or run."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
BENCHMARKS = REPO / "benchmarks"
SCRIPTS = sorted([*BENCHMARKS.glob("*.py"), *(BENCHMARKS / "experiments").glob("*.py")])
#: Every benchmark module, wherever it lives.
MODULES = {p.stem for p in SCRIPTS}


def inserted_folders(script: Path) -> list[Path]:
    """The folders ``script`` puts on ``sys.path`` (module level or inside a function), with its module-level
    path constants (``ROOT = Path(__file__).resolve().parents[2]`` ...) evaluated first."""
    tree = ast.parse(script.read_text(encoding="utf-8"))
    names: dict[str, object] = {"Path": Path, "str": str, "__file__": str(script)}
    for node in tree.body:
        if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name):
            try:
                names[node.targets[0].id] = eval(compile(ast.Expression(node.value), str(script), "eval"),
                                                 {"__builtins__": {}}, dict(names))
            except Exception:  # not a path constant
                continue
    folders = []
    for node in ast.walk(tree):
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "insert"
                and ast.unparse(node.func.value) == "sys.path" and len(node.args) == 2):
            value = eval(compile(ast.Expression(node.args[1]), str(script), "eval"), {"__builtins__": {}}, dict(names))
            folders.append(Path(value).resolve())
    return folders


def imported_benchmark_modules(script: Path) -> set[str]:
    """The benchmark modules ``script`` imports, at the top or inside a function."""
    found = set()
    for node in ast.walk(ast.parse(script.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.add(node.module.split(".")[0])
    return found & MODULES


def test_the_reader_sees_an_experiment_reach_the_folder_above(tmp_path):
    script = tmp_path / "experiments" / "probe.py"
    script.parent.mkdir()
    script.write_text("import sys\nfrom pathlib import Path\n\nROOT = Path(__file__).resolve().parents[1]\n"
                      "sys.path.insert(0, str(ROOT))\nsys.path.insert(0, str(Path(__file__).resolve().parent / 'x'))\n")
    assert inserted_folders(script) == [tmp_path.resolve(), (tmp_path / "experiments" / "x").resolve()]


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: str(p.relative_to(BENCHMARKS)))
def test_every_imported_benchmark_module_is_on_the_scripts_path(script):
    folders = [script.parent.resolve(), *inserted_folders(script)]
    missing = sorted(name for name in imported_benchmark_modules(script)
                     if not any((folder / f"{name}.py").is_file() for folder in folders))
    assert missing == [], f"{script.relative_to(REPO)} imports {missing}, found in none of {folders}"
