"""Campaigns, readings and outcomes: idempotent writes, the unique key, resume."""

from __future__ import annotations

import datetime as dt

import numpy as np
import pytest
from sqlalchemy import text
from sqlalchemy.exc import IntegrityError

from robocal.server.formats import InputError
from robocal.server.store import (
    Conflict,
    LeaseHeld,
    NotFound,
    create_campaign,
    discard_unfinished_pose,
    get_campaign,
    list_campaigns,
    next_unmeasured_pose,
    planned_poses,
    pose_readings,
    record_missing,
    record_pose_outcome,
    record_reading,
    release_lease,
    renew_lease,
    set_status,
    take_lease,
)

from .conftest import POSES_DEG

READING = dict(
    xyz=[1200.5, -300.25, 845.125],
    std=[0.002, 0.003, 0.001],
    samples=25,
    time_s=12.5,
    temp_c=20.3,
    pressure_hpa=1013.2,
    humidity_pct=41.0,
)


def measure_pose(db, cid, i, targets=("A", "B", "C")):
    """What an engine does at a pose: each target, then the outcome."""
    for t in targets:
        record_reading(db, campaign_id=cid, pose_index=i, target=t, **READING)
    record_pose_outcome(
        db,
        campaign_id=cid,
        pose_index=i,
        state="measured",
        reached_deg=POSES_DEG[i % len(POSES_DEG)],
    )


def test_create_stores_campaign_and_plan(db, cell_json):
    cid = create_campaign(
        db,
        name=" first ",
        cell_json=cell_json,
        poses_deg=POSES_DEG,
        settings={"seed": 7, "settle": "adaptive"},
        simulated=True,
        notes="n",
    )
    info = get_campaign(db, campaign_id=cid)
    assert (info.name, info.status, info.simulated, info.notes) == ("first", "planned", True, "n")
    assert info.settings == {"seed": 7, "settle": "adaptive"}
    assert (info.n_poses, info.n_done) == (3, 0)
    assert info.created_at.tzinfo == dt.UTC
    assert abs(info.created_at - dt.datetime.now(dt.UTC)) < dt.timedelta(minutes=1)
    poses = planned_poses(db, campaign_id=cid)
    assert [p.label for p in poses] == ["1", "2", "3"]
    assert [list(p.joints_deg) for p in poses] == POSES_DEG
    assert [c.id for c in list_campaigns(db)] == [cid]
    assert list_campaigns(db, status="running") == []


def test_create_refuses_bad_input_and_writes_nothing(db, cell_json):
    with pytest.raises(ValueError, match="outside"):
        create_campaign(db, name="x", cell_json=cell_json, poses_deg=[[0, 0, 100, 0, 0, 0]])
    with pytest.raises(ValueError, match=r"\(n >= 1, 6\)"):
        create_campaign(db, name="x", cell_json=cell_json, poses_deg=[[0, 0, 0]])
    with pytest.raises(ValueError, match="labels"):
        create_campaign(
            db, name="x", cell_json=cell_json, poses_deg=POSES_DEG, labels=["a", "a", "b"]
        )
    with pytest.raises(ValueError, match="settings"):
        create_campaign(
            db, name="x", cell_json=cell_json, poses_deg=POSES_DEG, settings={"pause": float("nan")}
        )
    with pytest.raises(InputError):
        create_campaign(db, name="x", cell_json='{"robot": "nope"}', poses_deg=POSES_DEG)
    assert list_campaigns(db) == []


def test_status_transitions(db, cell_json):
    """The store follows the engine's life-cycle table: one request or event per step."""
    cid = create_campaign(db, name="x", cell_json=cell_json, poses_deg=POSES_DEG[:1])
    with pytest.raises(Conflict, match="planned; it can go to aborted, running, not paused"):
        set_status(db, campaign_id=cid, status="paused")
    assert set_status(db, campaign_id=cid, status="running") == "planned"
    assert set_status(db, campaign_id=cid, status="running") == "running"  # a no-op
    with pytest.raises(Conflict, match="not paused"):  # only through pausing
        set_status(db, campaign_id=cid, status="paused")
    for status in ("pausing", "paused", "estopped", "paused", "running"):  # estop, reset, resume
        set_status(db, campaign_id=cid, status=status)
    with pytest.raises(Conflict, match="pose 0 has no outcome"):
        set_status(db, campaign_id=cid, status="done")
    measure_pose(db, cid, 0)
    set_status(db, campaign_id=cid, status="done")
    with pytest.raises(Conflict, match="nothing"):
        set_status(db, campaign_id=cid, status="running")
    with pytest.raises(ValueError):
        set_status(db, campaign_id=cid, status="finished")
    with pytest.raises(NotFound):
        set_status(db, campaign_id=cid + 1, status="running")


