"""Tests that ask for `store_url` run once per store backend (tests/backends.py)."""

from __future__ import annotations

import pytest

from tests.backends import BACKENDS, store_url_for


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
