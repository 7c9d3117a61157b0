"""A real uvicorn server on 127.0.0.1 per test, with its own store, data dir and token."""

from __future__ import annotations

import socket
import threading
import time
from dataclasses import dataclass

import httpx
import pytest
import uvicorn

from robocal.server.service.app import create_app
from robocal.server.service.security import ensure_token
from robocal.server.service.settings import Settings


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# No connection kept between requests: uvicorn closes one idle for 5 s, and a request sent as it
# does (a loaded machine waits that long between two) is cut off with "Server disconnected
# without sending a response"; the test clients ask on a fresh connection instead.
ONE_CONNECTION_A_REQUEST = httpx.Limits(max_keepalive_connections=0)


@dataclass
class Live:
    """A running server: its settings, token and clients with and without the token."""

    settings: Settings
    token: str
    url: str
    client: httpx.Client  # sends the token
    anonymous: httpx.Client


def settings_for(tmp_path, database: str | None = None) -> Settings:
    """A service's settings under tmp_path; its store a SQLite file there unless `database`."""
    return Settings(
        database=database or str(tmp_path / "robocal.db"),
        data_dir=tmp_path / "data",
        port=free_port(),
    )


@pytest.fixture
def live(tmp_path, store_url):
    """A running service, once on each store backend."""
    yield from serve(settings_for(tmp_path, store_url))


def serve(settings: Settings):
    """Run a server with these settings until the generator is closed; yields a Live."""
    # Made before start, as a first start would (the server then finds it and prints nothing).
    token = ensure_token(settings.token_file)
    # An open event stream would hold a graceful stop until its next keep-alive: cut it short
    # (signals, which end the streams at once, reach only a server on the main thread).
    server = uvicorn.Server(
        uvicorn.Config(
            create_app(settings),
            host=settings.host,
            port=settings.port,
            log_level="warning",
            timeout_graceful_shutdown=1,
        )
    )
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 30
    while not server.started:
        assert thread.is_alive() and time.monotonic() < deadline, "server did not start"
        time.sleep(0.02)
    # The first upload or job would wait for the fork server to import the solver: tens of
    # seconds on a loaded machine, past a request's timeout. A user's first request may wait;
    # a test's waits here instead, for as long as the machine needs.
    assert server.config.app.state.jobs.warm.wait(600), "the fork server did not start"
    url = f"http://{settings.host}:{settings.port}"
    with (
        httpx.Client(
            base_url=url,
            headers={"Authorization": f"Bearer {token}"},
            timeout=30,
            limits=ONE_CONNECTION_A_REQUEST,
        ) as client,
        httpx.Client(base_url=url, timeout=30, limits=ONE_CONNECTION_A_REQUEST) as anonymous,
    ):
        yield Live(settings, token, url, client, anonymous)
    server.should_exit = True
    thread.join(timeout=30)


def wait_for(get, done, timeout=180.0, interval=0.1):
    """Poll get() until done(result); the last result."""
    deadline = time.monotonic() + timeout
    while True:
        result = get()
        if done(result):
            return result
        assert time.monotonic() < deadline, f"timed out; last: {result}"
        time.sleep(interval)


def done_job(client, **body) -> dict:
    """A job queued with this POST /api/jobs body and waited for; the job, asserted done."""
    r = client.post("/api/jobs", json=body)
    assert r.status_code == 202, r.text
    job = wait_for(
        lambda: client.get(f"/api/jobs/{r.json()['id']}").json(),
        lambda j: j["state"] in ("done", "failed"),
    )
    assert job["state"] == "done", job
    return job
