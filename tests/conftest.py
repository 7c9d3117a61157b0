"""Tests that start processes, a real service or a browser are marked `integration`, so that
`pytest -m "not integration"` runs the in-process tests alone (and quickly).

The mark is given here, from what a test does, so a new test cannot forget it: everything under
tests/server/api (the service over real sockets) and tests/web (the browser), and any test that
runs a subprocess (the `robocal` command line, uv, docker), itself, through a helper of its
module, or through one of its fixtures. A module may also mark itself explicitly.

Tests that ask for `store_url` run once per store backend (tests/backends.py).
"""

from __future__ import annotations

import inspect
import re
from functools import cache
from pathlib import Path

import pytest

from tests.backends import BACKENDS, store_url_for

TESTS = Path(__file__).resolve().parent
SERVICE_DIRS = (TESTS / "server" / "api", TESTS / "web")
# cli_process.run: a `robocal` process forked from a server that has imported the program
SPAWNS = re.compile(r"\bsubprocess\.|\bPopen\(|\bos\.system\(|\bcli_process\.run\(")


def _source(obj) -> str:
    try:
        return inspect.getsource(obj)
    except (OSError, TypeError):
        return ""


@cache
def _runners(module) -> frozenset[str]:
    """Names of the module's test-suite functions (its own or imported from tests) that spawn a
    process, directly or through one another."""
    funcs = {
        name: _source(f)
        for name, f in vars(module).items()
        if inspect.isfunction(f) and (getattr(f, "__module__", None) or "").startswith("tests")
    }
    found = {name for name, src in funcs.items() if SPAWNS.search(src)}
    while True:
        calls = re.compile(r"\b(" + "|".join(map(re.escape, found)) + r")\(") if found else None
        more = {n for n, src in funcs.items() if n not in found and calls and calls.search(src)}
        if not more:
            return frozenset(found)
        found |= more


def _spawns(source: str, runners: frozenset[str]) -> bool:
    if SPAWNS.search(source):
        return True
    return any(re.search(rf"\b{re.escape(n)}\(", source) for n in runners)


def spawns_a_process(item) -> bool:
    """Whether the test, or a fixture it uses, runs a subprocess (directly or via a helper)."""
    module = getattr(item, "module", None)
    if module is None:
        return False
    sources = [_source(getattr(item, "function", None))]
    for defs in getattr(item, "_fixtureinfo", None).name2fixturedefs.values():
        for d in defs:
            func = getattr(d, "func", None)
            if func is not None and getattr(func, "__module__", "").startswith("tests"):
                sources.append(_source(func))
                mod = inspect.getmodule(func)
                if mod is not None and mod is not module:
                    if any(_spawns(s, _runners(mod)) for s in sources[-1:]):
                        return True
    runners = _runners(module)
    return any(_spawns(s, runners) for s in sources)


def pytest_collection_modifyitems(config, items):
    for item in items:
        path = Path(str(item.fspath)).resolve()
        if any(path.is_relative_to(d) for d in SERVICE_DIRS) or spawns_a_process(item):
            item.add_marker(pytest.mark.integration)


def pytest_configure(config):
    config.addinivalue_line(
        "markers", "sqlite_only: reads or alters the SQLite file itself; not run on PostgreSQL"
    )


def pytest_generate_tests(metafunc):
    if "store_url" in metafunc.fixturenames:
        sqlite_only = metafunc.definition.get_closest_marker("sqlite_only") is not None
        backends = BACKENDS[:1] if sqlite_only else BACKENDS
        metafunc.parametrize("store_url", backends, indirect=True)


@pytest.fixture
def store_url(request, tmp_path):
    """The URL of an empty store on this test's backend."""
    with store_url_for(request.param, tmp_path) as url:
        yield url
