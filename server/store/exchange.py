"""A campaign in and out of the store: measurements for the solver, CSV import and export."""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Mapping, Sequence

import numpy as np
from sqlalchemy import and_, delete, func, insert, select

from robocal.server.formats.campaign_csv import read_campaign, write_campaign
from robocal.server.formats.cell_json import parse_cell
from robocal.solver.measurements import Measurements
from robocal.solver.robot import Robot

from . import checks
from .campaigns import _add_campaign, _add_plan, _campaign
from .db import Database
from .errors import Conflict, StoreError
from .models import Campaign, PlannedPose, PoseOutcome, Reading
from .readings import IMPORTING, _poses_query


def campaign_measurements(
    db: Database,
    *,
    campaign_id: int,
    robot: Robot | None = None,
    targets: Sequence[str] | None = None,
) -> Measurements:
    """The campaign's readings as arrays: poses with at least one reading, in plan order.

    Targets sorted by name (or `targets`, in that order), missing ones NaN; q in rad from the
    joints reached (the plan's where no outcome gives them); time_s / temp_c None when no
    reading has one. `robot` defaults to the cell's.
    """
    with db.session() as s:
        campaign = _campaign(s, campaign_id)
        poses = s.execute(_poses_query(campaign_id)).all()
        rows = s.execute(
            select(
                Reading.pose_index,
                Reading.target,
                Reading.x,
                Reading.y,
                Reading.z,
                Reading.time_s,
                Reading.temp_c,
            ).where(Reading.campaign_id == campaign_id, Reading.status == "ok")
        ).all()
        cell_text = campaign.cell_json
    robot = checks.matching_robot(robot, parse_cell(cell_text, f"<campaign {campaign_id} cell>"))
    if targets is None:
        names = tuple(sorted({r.target for r in rows}))
    else:
        names = tuple(checks.target_name(t) for t in targets)
        rows = [r for r in rows if r.target in names]
    used = {r.pose_index for r in rows}
    poses = [p for p in poses if p.pose_index in used]
    row_of = {p.pose_index: i for i, p in enumerate(poses)}
    col = {n: k for k, n in enumerate(names)}
    m, K = len(poses), len(names)
    q = np.array(
        [p.reached_deg if p.reached_deg is not None else p.joints_deg for p in poses], dtype=float
    ).reshape(m, -1 if m else robot.n_joints)
    if q.shape[1] != robot.n_joints:
        raise ValueError(
            f"campaign {campaign_id} has {q.shape[1]} joints per pose, "
            f"{robot.name} has {robot.n_joints}"
        )
    xyz = np.full((m, K, 3), np.nan)
    time_s, temp_c = np.full((m, K), np.nan), np.full((m, K), np.nan)
    for r in rows:
        i, k = row_of[r.pose_index], col[r.target]
        xyz[i, k] = r.x, r.y, r.z
        time_s[i, k] = np.nan if r.time_s is None else r.time_s
        temp_c[i, k] = np.nan if r.temp_c is None else r.temp_c
    some = lambda a: a if np.isfinite(a).any() else None  # noqa: E731
    prev = np.full(q.shape, np.nan)
    for i, p in enumerate(poses):
        if p.prev_deg is not None:
            prev[i] = p.prev_deg
    return Measurements(
        [p.label for p in poses],
        np.deg2rad(q),
        names,
        xyz,
        some(time_s),
        some(temp_c),
        some(np.deg2rad(prev)),
    )


def measured_targets(db: Database, *, campaign_id: int) -> tuple[str, ...]:
    """The SMRs with a good reading in the campaign, sorted: campaign_measurements' targets."""
    with db.session() as s:
        _campaign(s, campaign_id)
        rows = s.scalars(
            select(Reading.target)
            .where(Reading.campaign_id == campaign_id, Reading.status == "ok")
            .distinct()
        )
        return tuple(sorted(rows))


