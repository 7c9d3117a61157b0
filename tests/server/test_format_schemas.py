"""The JSON files' pydantic models: their committed JSON Schemas, the `schema` command, and the
API validating cell uploads with the same model as the file reader."""

from __future__ import annotations

import json

import jsonschema_rs
import pytest

from robocal.server.formats import cell_to_json, default_cell
from robocal.server.formats.json_schema import MODELS, committed, generated
from tests import cli_process
from tests.server.api.conftest import serve, settings_for

SPEC_CELL = {
    "robot": "irb2600",
    "targets": {"A": [60.0, 0.0, 35.0], "B": [-30.0, 52.0, 35.0], "C": [-30.0, -52.0, 35.0]},
}
SPEC_REPORT = {
    "schema": 1,
    "noise_floor_mm": 0.017,
    "baseline": {"model": "geometric", "holdout_rmse_mm": 0.43, "holdout_max_mm": 1.2},
    "effects": [
        {
            "name": "joint_compliance",
            "joint": 2,
            "evidence": "one sentence a person can check",
            "holdout_rmse_before_mm": 0.43,
            "holdout_rmse_after_mm": 0.018,
            "parameters": {"k_deg_per_kNm": 0.0},
        }
    ],
    "final": {
        "model": "geometric+joint_compliance(2)",
        "holdout_rmse_mm": 0.018,
        "holdout_max_mm": 0.06,
    },
}


JOINT = {"a": 0, "d": 400, "theta": 0, "alpha": 0}  # a link an arm can have (reach >= 100 mm)
IDENTITY = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
DEVICES = {
    "tracker": {"host": "127.0.0.1", "port": 5000},
    "controller": {"url": "socket://127.0.0.1:5001"},
}


def validator(name):
    return jsonschema_rs.validator_for(json.loads(committed(name).read_text()))


@pytest.mark.parametrize("name", sorted(MODELS))
def test_committed_schema_is_the_models(name):
    # If this fails: python -m robocal.server.formats.json_schema, and commit the files.
    assert committed(name).read_text() == generated(name)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_schema_command_prints_the_committed_file(name):
    r = cli_process.run("schema", name, cwd=".", timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout == committed(name).read_text()
    assert json.loads(r.stdout)["title"] == f"{name}.json"


def test_schemas_accept_the_spec_examples_and_what_the_program_writes(tmp_path):
    from robocal.server.formats.model_json import model_to_json
    from tests.server.test_formats import INLINE_MDH, every_effect

    cell = validator("cell")
    for doc in (SPEC_CELL, json.loads(INLINE_MDH), cell_to_json(default_cell())):
        assert cell.is_valid(doc), list(cell.iter_errors(doc))
    model, *_ = every_effect(0)
    written = json.loads(json.dumps(model_to_json(model)))
    assert validator("model").is_valid(written), list(validator("model").iter_errors(written))
    assert validator("report").is_valid(SPEC_REPORT)


@pytest.mark.parametrize(
    "change",
    [
        {"targets": {}},
        {"targets": {"a b": [0, 0, 0]}},
        {"targets": {"A": [0, 0]}},
        {"robot": {"convention": "DH", "joints": [{"a": 0, "d": 0, "theta": 0, "alpha": 0}]}},
        {"robot": {"convention": "dh", "joints": [{"a": 0, "d": 0, "theta": 0, "alpah": 0}]}},
        {"robot": {"convention": "dh", "joints": [{"a": 1e6, "d": 0, "theta": 0, "alpha": 0}]}},
        {"payload_kg": -1},
        {"tracker": {"mpe_um": "10"}},
        # issue 20: the schema allowed these, the reader refused them
        {"robot": ""},
        {"robot": " "},
        {"robot": "irb2601"},
        {"robot": {"name": "", "convention": "dh", "joints": [JOINT]}},
        {"robot": {"name": "arm\u2028", "convention": "dh", "joints": [JOINT]}},
        {"robot": {"name": "a" * 201, "convention": "dh", "joints": [JOINT]}},
        # and bools taken for numbers by both
        {"payload_kg": False},
        {"base": IDENTITY, "devices": {**DEVICES, "tracker": {"host": "127.0.0.1", "port": True}}},
        {
            "base": IDENTITY,
            "devices": {**DEVICES, "controller": {"url": "/dev/ttyS0", "baudrate": "9600"}},
        },
    ],
)
def test_cell_schema_refuses_what_the_reader_refuses(change):
    from robocal.server.formats import InputError, parse_cell

    doc = {**SPEC_CELL, **change}
    assert not validator("cell").is_valid(doc)
    with pytest.raises(InputError):
        parse_cell(json.dumps(doc))


@pytest.mark.parametrize(
    "change",
    [
        {"robot": " IRB2600 "},
        {"robot": {"name": "arm 2 (cell 3)", "convention": "dh", "joints": [JOINT]}},
        {"base": IDENTITY, "devices": DEVICES},
        {
            "base": IDENTITY,
            "devices": {**DEVICES, "controller": {"url": "COM3", "baudrate": 9600.0}},
        },
    ],
)
def test_cell_reader_takes_what_the_schema_allows(change):
    from robocal.server.formats import parse_cell

    doc = {**SPEC_CELL, **change}
    assert validator("cell").is_valid(doc), list(validator("cell").iter_errors(doc))
    parse_cell(json.dumps(doc))


def test_no_bound_is_lost_from_a_schema(tmp_path):
    """A bound on an Integer (a wrapped int) was once written "ge" instead of "minimum", which
    no validator reads."""
    from robocal.server.service.app import create_app

    texts = [committed(name).read_text() for name in MODELS]
    texts.append(json.dumps(create_app(settings_for(tmp_path)).openapi()))
    for text in texts:
        assert '"ge":' not in text and '"le":' not in text and '"gt":' not in text


def test_api_upload_is_validated_by_the_cell_model(tmp_path):
    gen = serve(settings_for(tmp_path))
    live = next(gen)
    try:
        bad = '{\n  "robot": "irb2600",\n  "targets": {"A": [60.0, 0.0, "35"]}\n}'
        r = live.client.post("/api/cells", content=bad)
        assert r.status_code == 422, r.text
        problem = r.json()
        assert (problem["line"], problem["column"]) == (3, 32)
        assert "targets.A[2]: expected a number, got the string '35'" in problem["detail"]
        r = live.client.post("/api/cells", json=SPEC_CELL)
        assert r.status_code == 201, r.text
        back = live.client.get(f"/api/cells/{r.json()['id']}").json()["cell"]
        assert back == cell_to_json(default_cell())
        schema = live.client.get("/openapi.json").json()
        body = schema["paths"]["/api/cells"]["post"]["requestBody"]["content"]["application/json"]
        assert body["schema"] == {"$ref": "#/components/schemas/CellDoc"}
        assert "CellDoc" in schema["components"]["schemas"]
    finally:
        gen.close()


def test_a_syntax_error_after_a_duplicate_key_is_the_one_reported():
    from robocal.server.formats import InputError, parse_cell

    text = '{"robot": "irb2600", "robot": "irb2600",\n "targets": {"A": [1, 2, 3]]}'
    with pytest.raises(InputError) as e:
        parse_cell(text, "cell.json")
    assert (e.value.line, e.value.column) == (2, 28) and "invalid JSON" in e.value.message
    with pytest.raises(InputError) as e:
        parse_cell(text.replace("]]", "]}"), "cell.json")
    assert (e.value.line, e.value.column) == (1, 22) and "duplicate key 'robot'" in e.value.message
