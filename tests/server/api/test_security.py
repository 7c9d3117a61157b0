"""Every mutating route needs the token; the token is stored hashed; the service is closed."""

import hashlib

import pytest

from robocal.server.service.app import MUTATING, _api_routes, create_app
from robocal.server.service.security import ensure_token, reads_open, reset_token
from robocal.server.service.settings import Settings

from .conftest import serve, settings_for

PROBLEM = "application/problem+json"
# The token is checked before the store is asked: one backend is enough.
pytestmark = pytest.mark.sqlite_only


def mutating_operations(schema):
    return [
        (method.upper(), path)
        for path, ops in schema["paths"].items()
        for method in ops
        if method.upper() in MUTATING
    ]


def concrete(path):
    return (
        path.replace("{campaign_id}", "1").replace("{job_id}", "1").replace("{cell_id}", "default")
    )


def test_every_mutating_route_answers_401_without_the_token(live):
    schema = live.anonymous.get("/openapi.json").json()
    ops = mutating_operations(schema)
    app_ops = {
        (m, r.path)
        for r in _api_routes(create_app(live.settings).routes)
        for m in r.methods & MUTATING
    }
    assert set(ops) == app_ops and len(ops) >= 7  # the schema hides none of the app's routes
    for method, path in ops:
        for headers in ({}, {"Authorization": "Bearer wrong"}, {"Authorization": "Basic eDp5"}):
            r = live.anonymous.request(method, concrete(path), headers=headers, json={})
            assert r.status_code == 401, (method, path, headers, r.text)
            assert r.headers["content-type"] == PROBLEM
            assert r.headers["www-authenticate"] == "Bearer"
            assert r.json()["status"] == 401 and r.json()["detail"]
        assert schema["paths"][path][method.lower()]["security"] == [{"HTTPBearer": []}]
    # Nothing was created by the refused requests.
    assert live.client.get("/api/campaigns").json() == []


def test_every_read_answers_401_without_the_token_but_the_page_and_health(live):
    schema = live.anonymous.get("/openapi.json").json()
    reads = [p for p, ops in schema["paths"].items() if "get" in ops]
    assert len(reads) >= 15
    for path in reads:
        for headers in ({}, {"Authorization": "Bearer wrong"}):
            r = live.anonymous.get(concrete(path), headers=headers)
            if path == "/api/health":
                assert r.status_code == 200 and r.json() == {"status": "ok"}
                continue
            assert r.status_code == 401, (path, headers, r.text)
            assert r.headers["content-type"] == PROBLEM
            assert r.headers["www-authenticate"] == "Bearer"
        if path != "/api/health":
            assert schema["paths"][path]["get"]["security"] == [{"HTTPBearer": []}]
            assert "401" in schema["paths"][path]["get"]["responses"]
    # The event stream too (a browser's EventSource could not send the header: the page reads
    # it with fetch()).
    with live.anonymous.stream("GET", "/api/events") as r:
        assert r.status_code == 401
    assert live.anonymous.get("/").status_code == 200
    assert live.anonymous.get("/app.js").status_code == 200
    assert live.client.get("/api/cells").json() == ["default"]
    r = live.client.post("/api/campaigns", json={"poses": 5, "seed": 1})
    assert r.status_code == 201, r.text


def test_open_reads_only_on_a_loopback_host(tmp_path):
    assert reads_open(Settings(open_reads=True, host="127.0.0.1"))
    assert reads_open(Settings(open_reads=True, host="::1"))
    assert reads_open(Settings(open_reads=True, host="localhost"))
    for host in ("0.0.0.0", "192.168.1.20", "::", "cell-pc.example"):
        assert not reads_open(Settings(open_reads=True, host=host)), host
    assert not reads_open(Settings(host="127.0.0.1"))  # closed by default
    for live in serve(settings_for(tmp_path).model_copy(update={"open_reads": True})):
        assert live.anonymous.get("/api/cells").json() == ["default"]
        # Writes stay closed.
        assert live.anonymous.post("/api/campaigns", json={"poses": 5}).status_code == 401


def test_an_unguarded_read_route_is_refused_at_build_time(monkeypatch):
    from fastapi import APIRouter

    from robocal.server.service import app as app_module

    leak = APIRouter()

    @leak.get("/leak")
    def leak_route() -> dict:
        return {}

    # Included like the open health router: a read without the token must be named.
    monkeypatch.setattr(app_module, "OPEN_ROUTERS", ())
    app = app_module.FastAPI()
    app.include_router(leak, prefix="/api")
    assert app_module.unguarded_routes(app) == ["GET /api/leak"]


def test_token_is_stored_only_as_its_sha256(tmp_path):
    path = tmp_path / "token.sha256"
    token = ensure_token(path)
    assert len(token) >= 40
    stored = path.read_text().strip()
    assert stored == hashlib.sha256(token.encode()).hexdigest() and token not in stored
    assert path.stat().st_mode & 0o077 == 0
    assert ensure_token(path) is None  # shown at first start only
    assert reset_token(path) != token


def test_rotated_token_takes_effect_without_restart(live):
    new = reset_token(live.settings.token_file)
    assert live.client.post("/api/campaigns", json={"poses": 5}).status_code == 401
    r = live.anonymous.post(
        "/api/campaigns", json={"poses": 5}, headers={"Authorization": f"Bearer {new}"}
    )
    assert r.status_code == 201, r.text


def test_cors_is_closed_by_default(live):
    r = live.anonymous.options(
        "/api/campaigns",
        headers={"Origin": "http://evil.example", "Access-Control-Request-Method": "POST"},
    )
    assert "access-control-allow-origin" not in r.headers


def test_settings_listen_on_loopback_by_default(monkeypatch):
    monkeypatch.delenv("ROBOCAL_HOST", raising=False)
    assert Settings().host == "127.0.0.1"
    assert Settings().cors_origins == []
    monkeypatch.setenv("DATABASE_URL", "sqlite:///platform.db")
    assert Settings().database == "sqlite:///platform.db"
    monkeypatch.setenv("ROBOCAL_DATABASE", "mine.db")
    monkeypatch.setenv("ROBOCAL_PORT", "9123")
    assert (Settings().database, Settings().port) == ("mine.db", 9123)


def test_an_unguarded_mutating_route_is_refused_at_build(tmp_path, monkeypatch):
    from fastapi import APIRouter

    import robocal.server.service.app as app_module

    extra = APIRouter()
    extra.delete("/oops")(lambda: None)
    monkeypatch.setattr(app_module, "ROUTERS", (*app_module.ROUTERS, extra))
    with pytest.raises(RuntimeError, match="DELETE /api/oops"):
        create_app(Settings(database=str(tmp_path / "x.db"), data_dir=tmp_path))