def export_csv(db: Database, *, campaign_id: int, path, robot: Robot | None = None) -> None:
    """Write the campaign's readings as a `meas.csv` (spec section 1), atomically."""
    meas = campaign_measurements(db, campaign_id=campaign_id, robot=robot)
    if meas.n_poses == 0:
        raise StoreError(f"campaign {campaign_id} has no readings to export")
    write_campaign(path, meas)


# Rows per write transaction of an import: each commits in a few milliseconds, so a campaign
# recording readings at the same time never waits near the busy timeout for the write lock.
IMPORT_CHUNK = 2000


def import_csv(
    db: Database,
    *,
    path,
    cell_json: str | Mapping,
    name: str,
    robot: Robot | None = None,
    notes: str = "",
    measurements: Measurements | None = None,
    arm: str | None = None,
) -> int:
    """Store a `meas.csv` as a `done` campaign (of this physical arm, if named); its id. All or nothing: InputError on a bad file
    (or cell), and then nothing is written. `measurements`: the file at `path` read already (by
    a worker process), for this robot.

    The whole file is checked first; then the campaign is written in short transactions
    (IMPORT_CHUNK rows each), marked `failed` ("import in progress") until the last one turns
    it `done`; a write that fails removes what was written.
    Joints are the file's (planned = reached); a target absent at a pose is recorded missing.
    """
    cell, cell_text = checks.cell_text(cell_json)
    robot = checks.matching_robot(robot, cell)
    # the whole file is checked before the database is touched
    meas = read_campaign(path, robot, list(cell.targets)) if measurements is None else measurements
    q = np.rad2deg(meas.q)
    prev = None if meas.prev_q is None else np.rad2deg(meas.prev_q)
    mask = meas.mask
    settings = {"source": "csv", "file": os.path.basename(os.fspath(path))}
    with db.session(write=True) as s:
        # `failed` until complete: a process killed mid-import leaves a campaign that says so,
        # never one that looks done with readings missing.
        campaign = _add_campaign(
            s,
            name=name,
            cell_text=cell_text,
            settings=settings,
            simulated=False,
            notes=IMPORTING,
            status="failed",
            arm=arm,
        )
        cid = campaign.id
    step = max(1, IMPORT_CHUNK // len(meas.target_names))  # poses per transaction
    try:
        for start in range(0, meas.n_poses, step):
            stop = min(meas.n_poses, start + step)
            with db.session(write=True) as s:
                _add_plan(s, cid, meas.pose_ids[start:stop], q[start:stop], first=start)
                s.execute(
                    insert(Reading),
                    [
                        _imported_reading(meas, cid, i, k, target, mask[i, k])
                        for i in range(start, stop)
                        for k, target in enumerate(meas.target_names)
                    ],
                )
                s.execute(
                    insert(PoseOutcome),
                    [
                        dict(
                            campaign_id=cid,
                            pose_index=i,
                            reached_deg=q[i].tolist(),
                            prev_deg=_given(prev, i),
                            state="measured" if mask[i].all() else "missing-target",
                            detail="imported",
                        )
                        for i in range(start, stop)
                    ],
                )
        with db.session(write=True) as s:
            done = _campaign(s, cid)
            done.status, done.notes = "done", str(notes)
    except BaseException:
        with db.session(write=True) as s:
            for table in (Reading, PoseOutcome, PlannedPose):
                s.execute(delete(table).where(table.campaign_id == cid))
            s.execute(delete(Campaign).where(Campaign.id == cid))
        raise
    return cid


def _prev_fields(prev_deg, n: int) -> list[str]:
    """A row's n prev_q fields as meas.csv writes them (blank where the pose gives none)."""
    if not n:
        return []
    return [f"{v:.9f}" for v in prev_deg] if prev_deg is not None else [""] * n


def _given(prev: np.ndarray | None, i: int) -> list | None:
    """Pose i's prev_q row (deg) as stored, None where the file gives none."""
    if prev is None or not np.isfinite(prev[i]).all():
        return None
    return prev[i].tolist()


def export_lines(db: Database, *, campaign_id: int, chunk: int = 5000):
    """The campaign's meas.csv, line by line (the text export_csv writes), read in short
    transactions of `chunk` readings so that any size streams in bounded memory; Conflict if it
    has no readings."""
    with db.session() as s:
        campaign = _campaign(s, campaign_id)
        ok = and_(Reading.campaign_id == campaign_id, Reading.status == "ok")
        if not s.scalar(select(func.count()).where(ok)):
            raise Conflict(f"campaign {campaign_id} has no readings to export yet")
        extras = [
            c
            for c, col in (("time_s", Reading.time_s), ("temp_c", Reading.temp_c))
            if s.scalar(select(func.count()).where(ok, col.is_not(None)))
        ]
        n_joints = parse_cell(campaign.cell_json).robot.n_joints
        given = PoseOutcome.campaign_id == campaign_id, PoseOutcome.prev_deg.is_not(None)
        has_prev = bool(s.scalar(select(func.count()).where(*given)))
    prev_cols = [f"prev_q{i}" for i in range(1, n_joints + 1)] if has_prev else []
    yield (
        ",".join(
            [
                "pose",
                *[f"q{i}" for i in range(1, n_joints + 1)],
                "target",
                "x",
                "y",
                "z",
                *extras,
                *prev_cols,
            ]
        )
        + "\n"
    )
    after = (-1, "")  # keyset: (pose_index, target) of the last line written
    on = and_(
        PlannedPose.campaign_id == Reading.campaign_id, PlannedPose.pose_index == Reading.pose_index
    )
    done = and_(
        PoseOutcome.campaign_id == Reading.campaign_id, PoseOutcome.pose_index == Reading.pose_index
    )
    while True:
        with db.session() as s:
            rows = s.execute(
                select(
                    Reading.pose_index,
                    Reading.target,
                    Reading.x,
                    Reading.y,
                    Reading.z,
                    Reading.time_s,
                    Reading.temp_c,
                    PlannedPose.label,
                    PlannedPose.joints_deg,
                    PoseOutcome.reached_deg,
                    PoseOutcome.prev_deg,
                )
                .join(PlannedPose, on)
                .outerjoin(PoseOutcome, done)
                .where(
                    Reading.campaign_id == campaign_id,
                    Reading.status == "ok",
                    (Reading.pose_index > after[0])
                    | ((Reading.pose_index == after[0]) & (Reading.target > after[1])),
                )
                .order_by(Reading.pose_index, Reading.target)
                .limit(chunk)
            ).all()
        if not rows:
            return
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        for r in rows:
            q = r.reached_deg if r.reached_deg is not None else r.joints_deg
            more = {"time_s": r.time_s, "temp_c": r.temp_c}
            w.writerow(
                [
                    r.label,
                    *[f"{v:.9f}" for v in q],
                    r.target,
                    *[f"{v:.6f}" for v in (r.x, r.y, r.z)],
                    *["" if more[c] is None else f"{more[c]:.6f}" for c in extras],
                    *_prev_fields(r.prev_deg, n_joints if has_prev else 0),
                ]
            )
        yield buf.getvalue()
        after = (rows[-1].pose_index, rows[-1].target)


def _imported_reading(meas: Measurements, cid: int, i: int, k: int, target: str, present) -> dict:
    row = dict(
        campaign_id=cid,
        pose_index=i,
        target=target,
        std_x=None,
        std_y=None,
        std_z=None,
        samples=None,
        pressure_hpa=None,
        humidity_pct=None,
    )
    if not present:
        return row | dict(
            status="missing",
            x=None,
            y=None,
            z=None,
            time_s=None,
            temp_c=None,
            detail="absent from the imported file",
        )
    extra = {
        c: None if a is None else checks.optional(a[i, k])
        for c, a in (("time_s", meas.time_s), ("temp_c", meas.temp_c))
    }
    x, y, z = (float(v) for v in meas.xyz[i, k])
    return row | extra | dict(status="ok", x=x, y=y, z=z, detail="")