def test_every_lifecycle_state_is_storable(db, cell_json):
    """All nine engine states pass the table's check constraint."""
    from robocal.drivers.lifecycle import STATES

    cid = create_campaign(db, name="x", cell_json=cell_json, poses_deg=POSES_DEG[:1])
    with db.session(write=True) as s:
        for state in STATES:
            s.execute(text("UPDATE campaign SET status = :s WHERE id = :i"), dict(s=state, i=cid))
    with pytest.raises(IntegrityError):
        with db.session(write=True) as s:
            s.execute(text("UPDATE campaign SET status = 'queued' WHERE id = :i"), dict(i=cid))


def test_lease_is_taken_atomically_and_lapses(db, cell_json):
    cid = create_campaign(db, name="x", cell_json=cell_json, poses_deg=POSES_DEG[:1])
    take_lease(db, campaign_id=cid, owner="h:1:a", ttl_s=30)
    take_lease(db, campaign_id=cid, owner="h:1:a", ttl_s=30)  # the owner renews
    with pytest.raises(LeaseHeld, match=r"another process \(h:1:a") as held:
        take_lease(db, campaign_id=cid, owner="h:2:b", ttl_s=30)
    assert held.value.owner == "h:1:a"
    assert not renew_lease(db, campaign_id=cid, owner="h:2:b", ttl_s=30)  # renew never steals
    take_lease(db, campaign_id=cid, owner="h:2:b", ttl_s=30, dead_owner="h:1:a")  # gone: taken
    assert get_campaign(db, campaign_id=cid).lease_owner == "h:2:b"
    assert renew_lease(db, campaign_id=cid, owner="h:2:b", ttl_s=-1)  # now lapsed
    take_lease(db, campaign_id=cid, owner="h:3:c", ttl_s=30)
    release_lease(db, campaign_id=cid, owner="h:2:b")  # not h:2:b's any more: a no-op
    assert get_campaign(db, campaign_id=cid).lease_owner == "h:3:c"
    release_lease(db, campaign_id=cid, owner="h:3:c")
    assert get_campaign(db, campaign_id=cid).lease_owner is None
    with pytest.raises(NotFound):
        take_lease(db, campaign_id=cid + 1, owner="h:3:c", ttl_s=30)


def test_record_reading_is_idempotent(db, running):
    assert record_reading(db, campaign_id=running, pose_index=1, target="A", **READING)
    assert not record_reading(db, campaign_id=running, pose_index=1, target="A", **READING)
    # numpy values and NaN for "not recorded" compare as what they store
    same = READING | dict(xyz=np.array(READING["xyz"]), samples=np.int64(25))
    assert not record_reading(db, campaign_id=running, pose_index=1, target="A", **same)
    with pytest.raises(Conflict, match="other x"):
        record_reading(
            db,
            campaign_id=running,
            pose_index=1,
            target="A",
            **READING | dict(xyz=[1200.6, -300.25, 845.125]),
        )
    with pytest.raises(Conflict, match="temp_c"):
        record_reading(
            db, campaign_id=running, pose_index=1, target="A", **READING | dict(temp_c=float("nan"))
        )
    stored = pose_readings(db, campaign_id=running, pose_index=1)
    assert list(stored) == ["A"]
    a = stored["A"]
    assert (a.xyz, a.std, a.samples, a.time_s, a.temp_c, a.pressure_hpa, a.humidity_pct) == (
        tuple(READING["xyz"]),
        tuple(READING["std"]),
        25,
        12.5,
        20.3,
        1013.2,
        41.0,
    )


