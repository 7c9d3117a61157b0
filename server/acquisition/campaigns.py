"""The campaigns the service plans (as `robocal acquire` would run them) and those it imports
from an uploaded meas.csv: keyword-only functions over the store, no HTTP."""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

from robocal.server import store
from robocal.server.acquisition.acquire import (
    UNFINISHED,
    AcquireOptions,
    base_guess,
    check_options,
    plan_and_store,
)
from robocal.server.formats.cell_json import Cell, cell_to_json
from robocal.server.formats.errors import InputError


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
    from robocal.server.calibration.units import units_refusal

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
