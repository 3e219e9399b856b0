"""The package's layers point one way and no module imports itself back (docs/architecture.md).

Every ``import`` in ``src/dmtrack`` counts, also the lazy ones inside functions: a lazy import is a dependency
like any other, it is only paid for later. The checker is tested on a copy of the tree with an upward import
and a cycle planted in it, so it cannot pass by seeing nothing.
"""

from __future__ import annotations

import ast
import shutil
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"

# Bottom to top. A module may import from its own layer (without cycles) and from the layers below it.
LAYERS: list[set[str]] = [
    {"errors", ""},  # "" is dmtrack/__init__.py itself (it imports nothing eagerly)
    {"geometry"},
    {"io"},
    {"features", "datasets"},
    {"odometry"},
    {"initialization"},
    {"window", "calibration"},
    {"slam"},
    {"relocalisation"},
    {"training"},
    {"viz"},
    {"outputs"},
    {"evaluation"},
    {"pipeline"},
    {"experiments"},
    {"ros"},  # the ROS 2 node: a frame source and a sink around the run loop
    {"api", "cli", "__main__"},
]
MAX_LINES = 800


def _modules(src: Path) -> dict[str, Path]:
    out = {}
    for p in sorted((src / "dmtrack").rglob("*.py")):
        parts = p.relative_to(src).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


def import_graph(src: Path) -> dict[str, dict[str, int]]:
    """module → {imported dmtrack module: line}, with ``from pkg import submodule`` resolved to the submodule."""
    modules = _modules(src)

    def resolve(name: str) -> str:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name

    graph: dict[str, dict[str, int]] = {}
    for mod, path in modules.items():
        package = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
        deps: dict[str, int] = {}
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[: len(package.split(".")) - node.level + 1]
                    name = ".".join(base + ([node.module] if node.module else []))
                else:
                    name = node.module or ""
                subs = [f"{name}.{a.name}" for a in node.names if f"{name}.{a.name}" in modules]
                targets = subs if len(subs) == len(node.names) else [name, *subs]
            for t in targets:
                if t.split(".")[0] != "dmtrack":
                    continue
                r = resolve(t)
                if r and r != mod:
                    deps.setdefault(r, node.lineno)
        graph[mod] = deps
    return graph


def layer_of(module: str) -> int:
    parts = module.split(".")
    key = parts[1] if len(parts) > 1 else ""
    for i, names in enumerate(LAYERS):
        if key in names:
            return i
    raise KeyError(f"{module}: not in any layer of tests/test_layers.py (add its package to LAYERS)")


def upward_imports(graph: dict[str, dict[str, int]]) -> list[str]:
    bad = []
    for mod, deps in graph.items():
        for dep, line in deps.items():
            if layer_of(dep) > layer_of(mod):
                bad.append(f"{mod} (line {line}) imports {dep}, a higher layer")
    return sorted(bad)


def cycles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = 0
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(graph[root]))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            v, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(graph[w])))
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        found.append(sorted(comp))
    return found


def test_every_module_has_a_layer():
    for mod in _modules(SRC):
        layer_of(mod)


def test_layers_point_down():
    assert upward_imports(import_graph(SRC)) == []


def test_no_import_cycles():
    assert cycles(import_graph(SRC)) == []


def test_no_module_over_800_lines():
    long = {
        str(p.relative_to(SRC)): n
        for p in _modules(SRC).values()
        if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_LINES
    }
    assert long == {}


def test_checker_finds_an_upward_import_and_a_cycle(tmp_path: Path):
    shutil.copytree(SRC / "dmtrack", tmp_path / "dmtrack", ignore=shutil.ignore_patterns("__pycache__", "*.pth"))
    camera = tmp_path / "dmtrack" / "geometry" / "camera.py"
    camera.write_text(camera.read_text(encoding="utf-8") + "\n\ndef _late():\n    from dmtrack.cli import main\n")
    graph = import_graph(tmp_path)
    bad = upward_imports(graph)
    planted = [b for b in bad if b.startswith("dmtrack.geometry.camera")]
    assert planted and planted[0].endswith("imports dmtrack.cli, a higher layer")
    # the planted import also closes a loop: cli → … → geometry.camera → cli
    assert any("dmtrack.cli" in c and "dmtrack.geometry.camera" in c for c in cycles(graph))


def test_checker_finds_a_same_layer_cycle(tmp_path: Path):
    pkg = tmp_path / "dmtrack"
    (pkg / "features").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "features" / "__init__.py").write_text("")
    (pkg / "features" / "a.py").write_text("from dmtrack.features import b\n")
    (pkg / "features" / "b.py").write_text("def f():\n    from .a import g\n")
    graph = import_graph(tmp_path)
    assert graph["dmtrack.features.a"] == {"dmtrack.features.b": 1}
    assert graph["dmtrack.features.b"] == {"dmtrack.features.a": 2}
    assert cycles(graph) == [["dmtrack.features.a", "dmtrack.features.b"]]
    assert upward_imports(graph) == []


@pytest.mark.parametrize("module", ["dmtrack.pipeline", "dmtrack.odometry.vo"])
def test_lower_layers_do_not_load_higher_ones(module: str):
    """Importing a layer must not load a higher one as a side effect (a check on the real import machinery)."""
    import subprocess
    import sys

    code = (
        f"import sys, {module}\n"
        "bad = sorted(m for m in sys.modules if m.startswith(('dmtrack.experiments', 'dmtrack.cli', 'dmtrack.api')))\n"
        "print(bad)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
