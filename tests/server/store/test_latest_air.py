"""The air temperature a compensated pose is solved at: the campaign's latest reading that has
one, read as a single indexed row however many readings the campaign holds."""

from __future__ import annotations

import numpy as np
from sqlalchemy import event, text

from robocal.drivers.cell import VirtualCell
from robocal.server.bench.air import whole_campaign  # how it was found, from all readings
from robocal.server.store import (
    create_campaign,
    latest_air,
    record_missing,
    record_pose_outcome,
    record_reading,
    set_status,
)
from robocal.solver.robot import IRB2600
from tests.robots import TARGETS


def started(db, cell_json, q_deg) -> int:
    cid = create_campaign(db, name="air", cell_json=cell_json, poses_deg=q_deg, simulated=True)
    set_status(db, campaign_id=cid, status="running")
    return cid


def test_the_latest_air_temperature_as_readings_arrive(db, cell_json):
    """Pose by pose, with beam breaks (recorded missing, timed, no temperature) and readings whose
    weather station did not answer: the latest reading's temperature that has one."""
    meas = VirtualCell.random(IRB2600, TARGETS, seed=11).campaign(20, seed=12, beam_break_rate=0.2)
    q_deg = np.rad2deg(meas.q)
    cid = started(db, cell_json, q_deg)
    assert latest_air(db, campaign_id=cid) is None
    seen = []
    for i in range(meas.n_poses):
        for k, t in enumerate(meas.target_names):
            time_s = 20.0 * i + k  # each reading its own time: no tie between two
            if meas.mask[i, k]:
                deaf = i % 5 == 3  # the weather station did not answer
                record_reading(db, campaign_id=cid, pose_index=i, target=t, xyz=meas.xyz[i, k],
                               time_s=time_s, temp_c=None if deaf else meas.temp_c[i, k])  # fmt: skip
            else:
                record_missing(db, campaign_id=cid, pose_index=i, target=t, time_s=time_s)
        record_pose_outcome(db, campaign_id=cid, pose_index=i, state="measured"
                            if meas.mask[i].all() else "missing-target", reached_deg=q_deg[i])  # fmt: skip
        want = whole_campaign(db, cid)
        air = latest_air(db, campaign_id=cid)
        assert (air is None and want is None) or (air.temp_c == want and air.time_s <= 20.0 * i + 2)
        seen.append(want)
    assert len(set(seen)) > 10  # it followed the air as the readings came


def test_the_latest_air_temperature_is_one_indexed_row(db, cell_json):
    """One statement, limited to one row, which the campaign-and-time index serves."""
    meas = VirtualCell.random(IRB2600, TARGETS, seed=11).campaign(30, seed=12)
    q_deg = np.rad2deg(meas.q)
    cid = started(db, cell_json, q_deg)
    for i in range(meas.n_poses):
        for k, t in enumerate(meas.target_names):
            record_reading(db, campaign_id=cid, pose_index=i, target=t, xyz=meas.xyz[i, k],
                           time_s=meas.time_s[i, k], temp_c=meas.temp_c[i, k])  # fmt: skip
    said: list = []
    listen = lambda conn, cursor, statement, params, *a: said.append((statement, params))  # noqa: E731
    event.listen(db.engine, "before_cursor_execute", listen)
    try:
        latest_air(db, campaign_id=cid)
    finally:
        event.remove(db.engine, "before_cursor_execute", listen)
    asked = [(s, p) for s, p in said if s.lstrip().upper().startswith("SELECT")]
    assert len(asked) == 1 and "LIMIT" in asked[0][0].upper(), said
    sqlite = db.engine.dialect.name == "sqlite"
    with db.engine.connect() as c:
        if not sqlite:  # a small table: ask whether an index can serve the order at all
            for way in ("seqscan", "bitmapscan", "sort"):
                c.execute(text(f"SET enable_{way} = off"))
        explain = "EXPLAIN QUERY PLAN " if sqlite else "EXPLAIN "
        plan = " ".join(str(r) for r in c.exec_driver_sql(explain + asked[0][0], asked[0][1]))
    assert "ix_reading_campaign_time" in plan, plan
