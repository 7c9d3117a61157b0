"""What the routes do with the store and the data dir: keyword-only functions, no HTTP."""

from __future__ import annotations

import hashlib
import json
import re
from dataclasses import asdict
from pathlib import Path

from robocal.server import store
from robocal.server.acquire import (
    UNFINISHED,
    AcquireOptions,
    base_guess,
    check_options,
    plan_and_store,
)
from robocal.server.formats.cell_json import Cell, cell_to_json, default_cell, parse_cell
from robocal.server.formats.errors import InputError
from robocal.server.formats.files import atomic_write_text

DEFAULT_CELL = "default"
CELL_ID = re.compile(r"[0-9a-f]{16}")


# --- cells -------------------------------------------------------------------------------------


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


# --- campaigns ---------------------------------------------------------------------------------


def plan_campaign(db: store.Database, *, cell: Cell, opts: AcquireOptions, progress=None) -> int:
    """Plan a campaign on the cell (simulated or real) exactly as `robocal acquire` would, and
    store it `planned`; ValueError for options the cell cannot have. progress(fraction), if
    given, follows the planning."""
    check_options(cell, opts)
    name = opts.name or f"campaign-seed{opts.seed}"
    # acquire() resumes the latest unfinished campaign of a name, so names must not collide.
    clash = [c.id for c in store.list_campaigns(db) if c.name == name and c.status in UNFINISHED]
    if clash:
        raise store.Conflict(f"campaign {clash[-1]} is already named {name!r} and unfinished")
    opts = AcquireOptions(**{**asdict(opts), "name": name})
    cid, _ = plan_and_store(
        db, name=name, cell=cell, opts=opts, base=base_guess(cell, opts.seed), progress=progress
    )
    return cid


def plan_given(db: store.Database, *, cell: Cell, opts: AcquireOptions, poses_deg, **stored) -> int:
    """Store a campaign of given joint commands (a verification's) `planned`, on the cell as
    `robocal acquire` would run it; stored: its pose labels and settings of its own."""
    check_options(cell, opts)
    cid, _ = plan_and_store(
        db,
        name=opts.name or "verify",
        cell=cell,
        opts=opts,
        base=base_guess(cell, opts.seed),
        poses_deg=poses_deg,
        **stored,
    )
    return cid


# --- readings and files ------------------------------------------------------------------------


def import_campaign(
    db: store.Database,
    *,
    measurements,
    filename: str,
    cell: Cell,
    name: str,
    arm: str | None = None,
) -> int:
    """Store an uploaded meas.csv, read already (uploads.read_measurements), as a done campaign;
    InputError naming `filename`."""
    from robocal.server.workflow import units_refusal

    filename = Path(filename).name or "meas.csv"  # only a label: never a path on this machine
    why = units_refusal(cell, measurements)
    if why:  # before anything is stored
        raise InputError(filename, None, None, why)
    try:
        return store.import_csv(
            db,
            path=filename,
            cell_json=cell_to_json(cell),
            name=name,
            measurements=measurements,
            arm=arm,
        )
    except InputError as e:
        raise InputError(filename, e.line, e.column, e.message) from None
