"""No module imports the old top-level names: everything goes through the robocal root."""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
GONE = {"server", "solver", "drivers"}
FOLDERS = ("robocal", "solver", "drivers", "server", "tests", "migrations", "docker")


def old_root_imports(source: str) -> list[int]:
    """Lines that import server, solver or drivers as a top-level (absolute) name."""
    lines = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
        else:
            continue
        if any(n.split(".")[0] in GONE for n in names):
            lines.append(node.lineno)
    return lines


def test_the_check_sees_every_form_of_an_old_import():
    src = "from server.cli import x\nimport solver\nimport drivers.abb as a\nfrom . import server\n"
    assert old_root_imports(src) == [1, 2, 3]
    assert old_root_imports("from robocal.server.cli import main\nfrom .server import y\n") == []


def test_no_module_imports_an_old_top_level_name():
    paths = [p for folder in FOLDERS for p in sorted((ROOT / folder).rglob("*.py"))]
    assert len(paths) > 100  # the walk reached the tree
    found = [
        f"{path.relative_to(ROOT)}:{line}"
        for path in paths
        for line in old_root_imports(path.read_text(encoding="utf-8"))
    ]
    assert found == [], "write robocal.<name>: " + ", ".join(found)