def test_record_reading_refusals(db, running, cell_json):
    with pytest.raises(NotFound, match="no planned pose 3"):
        record_reading(db, campaign_id=running, pose_index=3, target="A", xyz=[0, 0, 0])
    with pytest.raises(NotFound, match="no campaign"):
        record_reading(db, campaign_id=running + 1, pose_index=0, target="A", xyz=[0, 0, 0])
    with pytest.raises(ValueError, match="xyz"):
        record_reading(db, campaign_id=running, pose_index=0, target="A", xyz=[0, np.nan, 0])
    with pytest.raises(ValueError, match="std"):
        record_reading(
            db, campaign_id=running, pose_index=0, target="A", xyz=[0, 0, 0], std=[0, -1, 0]
        )
    with pytest.raises(ValueError, match="samples"):
        record_reading(db, campaign_id=running, pose_index=0, target="A", xyz=[0, 0, 0], samples=0)
    with pytest.raises(ValueError, match="target"):
        record_reading(db, campaign_id=running, pose_index=0, target="A B", xyz=[0, 0, 0])
    planned = create_campaign(db, name="not started", cell_json=cell_json, poses_deg=POSES_DEG)
    with pytest.raises(Conflict, match="planned"):
        record_reading(db, campaign_id=planned, pose_index=0, target="A", xyz=[0, 0, 0])
    assert pose_readings(db, campaign_id=running, pose_index=0) == {}


def test_the_database_itself_refuses_duplicates_and_strays(db, running):
    record_reading(db, campaign_id=running, pose_index=0, target="A", xyz=[1, 2, 3])
    insert = text(
        "INSERT INTO reading (campaign_id, pose_index, target, status, x, y, z, detail, "
        "created_at) VALUES (:c, :p, 'A', 'ok', 1, 2, 3, '', '2025-01-01')"
    )
    with pytest.raises(IntegrityError, match="(?i)unique"):
        with db.session(write=True) as s:
            s.execute(insert, {"c": running, "p": 0})
    with pytest.raises(IntegrityError, match="(?i)foreign key"):
        with db.session(write=True) as s:
            s.execute(insert, {"c": running, "p": 9})
    with pytest.raises(IntegrityError, match="(?i)check"):
        with db.session(write=True) as s:
            s.execute(text("UPDATE reading SET x = NULL"))


def test_outcomes_agree_with_readings(db, running):
    with pytest.raises(Conflict, match="cannot be measured"):
        record_pose_outcome(db, campaign_id=running, pose_index=0, state="measured")
    record_reading(db, campaign_id=running, pose_index=0, target="A", **READING)
    assert record_missing(
        db,
        campaign_id=running,
        pose_index=0,
        target="B",
        detail="beam break after 3 retries",
        time_s=14.0,
    )
    assert not record_missing(
        db,
        campaign_id=running,
        pose_index=0,
        target="B",
        detail="beam break after 3 retries",
        time_s=14.0,
    )
    with pytest.raises(Conflict, match="other status"):
        record_reading(db, campaign_id=running, pose_index=0, target="B", **READING)
    with pytest.raises(Conflict, match="cannot be measured"):
        record_pose_outcome(db, campaign_id=running, pose_index=0, state="measured")
    with pytest.raises(Conflict, match="cannot be skipped"):
        record_pose_outcome(db, campaign_id=running, pose_index=0, state="skipped")
    with pytest.raises(ValueError, match="reached_deg has 2 joints"):
        record_pose_outcome(
            db, campaign_id=running, pose_index=0, state="missing-target", reached_deg=[0, 0]
        )
    assert record_pose_outcome(
        db,
        campaign_id=running,
        pose_index=0,
        state="missing-target",
        reached_deg=POSES_DEG[0],
        detail="B lost",
    )
    assert not record_pose_outcome(
        db,
        campaign_id=running,
        pose_index=0,
        state="missing-target",
        reached_deg=POSES_DEG[0],
        detail="B lost",
    )
    with pytest.raises(Conflict, match="already closed"):
        record_pose_outcome(db, campaign_id=running, pose_index=0, state="missing-target")
    with pytest.raises(Conflict, match="other status"):  # C was recorded missing with it
        record_reading(db, campaign_id=running, pose_index=0, target="C", **READING)
    with pytest.raises(Conflict, match="already closed"):
        record_reading(db, campaign_id=running, pose_index=0, target="D", **READING)
    # a retried call of a reading already stored is still fine after the pose closed
    assert not record_reading(db, campaign_id=running, pose_index=0, target="A", **READING)
    assert record_pose_outcome(
        db,
        campaign_id=running,
        pose_index=1,
        state="skipped",
        detail="unreachable: collision check",
    )
    missing = pose_readings(db, campaign_id=running, pose_index=0)["B"]
    assert (missing.status, missing.xyz, missing.detail) == (
        "missing",
        None,
        "beam break after 3 retries",
    )
    poses = planned_poses(db, campaign_id=running)
    assert [(p.state, p.reached_deg) for p in poses] == [
        ("missing-target", tuple(POSES_DEG[0])),
        ("skipped", None),
        (None, None),
    ]


