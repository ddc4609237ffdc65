"""docs/configuration.md lists every environment variable the project reads, and nothing it no longer reads.

The scan: in Python (services/, common/, bench/, scripts/), every ``OBJSCAN_*`` name written as a string, and
any other name read through ``os.environ`` / ``os.getenv`` / an ``env`` map (by literal or by a module constant);
in the shell, Docker and compose files, every ``OBJSCAN_*`` name and every ``$NAME`` they expand."""

from __future__ import annotations

import ast
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
PY_ROOTS = ("services", "common", "bench", "scripts")
OTHER_FILES = ("Dockerfile", "docker-compose.yml", "deploy/docker-compose.tls.yml", "deploy/docker-compose.real.yml",
               "deploy/gen-certs.sh", "scripts/demo.sh", "scripts/install.sh", "scripts/lock.sh", "scripts/test.sh",
               ".ci/run")
OBJSCAN_NAME = re.compile(r"\bOBJSCAN_[A-Z0-9_]+\b")
ENV_MAPS = {"environ", "env", "environment"}  # names of the maps the code reads the environment through
# variables every shell sets, or a script sets itself before reading: not configuration of objscan
SHELL_OWN = {"HOME", "PATH", "PWD", "USER", "SHELL", "BASH_SOURCE", "UID", "0", "1", "2", "3", "@", "*", "#", "?",
             "!", "$"}


def _is_env_map(node: ast.AST) -> bool:
    if isinstance(node, ast.Attribute):
        return node.attr == "environ"
    return isinstance(node, ast.Name) and node.id in ENV_MAPS


def _python_reads(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), str(path))
    constants = {t.id: n.value.value for n in tree.body if isinstance(n, ast.Assign)
                 and isinstance(n.value, ast.Constant) and isinstance(n.value.value, str)
                 for t in n.targets if isinstance(t, ast.Name)}

    def name_of(node: ast.AST) -> str | None:
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            return node.value
        if isinstance(node, ast.Name):
            return constants.get(node.id)
        return None

    found: set[str] = set()
    for node in ast.walk(tree):
        key = None
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and OBJSCAN_NAME.fullmatch(node.value):
            key = node.value
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.args and (
                (node.func.attr in ("get", "setdefault", "pop") and _is_env_map(node.func.value))
                or node.func.attr == "getenv"):
            key = name_of(node.args[0])
        elif isinstance(node, ast.Subscript) and isinstance(node.ctx, ast.Load) and _is_env_map(node.value):
            key = name_of(node.slice)
        elif isinstance(node, ast.Compare) and len(node.ops) == 1 and isinstance(node.ops[0], (ast.In, ast.NotIn)) \
                and _is_env_map(node.comparators[0]):
            key = name_of(node.left)
        if key and re.fullmatch(r"[A-Z][A-Z0-9_]*", key):
            found.add(key)
    return found


def _shell_reads(path: Path) -> set[str]:
    text = path.read_text()
    found = set(OBJSCAN_NAME.findall(text))
    found |= {m for m in re.findall(r"\$\{?([A-Za-z_][A-Za-z0-9_]*)", text) if m.isupper()}
    assigned = set(re.findall(r"(?m)^\s*(?:export\s+|local\s+|ARG\s+)?([A-Z_][A-Z0-9_]*)=", text))
    defaulted = set(re.findall(r"\$\{([A-Z_][A-Z0-9_]*):?[-=]", text))  # ${NAME:-default}: the caller's, if set
    return {v for v in found - SHELL_OWN if v.startswith("OBJSCAN_") or v not in assigned or v in defaulted}


def variables_read() -> dict[str, set[str]]:
    """Every variable the project reads -> the files that read it."""
    out: dict[str, set[str]] = {}
    for root in PY_ROOTS:
        for path in sorted((REPO / root).rglob("*.py")):
            for var in _python_reads(path):
                out.setdefault(var, set()).add(str(path.relative_to(REPO)))
    for rel in OTHER_FILES:
        if (REPO / rel).is_file():
            for var in _shell_reads(REPO / rel):
                out.setdefault(var, set()).add(rel)
    return out


def variables_documented() -> set[str]:
    """The first column of the tables in docs/configuration.md (``| `NAME` | ...``)."""
    text = (REPO / "docs" / "configuration.md").read_text()
    return set(re.findall(r"(?m)^\|\s*`([A-Z][A-Z0-9_]*)`\s*\|", text))


def test_every_variable_the_code_reads_is_in_the_table():
    read, documented = variables_read(), variables_documented()
    missing = {v: sorted(files) for v, files in read.items() if v not in documented}
    assert not missing, f"read by the code but not in docs/configuration.md: {missing}"


def test_the_table_lists_no_variable_the_code_no_longer_reads():
    stale = variables_documented() - set(variables_read())
    assert not stale, f"in docs/configuration.md but read nowhere: {sorted(stale)}"


def test_the_scan_finds_reads_of_every_form(tmp_path):
    """The scanner itself: a literal, a module constant, a subscript, ``in``, ``getenv``; not a docstring word."""
    src = tmp_path / "m.py"
    src.write_text('"""Mentions HOME_DIR in prose."""\nimport os\nVAR = "OTHER_A"\n'
                   'a = os.environ.get(VAR)\nb = os.getenv("OTHER_B")\nc = os.environ["OTHER_C"]\n'
                   'd = "OTHER_D" in os.environ\ne = env.get("OTHER_E")\nf = "OBJSCAN_F"\n')
    assert _python_reads(src) == {"OTHER_A", "OTHER_B", "OTHER_C", "OTHER_D", "OTHER_E", "OBJSCAN_F"}
