"""The layers hold: the solver is pure numerics and its tests reach only it and the simulator.

Every import statement (at the top or inside a function) is read with ast, so a lazy import
inside a function counts as well: solver/ imports nothing of the server, the web page or the
drivers; drivers/ nothing of the server, the web page or an HTTP library; tests/solver and the
test helpers it imports nothing of the server or of the server's and the page's tests.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
HTTP = ("fastapi", "starlette", "uvicorn", "httpx", "requests", "flask", "werkzeug", "aiohttp")
RULES = {  # folder -> modules it may not import (a prefix matches its submodules too)
    "solver": ("robocal.server", "robocal.web", "robocal.drivers", *HTTP),
    "drivers": ("robocal.server", "robocal.web", *HTTP),
    "tests/solver": ("robocal.server", "robocal.web", "tests.server", "tests.web", *HTTP),
}
PACKAGE = {"solver": "robocal.solver", "drivers": "robocal.drivers", "tests/solver": "tests.solver"}


def imports(path: Path, package: str) -> list[tuple[int, str]]:
    """(line, absolute module name) of every import in the file, relative ones resolved."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # from .x / from ..x: relative to the file's package
                parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(parts + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            out.append((node.lineno, base))
            out += [(node.lineno, f"{base}.{a.name}") for a in node.names]
    return out


def forbidden(name: str, banned) -> bool:
    return any(name == b or name.startswith(b + ".") for b in banned)


def violations(folder: str) -> list[str]:
    """file:line module for every banned import under the folder (and, for tests/solver, in the
    test helpers at tests/ it imports)."""
    banned = RULES[folder]
    files = [(p, PACKAGE[folder]) for p in sorted((ROOT / folder).glob("*.py"))]
    if folder == "tests/solver":  # the shared helpers it imports are held to the same rule
        helpers = {
            m
            for p, pkg in files
            for _, m in imports(p, pkg)
            if m.startswith("tests.") and m.count(".") == 1
        }
        files += [(ROOT / "tests" / f"{m.split('.')[1]}.py", "tests") for m in sorted(helpers)]
    found: dict[str, str] = {}  # file:line -> the first banned name its statement imports
    for p, pkg in files:
        for line, name in imports(p, pkg) if p.exists() else []:
            if forbidden(name, banned):
                found.setdefault(f"{p.relative_to(ROOT)}:{line}", name)
    return [f"{where} imports {name}" for where, name in found.items()]


@pytest.mark.parametrize("folder", sorted(RULES))
def test_no_upward_import(folder):
    assert violations(folder) == []


def test_the_check_sees_an_upward_import(tmp_path, monkeypatch):
    """Not vacuous: a lazy import inside a function, and one in a helper it uses, are caught."""
    (tmp_path / "tests" / "solver").mkdir(parents=True)
    (tmp_path / "tests" / "solver" / "test_x.py").write_text(
        "def f():\n    from robocal.server.calibration import workflow\n"
    )
    (tmp_path / "tests" / "solver" / "test_y.py").write_text("from tests.helper import x\n")
    (tmp_path / "tests" / "helper.py").write_text("from robocal.server.formats import cell_json\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    found = violations("tests/solver")
    assert found == [
        "tests/solver/test_x.py:2 imports robocal.server.calibration",
        "tests/helper.py:1 imports robocal.server.formats",
    ], found
    assert violations("solver") == []  # an empty folder breaks no rule
