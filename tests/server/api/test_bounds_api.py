"""The API's bounds over HTTP: ids in range, upload size, huge coordinates and control
characters refused with their place, oversized plans refused at once, readings in pages."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest

from .conftest import serve, settings_for

PROBLEM = "application/problem+json"


@pytest.fixture
def small(tmp_path):
    """A service whose uploads are limited to 4 KiB."""
    yield from serve(settings_for(tmp_path).model_copy(update={"max_upload_bytes": 4096}))


@pytest.mark.sqlite_only  # checked before the store: once is enough
@pytest.mark.parametrize(
    "path",
    [
        "/api/jobs/99999999999999999999999",
        "/api/campaigns/1e3",
        "/api/campaigns/-1",
        "/api/campaigns/0",
        "/api/jobs/9223372036854775808",
        "/api/campaigns/1/measurements?limit=10001",
        "/api/campaigns/1/measurements?offset=-1",
        "/api/models/1/evaluate?campaign_id=1e400",
    ],
)
def test_ids_and_pages_out_of_range_are_422_never_500(live, path):
    r = live.client.get(path)
    assert r.status_code == 422 and r.headers["content-type"] == PROBLEM, r.text


def test_largest_id_is_404(live):
    r = live.client.get("/api/jobs/9223372036854775807")
    assert r.status_code == 404 and r.headers["content-type"] == PROBLEM


@pytest.mark.sqlite_only  # checked before the store: once is enough
def test_undeclared_method_is_405_with_allow(live):
    r = live.client.delete("/api/campaigns")
    assert r.status_code == 405 and r.headers["allow"] == "GET, HEAD, POST"
    assert r.headers["content-type"] == PROBLEM


def test_upload_over_the_limit_is_413_with_a_problem(small):
    body = ("pose,q1,q2,q3,q4,q5,q6,target,x,y,z\n" * 200).encode()
    r = small.client.post(
        "/api/measurements/import", content=body, headers={"Content-Type": "text/csv"}
    )
    assert r.status_code == 413 and r.headers["content-type"] == PROBLEM
    assert "4096 bytes" in r.json()["detail"]

    def chunks():  # no Content-Length: cut off as it streams in
        for _ in range(10):
            yield b"x" * 1000

    r = small.client.post(
        "/api/cells", content=chunks(), headers={"Content-Type": "application/json"}
    )
    assert r.status_code == 413 and r.headers["content-type"] == PROBLEM, r.text
    assert small.client.get("/api/cells").json() == ["default"]


def meas(x="100.5", pose="1", target="A"):
    rows = "".join(f"{pose}{i},0,0,0,0,30,0,{target},{x},200,300\n" for i in range(5))
    return "pose,q1,q2,q3,q4,q5,q6,target,x,y,z\n" + rows


def test_the_1e308_import_is_refused_with_its_line(live):
    t0 = time.monotonic()
    r = live.client.post(
        "/api/measurements/import",
        content=meas(x="1e308"),
        params={"filename": "huge.csv"},
        headers={"Content-Type": "text/csv"},
    )
    print(f"refused in {(time.monotonic() - t0) * 1000:.0f} ms: {r.json()['detail']}")
    assert r.status_code == 422 and r.headers["content-type"] == PROBLEM
    assert (r.json()["file"], r.json()["line"], r.json()["column"]) == ("huge.csv", 2, 9)
    assert "out of range" in r.json()["detail"]
    assert live.client.get("/api/campaigns").json() == []  # nothing stored


@pytest.mark.sqlite_only  # checked before the store: once is enough
@pytest.mark.parametrize("where", ["pose", "target"])
def test_control_characters_in_an_import_are_refused(live, where):
    text = meas(pose="p\x00") if where == "pose" else meas(target="A\x1bB")
    r = live.client.post(
        "/api/measurements/import", content=text, headers={"Content-Type": "text/csv"}
    )
    assert r.status_code == 422 and f"column '{where}'" in r.json()["detail"], r.text
    assert live.client.get("/api/campaigns").json() == []


@pytest.mark.sqlite_only  # checked before the store: once is enough
@pytest.mark.parametrize("name", ["bad\x00name", "line\nbreak", "esc\x1b[2J", "   "])
def test_control_characters_in_names_are_refused(live, name):
    r = live.client.post("/api/campaigns", json={"poses": 5, "name": name})
    assert r.status_code == 422 and r.json()["errors"][0]["loc"] == ["body", "name"], r.text
    r = live.client.post(
        "/api/measurements/import",
        content=meas(),
        params={"name": name},
        headers={"Content-Type": "text/csv"},
    )
    assert r.status_code == 422, r.text
    assert live.client.get("/api/campaigns").json() == []


@pytest.mark.sqlite_only  # checked before the store: once is enough
@pytest.mark.parametrize(
    "body",
    [
        {"poses": 1000, "choose_from": 1000},
        {"poses": 100, "choose_from": 12586},
        {"poses": 5001},
        {"samples": 100_001},
    ],
)
def test_an_oversized_plan_is_refused_at_once(live, body):
    t0 = time.monotonic()
    r = live.client.post("/api/campaigns", json=body)
    elapsed = time.monotonic() - t0
    print(f"{body}: {r.status_code} in {elapsed * 1000:.0f} ms")
    assert r.status_code == 422 and r.headers["content-type"] == PROBLEM


def test_readings_come_in_pages_and_the_export_streams(live, tmp_path):
    subprocess.run(
        [
            sys.executable,
            "-m",
            "robocal.server.cli",
            "simulate",
            "--poses",
            "30",
            "--seed",
            "5",
            "--out",
            "m.csv",
        ],
        cwd=tmp_path,
        check=True,
        capture_output=True,
        timeout=300,
    )
    text = (tmp_path / "m.csv").read_text()
    r = live.client.post(
        "/api/measurements/import", content=text, headers={"Content-Type": "text/csv"}
    )
    assert r.status_code == 201, r.text
    cid = r.json()["id"]
    url = f"/api/campaigns/{cid}/measurements"
    whole = live.client.get(url)
    assert whole.headers["x-total-count"] == str(len(text.splitlines()) - 1)
    total = int(whole.headers["x-total-count"])
    pages = []
    for offset in range(0, total, 7):
        page = live.client.get(url, params={"offset": offset, "limit": 7})
        assert page.headers["x-total-count"] == str(total) and len(page.json()) <= 7
        pages += page.json()
    assert pages == whole.json()
    assert live.client.get(url, params={"offset": total}).json() == []
    r = live.client.get(f"{url}.csv")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/csv")
    assert r.text.splitlines()[0] == text.splitlines()[0] and len(r.text.splitlines()) == total + 1
    planned = live.client.post("/api/campaigns", json={"poses": 5}).json()["id"]
    r = live.client.get(f"/api/campaigns/{planned}/measurements.csv")
    assert r.status_code == 409 and r.headers["content-type"] == PROBLEM
    assert live.client.get("/api/campaigns/999/measurements.csv").status_code == 404


@pytest.mark.sqlite_only  # checked before the store: once is enough
def test_health_is_open(live):
    r = live.anonymous.get("/api/health")
    assert r.status_code == 200 and r.json() == {"status": "ok"}


@pytest.mark.sqlite_only  # checked before the store: once is enough
def test_event_stream_is_documented_and_guarded(live):
    schema = live.client.get("/openapi.json").json()
    get = schema["paths"]["/api/events"]["get"]
    assert "text/event-stream" in get["responses"]["200"]["content"]
    assert get["responses"]["401"]["content"] == {
        PROBLEM: {"schema": get["responses"]["401"]["content"][PROBLEM]["schema"]}
    }
    with live.anonymous.stream("GET", "/api/events") as r:
        assert r.status_code == 401
    with live.client.stream("GET", "/api/events") as r:
        assert r.status_code == 200 and r.headers["content-type"].startswith("text/event-stream")
