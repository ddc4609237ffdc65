"""No import cycle among objscan's own modules, computed from the code.

Every ``import`` counts, wherever it stands: at module level, inside a function (a delayed import only hides a
cycle, it does not break it) or under ``TYPE_CHECKING``. Importing ``a.b.c`` also runs the packages ``a`` and
``a.b``, so those count as edges too. Two granularities are checked: modules, and the top-level packages
(``common``, ``bench``, ``services.<name>``), because a package-level loop (A uses B uses A) is the same tangle
spread over more files.
"""

from __future__ import annotations

import ast
from pathlib import Path

from tests.conftest import REPO

PACKAGES = ("common", "services", "bench")


def project_modules(root: Path) -> dict[str, Path]:
    """Dotted module name -> file, for every module of the project's packages."""
    modules: dict[str, Path] = {}
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root)
        if rel.parts[0] not in PACKAGES or ".venv" in rel.parts:
            continue
        name = ".".join(rel.with_suffix("").parts)
        modules[name.removesuffix(".__init__")] = path
    return modules


def _imported_names(module: str, path: Path, node: ast.Import | ast.ImportFrom, modules: dict[str, Path]) -> list[str]:
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    base = node.module or ""
    if node.level:
        parts = module.split(".")
        if path.name != "__init__.py":
            parts = parts[:-1]
        parts = parts[: len(parts) - (node.level - 1)]
        base = ".".join([*parts, base] if base else parts)
    names = []
    for alias in node.names:
        candidate = f"{base}.{alias.name}"
        names.append(candidate if candidate in modules else base)
    return names


def _owning_module(name: str, modules: dict[str, Path]) -> str | None:
    while name and name not in modules:
        name = name.rpartition(".")[0]
    return name or None


def import_graph(root: Path) -> dict[str, set[str]]:
    """Module -> the project modules it imports (its parent packages included)."""
    modules = project_modules(root)
    graph: dict[str, set[str]] = {name: set() for name in modules}
    for module, path in modules.items():
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if not isinstance(node, ast.Import | ast.ImportFrom) or getattr(node, "module", None) == "__future__":
                continue
            for name in _imported_names(module, path, node, modules):
                target = _owning_module(name, modules)
                if target is None:
                    continue
                parts = target.split(".")
                for i in range(1, len(parts) + 1):
                    dep = ".".join(parts[:i])
                    if dep in modules and dep != module and not module.startswith(dep + "."):
                        graph[module].add(dep)
    return graph


def package_of(module: str) -> str:
    parts = module.split(".")
    return ".".join(parts[:2]) if parts[0] == "services" and len(parts) > 1 else parts[0]


def package_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    packages: dict[str, set[str]] = {}
    for module, deps in graph.items():
        source = package_of(module)
        packages.setdefault(source, set())
        for dep in deps:
            if package_of(dep) != source:
                packages[source].add(package_of(dep))
                packages.setdefault(package_of(dep), set())
    return packages


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one member (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = 0
    for start in graph:
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = counter
        counter += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found


def test_no_import_cycle_among_modules():
    assert cycles(import_graph(REPO)) == []


def test_no_import_cycle_among_packages():
    assert cycles(package_graph(import_graph(REPO))) == []


def test_the_checker_sees_a_cycle_hidden_in_a_function(tmp_path):
    pkg = tmp_path / "services" / "demo"
    pkg.mkdir(parents=True)
    (tmp_path / "services" / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from services.demo import b\n")
    (pkg / "b.py").write_text("def late():\n    from . import a\n    return a\n")
    assert cycles(import_graph(tmp_path)) == [["services.demo.a", "services.demo.b"]]


def test_the_checker_sees_a_package_level_cycle(tmp_path):
    for name in ("one", "two"):
        (tmp_path / "services" / name).mkdir(parents=True)
        (tmp_path / "services" / name / "__init__.py").write_text("")
    (tmp_path / "services" / "__init__.py").write_text("")
    (tmp_path / "services" / "one" / "x.py").write_text("import services.two.y\n")
    (tmp_path / "services" / "two" / "y.py").write_text("from services.one import z\n")
    (tmp_path / "services" / "one" / "z.py").write_text("")
    assert cycles(import_graph(tmp_path)) == []
    assert cycles(package_graph(import_graph(tmp_path))) == [["services.one", "services.two"]]
