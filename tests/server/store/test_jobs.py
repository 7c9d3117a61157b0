"""Jobs in the store: created queued, moved along their states, failed when cut off."""

import pytest

from robocal.server.store import (
    Conflict,
    NotFound,
    create_campaign,
    create_job,
    fail_unfinished_jobs,
    get_job,
    list_jobs,
    update_job,
)
from tests.server.store.conftest import POSES_DEG


@pytest.fixture
def cid(db, cell_json):
    return create_campaign(db, name="c", cell_json=cell_json, poses_deg=POSES_DEG)


def test_job_lifecycle_and_results(db, cid):
    job = create_job(db, kind="calibration", campaign_id=cid, method="minimax")
    assert (job.state, job.progress, job.results, job.started_at) == ("queued", 0.0, {}, None)
    job = update_job(db, job_id=job.id, state="running", progress=0.5)
    assert job.state == "running" and job.started_at is not None and job.progress == 0.5
    job = update_job(db, job_id=job.id, state="done", results={"model": "m.json"})
    assert job.progress == 1.0 and job.finished_at is not None
    assert get_job(db, job_id=job.id).results == {"model": "m.json"}
    with pytest.raises(Conflict):
        update_job(db, job_id=job.id, state="running")
    assert [j.id for j in list_jobs(db, state="done")] == [job.id]


def test_bad_jobs_are_refused(db, cid):
    with pytest.raises(NotFound):
        create_job(db, kind="calibration", campaign_id=999, method="minimax")
    with pytest.raises(ValueError):
        create_job(db, kind="bake", campaign_id=cid, method="x")
    with pytest.raises(NotFound):
        get_job(db, job_id=42)
    job = create_job(db, kind="diagnosis", campaign_id=cid, method="diagnose")
    with pytest.raises(ValueError):
        update_job(db, job_id=job.id, progress=2.0)
    with pytest.raises(ValueError):
        update_job(db, job_id=job.id, state_x="no")


def test_unfinished_jobs_fail_with_the_reason(db, cid):
    queued = create_job(db, kind="calibration", campaign_id=cid, method="minimax")
    running = create_job(db, kind="diagnosis", campaign_id=cid, method="diagnose")
    update_job(db, job_id=running.id, state="running")
    done = create_job(db, kind="calibration", campaign_id=cid, method="ls-sum")
    update_job(db, job_id=done.id, state="running")
    update_job(db, job_id=done.id, state="done")
    assert fail_unfinished_jobs(db, reason="stopped") == [queued.id, running.id]
    assert {j.id: (j.state, j.reason) for j in list_jobs(db)} == {
        queued.id: ("failed", "stopped"),
        running.id: ("failed", "stopped"),
        done.id: ("done", None),
    }
