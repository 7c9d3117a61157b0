"""The cells the service keeps: the built-in default and each uploaded cell.json under its
content hash (the same cell uploaded twice is one cell)."""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path

from robocal.server import store
from robocal.server.formats.cell_json import Cell, cell_to_json, default_cell, parse_cell
from robocal.server.formats.files import atomic_write_text

DEFAULT_CELL = "default"
CELL_ID = re.compile(r"[0-9a-f]{16}")


def save_cell(*, cells_dir: Path, text: str, filename: str = "cell.json") -> tuple[str, Cell]:
    """Validate a cell.json and keep it under its content hash; (id, cell)."""
    cell = parse_cell(text, filename)
    normal = json.dumps(cell_to_json(cell), sort_keys=True, indent=2)
    cell_id = hashlib.sha256(normal.encode()).hexdigest()[:16]
    path = Path(cells_dir) / f"{cell_id}.json"
    if not path.exists():
        atomic_write_text(path, normal + "\n")
    return cell_id, cell


def load_cell(*, cells_dir: Path, cell_id: str) -> Cell:
    """The built-in default cell or an uploaded one; NotFound otherwise."""
    if cell_id == DEFAULT_CELL:
        return default_cell()
    # The id becomes a file name: accept nothing but the hash shape.
    path = Path(cells_dir) / f"{cell_id}.json"
    if not CELL_ID.fullmatch(cell_id) or not path.exists():
        raise store.NotFound(f"no cell {cell_id!r}")
    return parse_cell(path.read_text(), path.name)


def list_cells(*, cells_dir: Path) -> list[str]:
    """Cell ids: the default first, then uploads."""
    uploaded = sorted(p.stem for p in Path(cells_dir).glob("*.json") if CELL_ID.fullmatch(p.stem))
    return [DEFAULT_CELL, *uploaded]
