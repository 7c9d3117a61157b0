"""Input and output file formats (spec FORMATS.md sections 1 to 5), with located input errors;
the JSON files are pydantic models (cell_doc, model_doc, report_doc)."""

from .campaign_csv import read_campaign, read_poses, write_campaign, write_predictions
from .cell_json import (
    Cell,
    cell_to_json,
    default_cell,
    parse_cell,
    read_cell,
    robot_from_json,
    robot_to_json,
)
from .errors import InputError
from .files import atomic_write_text
from .json_doc import JsonDoc

__all__ = [
    "Cell",
    "InputError",
    "JsonDoc",
    "atomic_write_text",
    "cell_to_json",
    "default_cell",
    "parse_cell",
    "read_campaign",
    "read_cell",
    "read_poses",
    "robot_from_json",
    "robot_to_json",
    "write_campaign",
    "write_predictions",
]
