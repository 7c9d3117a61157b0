"""What the API shows of a campaign this service runs: the live engine's state with the store's
counts, the state read first, so a run that ends between the two reads never shows done with a
pose missing (CI under load once saw done with 39 of 40 poses)."""

from __future__ import annotations

import threading
from types import SimpleNamespace

import pytest

from robocal.server import store
from robocal.server.acquisition.acquire import AcquireOptions
from robocal.server.acquisition.campaigns import plan_campaign
from robocal.server.api import campaigns as routes
from robocal.server.formats import default_cell
from robocal.server.service import acquisitions as acquisitions_module
from robocal.server.service.acquisitions import Acquisitions
from robocal.server.service.job_queue import check_job

POSES = 3
WAIT_S = 10.0  # bound on every cross-thread wait; each is answered at once


class Engine(SimpleNamespace):
    """A stand-in for the run's engine: its state, moved by the test."""

    def estop(self) -> bool:
        return True


class Run:
    """A run of the campaign on the service's worker, with a stand-in engine the test moves:
    acquire() stores the state and all poses but the last, attaches it, then holds until
    released (nothing touches a device)."""

    def __init__(self, monkeypatch, db):
        self.db, self.engine = db, Engine(state="running")
        self.attached, self.release = threading.Event(), threading.Event()
        monkeypatch.setattr(acquisitions_module, "acquire", self.acquire)

    def acquire(self, database_url, cell, opts, *, campaign_id, on_engine, **kw):
        store.set_status(self.db, campaign_id=campaign_id, status="running")
        for i in range(POSES - 1):
            pose_done(self.db, campaign_id, i)
        on_engine(self.engine)
        self.attached.set()
        assert self.release.wait(WAIT_S)
        return {"state": self.engine.state}


def pose_done(db, cid, i):
    """Pose i measured: a reading of every target, then its outcome (as the run stores them)."""
    for target in sorted(default_cell().targets):
        store.record_reading(
            db,
            campaign_id=cid,
            pose_index=i,
            target=target,
            xyz=[1000.0, 0.0, 500.0],
            std=[0.01, 0.01, 0.01],
            samples=5,
            time_s=float(i),
        )
    store.record_pose_outcome(
        db, campaign_id=cid, pose_index=i, state="measured", reached_deg=[0] * 6
    )


def end_between_the_reads(monkeypatch, db, cid, engine, end):
    """store.get_campaign and list_campaigns as the run's last pose and its `end` (the engine's
    state; the store has not heard it yet) land right after the store was read."""
    for name in ("get_campaign", "list_campaigns"):
        real = getattr(store, name)

        def racing(*args, _real=real, **kw):
            read = _real(*args, **kw)
            if engine.state == "running":
                pose_done(db, cid, POSES - 1)
                engine.state = end
            return read

        monkeypatch.setattr(store, name, racing)


@pytest.fixture
def running(tmp_path, monkeypatch):
    """(db, acquisitions, run, campaign id): a run here with all poses stored but the last."""
    url = str(tmp_path / "robocal.db")
    db = store.open_database(url)
    opts = AcquireOptions(poses=POSES, seed=1, name="shown", pause_s=0.0, samples=5)
    cid = plan_campaign(db, cell=default_cell(), opts=opts)
    acq = Acquisitions(db)
    run = Run(monkeypatch, db)
    try:
        acq.request(campaign_id=cid, action="start")
        assert run.attached.wait(WAIT_S), acq.get(cid)
        yield db, acq, run, cid
    finally:
        run.release.set()
        acq.shutdown()
        db.close()


def shown(acq, cid, route):
    if route == "one":
        return routes.get_campaign(campaign_id=cid, acquisitions=acq)
    (one,) = routes.list_campaigns(acquisitions=acq)
    return one


@pytest.mark.parametrize("route", ["one", "list"])
@pytest.mark.parametrize("end", ["paused", "done"])
def test_a_run_ending_between_the_reads_shows_no_state_ahead_of_its_counts(
    running, monkeypatch, route, end
):
    """Read after the store, the engine's paused would come with the pose it finished missing
    (the next read, still paused, one more), its done with 39 of 40 poses."""
    db, acq, run, cid = running
    end_between_the_reads(monkeypatch, db, cid, run.engine, end)
    first = shown(acq, cid, route)
    assert run.engine.state == end  # the run did end between the reads
    assert (first.status, first.poses_done) == ("running", POSES - 1)
    then = shown(acq, cid, route)
    assert (then.status, then.poses_done) == (end if end == "paused" else "running", POSES)


def test_a_campaign_shown_done_is_one_a_job_accepts(running):
    """The engine is done before the store has heard it: the campaign shows done only once
    the store has it, when a calibration job (which goes by the store) is accepted."""
    db, acq, run, cid = running
    pose_done(db, cid, POSES - 1)
    run.engine.state = "done"
    for route in ("one", "list"):
        assert shown(acq, cid, route).status == "running"
    with pytest.raises(store.Conflict, match="is running"):
        check_job(db, kind="calibration", campaign_id=cid, method="ls-sum")
    store.set_status(db, campaign_id=cid, status="done")  # as the run's state writer does
    for route in ("one", "list"):
        now = shown(acq, cid, route)
        assert (now.status, now.poses_done, now.actions) == ("done", POSES, [])
    check_job(db, kind="calibration", campaign_id=cid, method="ls-sum")
