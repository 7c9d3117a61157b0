"""Request bodies: each route's limit (413 at once, by Content-Length or as the bytes stream in),
unknown fields refused, JSON validated as before, and the OpenAPI saying so."""

from __future__ import annotations

import json

import pytest

from robocal.server.api.bodies import (
    CELL_BODY_BYTES,
    CELLS,
    ESTOPS,
    JSON_BODY_BYTES,
    UPLOADS,
    RouteLimits,
)

from .conftest import serve, settings_for

PROBLEM = "application/problem+json"
pytestmark = pytest.mark.sqlite_only  # checked before the store: once is enough


@pytest.fixture
def live(tmp_path):
    yield from serve(settings_for(tmp_path))


def padded(doc: dict, size: int) -> bytes:
    """doc as JSON with trailing spaces up to size bytes (valid JSON, no unknown field)."""
    text = json.dumps(doc).encode()
    return text + b" " * (size - len(text))


def streamed(data: bytes, chunk: int = 8192):
    """The body with no Content-Length: chunked transfer, as a client streams a file."""
    for i in range(0, len(data), chunk):
        yield data[i : i + chunk]


@pytest.mark.parametrize("path", ["/api/campaigns", "/api/jobs", "/api/models/1/verify"])
def test_a_json_request_over_64_kib_is_413_at_once_whole_or_streamed(live, path):
    body = padded({"poses": 3}, JSON_BODY_BYTES + 1)
    for content in (body, streamed(body)):
        r = live.client.post(path, content=content, headers={"Content-Type": "application/json"})
        assert r.status_code == 413 and r.headers["content-type"] == PROBLEM, r.text
        assert f"larger than {JSON_BODY_BYTES} bytes" in r.json()["detail"], r.text
    assert live.client.get("/api/campaigns").json() == []


def test_a_json_request_within_its_limit_is_read_whole_or_streamed(live):
    body = padded({"poses": 3, "name": "padded"}, JSON_BODY_BYTES)
    r = live.client.post("/api/campaigns", content=body)
    assert r.status_code == 201, r.text
    body = padded({"poses": 3, "name": "streamed"}, JSON_BODY_BYTES)
    r = live.client.post("/api/campaigns", content=streamed(body))
    assert r.status_code == 201, r.text


def test_uploads_keep_max_upload_bytes_and_a_cell_its_own(live):
    big = b"pose,q1,q2,q3,q4,q5,q6,target,x,y,z\n" + b"1,0,0,0,0,30,0,A,1,2,3\n" * 20_000
    assert len(big) > CELL_BODY_BYTES
    r = live.client.post(
        "/api/measurements/import", content=big, headers={"Content-Type": "text/csv"}
    )
    assert r.status_code == 422 and "line" in r.json(), r.text  # read, and refused as a file
    cell = padded({"robot": "irb2600"}, CELL_BODY_BYTES + 1)
    r = live.client.post("/api/cells", content=streamed(cell))
    assert r.status_code == 413, r.text
    assert f"larger than {CELL_BODY_BYTES} bytes" in r.json()["detail"]


@pytest.mark.parametrize("path", ["/api/estop", "/api/campaigns/1/estop"])
def test_the_e_stop_is_never_refused_for_its_body(live, path):
    r = live.client.post(path, content=b"x" * (JSON_BODY_BYTES * 4))
    assert r.status_code != 413, r.text
    assert r.status_code in (200, 404), r.text


@pytest.mark.parametrize(
    "path, body, field",
    [
        ("/api/campaigns", {"poses": 3, "pose": 5}, ["body", "pose"]),
        ("/api/jobs", {"campaign_id": 1, "methode": "ls-sum"}, ["body", "methode"]),
        ("/api/models/1/verify", {"cycles": 1, "cylces": 2}, ["body", "cylces"]),
        (
            "/api/models/1/verify",
            {"points": [{"point": "P1", "x_mm": 0, "y_mm": 0, "z_mm": 0, "w_mm": 1}]},
            ["body", "points", 0, "w_mm"],
        ),
    ],
)
def test_an_unknown_field_is_422_naming_it(live, path, body, field):
    r = live.client.post(path, json=body)
    assert r.status_code == 422 and r.headers["content-type"] == PROBLEM, r.text
    errors = r.json()["errors"]
    assert {"loc": field, "msg": "Extra inputs are not permitted", "type": "extra_forbidden"} in (
        errors
    ), errors
    assert live.client.get("/api/campaigns").json() == []


def test_bad_json_and_no_body_are_422_under_body(live):
    r = live.client.post("/api/campaigns", content=b'{"poses": 3,')
    assert r.status_code == 422, r.text
    assert [e["loc"] for e in r.json()["errors"]] == [["body"]]
    assert r.json()["errors"][0]["type"] == "json_invalid"
    r = live.client.post("/api/jobs")
    assert r.status_code == 422, r.text
    assert r.json()["errors"] == [{"loc": ["body"], "msg": "Field required", "type": "missing"}]


def test_a_body_is_not_read_without_the_token(live):
    r = live.anonymous.post("/api/campaigns", content=b"{not json")
    assert r.status_code == 401, r.text


def test_the_openapi_documents_the_bodies_and_each_route_s_limit(live):
    spec = live.client.get("/openapi.json").json()
    for path, model in (
        ("/api/campaigns", "CampaignCreate"),
        ("/api/jobs", "JobCreate"),
        ("/api/models/{job_id}/verify", "VerifyCreate"),
    ):
        post = spec["paths"][path]["post"]
        assert post["requestBody"]["required"] is True
        schema = post["requestBody"]["content"]["application/json"]["schema"]
        assert schema == {"$ref": f"#/components/schemas/{model}"}
        assert spec["components"]["schemas"][model]["additionalProperties"] is False
        assert f"larger than {JSON_BODY_BYTES} bytes" in post["responses"]["413"]["description"]
    assert spec["components"]["schemas"]["PointIn"]["additionalProperties"] is False
    upload = spec["paths"]["/api/measurements/import"]["post"]["responses"]["413"]
    assert "max_upload_bytes" in upload["description"]
    cells = spec["paths"]["/api/cells"]["post"]["responses"]["413"]
    assert f"larger than {CELL_BODY_BYTES} bytes" in cells["description"]
    for _, path in ESTOPS:
        assert "413" not in spec["paths"][path]["post"]["responses"]
    served = {(m, p) for p, ops in spec["paths"].items() for m in (k.upper() for k in ops)}
    assert UPLOADS | CELLS | ESTOPS <= served  # the table names routes that exist


def test_route_limits_match_paths_with_their_parameters():
    limits = RouteLimits(max_upload_bytes=32 * 1024 * 1024)
    assert limits.of("POST", "/api/models/12/compensate").max_bytes == 32 * 1024 * 1024
    assert limits.of("POST", "/api/models/12/verify").max_bytes == JSON_BODY_BYTES
    assert limits.of("POST", "/api/campaigns/3/estop") is None
    assert limits.of("GET", "/api/measurements/import").max_bytes == JSON_BODY_BYTES
    assert RouteLimits(max_upload_bytes=4096).of("POST", "/api/jobs").max_bytes == 4096
