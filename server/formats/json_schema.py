"""The JSON Schema of each file, generated from its pydantic model and kept in schema/."""

from __future__ import annotations

import importlib
import json
from pathlib import Path

FOLDER = Path(__file__).with_name("schema")
# file -> (module, model) in this package; imported on demand (the CLI starts without pydantic)
MODELS = {
    "cell": ("cell_doc", "CellDoc"),
    "model": ("model_doc", "ModelDoc"),
    "report": ("report_doc", "ReportDoc"),
    "verification": ("verification_doc", "VerificationDoc"),
}


def generated(name: str) -> str:
    """The schema of `<name>.json` as its model states it, as the committed file's text."""
    module, model = MODELS[name]
    cls = getattr(importlib.import_module(f"{__package__}.{module}"), model)
    schema = {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": f"{name}.schema.json",
        **cls.model_json_schema(),
    }
    return json.dumps(schema, indent=2) + "\n"


def committed(name: str) -> Path:
    """Where the schema of `<name>.json` is kept (shipped in the wheel)."""
    return FOLDER / f"{name}.schema.json"


if (
    __name__ == "__main__"
):  # regenerate the committed files: python -m robocal.server.formats.json_schema
    for name in MODELS:
        committed(name).write_text(generated(name))
