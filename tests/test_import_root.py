"""Every `robocal.*` import resolves statically in a checkout: robocal/ holds links to the top-level
folders, so a reader that follows files (an IDE, mypy, an import-graph drawer) finds each module
without running the package's code."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = ("solver", "drivers", "server", "web", "migrations")


def _resolves(dotted: str) -> bool:
    """Whether robocal.<dotted> is a module or package file under ROOT/robocal."""
    path = ROOT.joinpath(*dotted.split("."))
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


def _imports(tree: ast.AST):
    """(module, names) of every robocal import in a parsed file."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "robocal":
                    yield alias.name, ()
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            if node.module.split(".")[0] == "robocal":
                yield node.module, tuple(a.name for a in node.names)


def test_the_package_links_the_top_level_folders():
    for folder in FOLDERS:
        link = ROOT / "robocal" / folder
        assert link.is_symlink() and link.resolve() == (ROOT / folder).resolve(), link


def test_every_robocal_import_resolves_from_the_files_alone():
    files = [p for d in (*FOLDERS, "robocal", "tests") for p in (ROOT / d).rglob("*.py")]
    seen, missing = 0, []
    for path in files:
        for module, names in _imports(ast.parse(path.read_text(), str(path))):
            seen += 1
            if not _resolves(module):
                missing.append(f"{path.relative_to(ROOT)}: {module}")
                continue
            for name in names:  # a submodule imported by name must be there too
                sub = ROOT.joinpath(*module.split("."), name)
                if sub.is_dir() and not (sub / "__init__.py").is_file():
                    missing.append(f"{path.relative_to(ROOT)}: {module}.{name}")
    assert seen > 500 and not missing, missing[:10]
