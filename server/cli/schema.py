"""`robocal schema`: the JSON Schemas of the files."""

from __future__ import annotations

import sys
from pathlib import Path

# The committed files (tests keep them equal to the models' schemas, formats/json_schema.py):
# read by path, since importing the formats package would import pydantic to print a file.
FOLDER = Path(__file__).resolve().parent.parent / "formats" / "schema"


def cmd_schema(args) -> None:
    sys.stdout.write((FOLDER / f"{args.file}.schema.json").read_text(encoding="utf-8"))


def add(sub) -> None:
    """The command's parser, on the command line's subparsers."""
    sc = sub.add_parser(
        "schema", help="the JSON Schema of cell.json, model.json, report.json or verification.json"
    )
    sc.add_argument(
        "file", choices=("cell", "model", "report", "verification"), help="which file's schema"
    )
    sc.set_defaults(func=cmd_schema)
