"""Nothing in ``services/`` or ``common/`` exists only for the tests or the benchmarks, computed from the code.

Why: what ships is what runs on a cell. A parameter only a test passes (a fault hook), a helper only a benchmark
calls, or a product module that reaches into the benchmarks' scripted scans is code a user carries, reads and
cannot use, and it couples the product to its test harness. Tests inject faults by subclassing or patching
(``tests/library/helpers.CrashingLibrary``); the benchmarks' scripted twin scans (``bench/scenario.py``)
and emulated devices (``bench/software_d435.py``) are imported by ``bench/`` and the tests, never by a service.
The benchmark command itself (``objscan bench``, ``services/cli/cmd_bench.py``) is product and may import them.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

from tests.common.test_import_cycles import import_graph, project_modules
from tests.conftest import REPO

PRODUCT = ("common", "services")
#: The product's benchmark command: it runs ``bench/``, so it may import it.
BENCH_COMMAND = "services.cli.cmd_bench"
#: What only the benchmarks and the tests may import.
BENCH_ONLY = ("bench",)
#: A docstring or comment saying that code is there for the tests or the benchmarks.
TEST_ONLY_WORDS = re.compile(
    r"\bfor tests\b|\btests? only\b|\btest-only\b|\bonly (?:for|in) tests\b|\bfor (?:the )?benchmarks?\b"
    r"|\bbenchmarks? only\b|\bin tests\)|\bD435 for tests\b", re.IGNORECASE)
#: A parameter whose only caller is a test harness.
TEST_ONLY_PARAMETER = re.compile(r"(?:fault|crash|test)_?hook|^test_|_for_tests?$|^testing$")


def _product(module: str) -> bool:
    return module.split(".")[0] in PRODUCT and module != BENCH_COMMAND


def bench_imports(root: Path) -> dict[str, list[str]]:
    """Product module -> the benchmark-only modules it imports (delayed imports count)."""
    found = {}
    for module, deps in import_graph(root).items():
        if not _product(module):
            continue
        bad = sorted(d for d in deps if any(d == b or d.startswith(b + ".") for b in BENCH_ONLY))
        if bad:
            found[module] = bad
    return found


def words_for_tests(root: Path) -> list[str]:
    """``file:line`` of each product line that says its code is there for the tests or benchmarks."""
    found = []
    for module, path in project_modules(root).items():
        if not _product(module):
            continue
        for n, line in enumerate(path.read_text().splitlines(), 1):
            if TEST_ONLY_WORDS.search(line):
                found.append(f"{path.relative_to(root).as_posix()}:{n}: {line.strip()}")
    return found


def harness_parameters(root: Path) -> list[str]:
    """``module.function(parameter)`` of each product parameter named for a test harness."""
    found = []
    for module, path in project_modules(root).items():
        if not _product(module):
            continue
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                args = node.args
                for arg in [*args.posonlyargs, *args.args, *args.kwonlyargs]:
                    if TEST_ONLY_PARAMETER.search(arg.arg):
                        found.append(f"{module}.{node.name}({arg.arg})")
    return found


def test_no_product_module_imports_benchmark_code():
    assert bench_imports(REPO) == {}


def test_no_product_code_says_it_is_there_for_tests():
    assert words_for_tests(REPO) == []


def test_no_product_function_takes_a_test_harness_parameter():
    assert harness_parameters(REPO) == []


def test_the_checkers_see_a_test_hook_and_a_delayed_scenario_import(tmp_path):
    for pkg in ("services", "services/sim", "services/report", "services/cli", "bench"):
        (tmp_path / pkg).mkdir(parents=True, exist_ok=True)
        (tmp_path / pkg / "__init__.py").write_text("")
    (tmp_path / "bench" / "scenario.py").write_text("")
    (tmp_path / "bench" / "dynamic.py").write_text("from bench.scenario import x\n")  # bench: allowed
    (tmp_path / "services" / "cli" / "cmd_bench.py").write_text("import bench.dynamic\n")  # the command: allowed
    (tmp_path / "services" / "report" / "data.py").write_text(
        '"""Report data (for tests only)."""\n'
        "def truth(fault_hook=None):\n    from bench.scenario import x\n    return x\n")
    assert bench_imports(tmp_path) == {"services.report.data": ["bench", "bench.scenario"]}
    assert words_for_tests(tmp_path) == ['services/report/data.py:1: """Report data (for tests only)."""']
    assert harness_parameters(tmp_path) == ["services.report.data.truth(fault_hook)"]
