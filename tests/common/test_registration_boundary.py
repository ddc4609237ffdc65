"""Registration is used through its one public module, ``services.registration.api``, computed from the code.

Why: live scans, replay, ``objscan reconstruct``, ``objscan import``, the report, export, library and the
benchmarks all run the same registration pipeline; when they reach into its internals they assemble it each in
their own way (and the assemblies drift apart). Every ``import`` counts, wherever it stands, as in the
import-cycle test. Registration's own code and its own tests (``tests/registration``) may use its internals;
so may the two test drivers that start or coordinate the registration service itself (its Zenoh face).
"""

from __future__ import annotations

import ast
from pathlib import Path

from tests.common.test_import_cycles import _imported_names, project_modules
from tests.conftest import REPO

PUBLIC = "services.registration.api"
HOME = "services.registration"
# test drivers of the registration service's own Zenoh face (not users of the library)
SERVICE_DRIVERS = {
    "tests.faults.registration_worker",  # runs ``services.registration.service.main`` as a fault-test worker
    "tests.hardening.netns_driver",  # coordinates pair jobs with ``dynamic_face.distributed_map`` across hosts
}


def _modules(root: Path) -> dict[str, Path]:
    """The project's modules and the test modules, by dotted name."""
    modules = project_modules(root)
    for path in sorted((root / "tests").rglob("*.py")) if (root / "tests").is_dir() else []:
        modules[".".join(path.relative_to(root).with_suffix("").parts).removesuffix(".__init__")] = path
    return modules


def _inside(module: str) -> bool:
    """Registration itself, its tests and its service drivers may import its internals."""
    return (module == HOME or module.startswith(HOME + ".") or module.startswith("tests.registration")
            or module in SERVICE_DRIVERS)


def internal_imports(root: Path) -> dict[str, list[str]]:
    """Module outside registration -> the registration modules other than the public one it imports."""
    modules = _modules(root)
    found: dict[str, list[str]] = {}
    for module, path in modules.items():
        if _inside(module):
            continue
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if not isinstance(node, ast.Import | ast.ImportFrom):
                continue
            for name in _imported_names(module, path, node, modules):
                if name.startswith(HOME + ".") and not (name == PUBLIC or name.startswith(PUBLIC + ".")):
                    found.setdefault(module, []).append(name)
                elif name == HOME and isinstance(node, ast.ImportFrom):  # ``from services.registration import x``
                    found.setdefault(module, []).extend(f"{HOME}.{a.name}" for a in node.names if a.name != "api")
    return {m: sorted(set(n)) for m, n in found.items() if n}


def test_nothing_outside_registration_imports_its_internals():
    assert internal_imports(REPO) == {}


def test_the_checker_sees_an_internal_import_in_a_function(tmp_path):
    reg = tmp_path / "services" / "registration"
    (reg / "dynamic").mkdir(parents=True)
    (tmp_path / "services" / "other").mkdir()
    for init in ("services", "services/registration", "services/registration/dynamic", "services/other"):
        (tmp_path / init / "__init__.py").write_text("")
    (reg / "api.py").write_text("")
    (reg / "dynamic" / "model.py").write_text("")
    (reg / "inner.py").write_text("from services.registration.dynamic import model\n")  # inside: allowed
    (tmp_path / "services" / "other" / "ok.py").write_text("from services.registration.api import build_model\n")
    (tmp_path / "services" / "other" / "bad.py").write_text(
        "def late():\n    from services.registration.dynamic.model import build_model\n    return build_model\n")
    (tmp_path / "services" / "other" / "bad2.py").write_text("from services.registration import dynamic\n")
    assert internal_imports(tmp_path) == {
        "services.other.bad": ["services.registration.dynamic.model"],
        "services.other.bad2": ["services.registration.dynamic"],
    }
