"""`robocal schema`: the JSON Schemas of the files."""

from __future__ import annotations

import sys

from ..formats.json_schema import committed


def cmd_schema(args) -> None:
    # The committed file (tests keep it equal to the model's): no pydantic import to print it.
    sys.stdout.write(committed(args.file).read_text(encoding="utf-8"))


def add(sub) -> None:
    """The command's parser, on the command line's subparsers."""
    sc = sub.add_parser("schema", help="the JSON Schema of cell.json, model.json or report.json")
    sc.add_argument("file", choices=("cell", "model", "report"), help="which file's schema")
    sc.set_defaults(func=cmd_schema)
