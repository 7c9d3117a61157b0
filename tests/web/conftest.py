"""A real uvicorn serving the API, the page and the charts, on 127.0.0.1 with its own data."""

from __future__ import annotations

import socket
import threading
import time
from dataclasses import dataclass

import pytest
import uvicorn

from server.app import create_app
from server.security import ensure_token
from server.settings import Settings


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass
class Served:
    settings: Settings
    token: str
    url: str


@pytest.fixture
def served(tmp_path):
    settings = Settings(database=str(tmp_path / "robocal.db"), data_dir=tmp_path / "data",
                        port=free_port())
    token = ensure_token(settings.token_file)
    server = uvicorn.Server(uvicorn.Config(create_app(settings), host=settings.host,
                                           port=settings.port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 30
    while not server.started:
        assert thread.is_alive() and time.monotonic() < deadline, "server did not start"
        time.sleep(0.02)
    yield Served(settings, token, f"http://{settings.host}:{settings.port}")
    server.should_exit = True
    thread.join(timeout=30)
