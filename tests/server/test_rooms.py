"""The server wing's rooms hold: use cases in their packages reach nothing of the service, the
API, the command line or the benchmarks (those compose them, never the other way), and the hall holds
packages rather than modules."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.solver.test_layering import forbidden, imports

ROOT = Path(__file__).resolve().parents[2]
# the rooms that compose the others: a use case importing one of them would import upward
COMPOSERS = tuple(f"robocal.server.{p}" for p in ("service", "api", "cli", "bench"))
USE_CASES = (
    "acquisition",
    "calibration",
    "checks",
    "compensate",
    "exports",
    "figures",
    "formats",
    "recordings",
    "store",
    "verify",
)
HALL_MODULES_MAX = 3  # modules directly in server/ (its __init__ included)


def upward(room: str) -> list[str]:
    """file:line module for every import of a composing room from this use case's package."""
    found: dict[str, str] = {}  # file:line -> the first composing module its statement names
    for p in sorted((ROOT / "server" / room).rglob("*.py")):
        rel = p.relative_to(ROOT).with_suffix("")
        package = ".".join(["robocal", *rel.parts[:-1]])
        for line, name in imports(p, package):
            if forbidden(name, COMPOSERS):
                found.setdefault(f"{p.relative_to(ROOT)}:{line}", name)
    return [f"{where} imports {name}" for where, name in found.items()]


@pytest.mark.parametrize("room", USE_CASES)
def test_a_use_case_imports_nothing_that_composes_it(room):
    assert (ROOT / "server" / room / "__init__.py").exists()
    assert upward(room) == []


def test_the_check_sees_an_upward_import(tmp_path, monkeypatch):
    """Not vacuous: a lazy import of the service inside a use case's function is caught."""
    (tmp_path / "server" / "verify").mkdir(parents=True)
    (tmp_path / "server" / "verify" / "x.py").write_text(
        "def f():\n    from ..service.events import Bus\n"
    )
    monkeypatch.setitem(globals(), "ROOT", tmp_path)
    assert upward("verify") == ["server/verify/x.py:2 imports robocal.server.service.events"]


def test_the_hall_holds_rooms_not_modules():
    modules = sorted(p.name for p in (ROOT / "server").glob("*.py"))
    assert len(modules) <= HALL_MODULES_MAX, modules


LINES_MAX = 700


def test_no_source_file_outgrows_a_reader():
    """No non-test source file over 700 lines (the engine's sighting has a module of its own)."""
    long = {
        str(p.relative_to(ROOT)): n
        for folder in ("server", "solver", "drivers", "migrations", "web")
        for p in (ROOT / folder).rglob("*.py")
        if (n := len(p.read_text().splitlines())) > LINES_MAX
    }
    assert long == {}