def test_resume_point(db, cell_json):
    cid = create_campaign(db, name="twelve", cell_json=cell_json, poses_deg=POSES_DEG * 4)
    set_status(db, campaign_id=cid, status="running")
    assert next_unmeasured_pose(db, campaign_id=cid) == 0
    for k in range(1, 13):
        measure_pose(db, cid, k - 1, targets=("A", "B", "C")[: 1 + k % 3])
        assert next_unmeasured_pose(db, campaign_id=cid) == (k if k < 12 else None)
        assert get_campaign(db, campaign_id=cid).n_done == k


def test_resume_inside_a_pose(db, running):
    """Killed between two targets: the pose is still to do, and its stored readings are kept."""
    measure_pose(db, running, 0)
    record_reading(db, campaign_id=running, pose_index=1, target="A", **READING)
    record_reading(db, campaign_id=running, pose_index=1, target="B", **READING)
    assert next_unmeasured_pose(db, campaign_id=running) == 1
    kept = pose_readings(db, campaign_id=running, pose_index=1)
    assert sorted(kept) == ["A", "B"]
    for t in ("A", "B", "C"):
        if t not in kept:
            record_reading(db, campaign_id=running, pose_index=1, target=t, **READING)
    record_pose_outcome(db, campaign_id=running, pose_index=1, state="measured")
    assert next_unmeasured_pose(db, campaign_id=running) == 2
    with db.session() as s:
        assert s.execute(text("SELECT count(*) FROM reading")).scalar() == 6


def test_outcome_records_the_missing_targets_with_it(db, running):
    record_reading(db, campaign_id=running, pose_index=0, target="B", **READING)
    # by default, the cell's targets (A, B, C) without a reading
    record_pose_outcome(
        db,
        campaign_id=running,
        pose_index=0,
        state="missing-target",
        detail="beam break after 2 retries",
    )
    stored = pose_readings(db, campaign_id=running, pose_index=0)
    assert {t: r.status for t, r in stored.items()} == {"A": "missing", "B": "ok", "C": "missing"}
    assert stored["A"].detail == "beam break after 2 retries"
    record_reading(db, campaign_id=running, pose_index=1, target="A", **READING)
    with pytest.raises(Conflict, match="has a reading"):
        record_pose_outcome(
            db, campaign_id=running, pose_index=1, state="missing-target", missing=["A"]
        )
    record_pose_outcome(
        db, campaign_id=running, pose_index=1, state="missing-target", missing=["C"]
    )
    assert sorted(pose_readings(db, campaign_id=running, pose_index=1)) == ["A", "C"]


def test_discard_unfinished_pose(db, running):
    """The other resume policy: measure the interrupted pose again, whole, at one arrival."""
    measure_pose(db, running, 0)
    record_reading(db, campaign_id=running, pose_index=1, target="A", **READING)
    assert discard_unfinished_pose(db, campaign_id=running, pose_index=1) == 1
    assert pose_readings(db, campaign_id=running, pose_index=1) == {}
    assert discard_unfinished_pose(db, campaign_id=running, pose_index=2) == 0
    with pytest.raises(Conflict, match="closed"):
        discard_unfinished_pose(db, campaign_id=running, pose_index=0)
    assert len(pose_readings(db, campaign_id=running, pose_index=0)) == 3
