"""A real uvicorn serving the API, the page and the charts, on 127.0.0.1 with its own data."""

import pytest

from tests.server.api.conftest import serve, settings_for


@pytest.fixture
def served(tmp_path):
    yield from serve(settings_for(tmp_path))
