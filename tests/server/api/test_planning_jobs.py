"""A campaign's planning off the request path: a D-optimal choice answers 202 at once with a
planning job whose progress rises and which ends done with the campaign; cancelled or past its
wall-clock limit it ends failed with nothing stored; a small plan still answers 201 inline."""

from __future__ import annotations

import time

from tests.server.api.conftest import wait_for
from tests.server.api.test_job_limits import make_live  # noqa: F401 - a fixture

# At the planning bounds (poses x choose_from = 40 000): seconds of D-optimal exchange.
BIG = {"poses": 20, "choose_from": 2000}
ENDED = ("done", "failed")


def post_plan(c, **body):
    t0 = time.perf_counter()
    r = c.post("/api/campaigns", json=body)
    return r, time.perf_counter() - t0


def test_a_d_optimal_plan_is_a_job_whose_progress_rises_to_a_planned_campaign(make_live):
    c = make_live(job_workers=1).client
    r, took = post_plan(c, **BIG, name="chosen")
    print(f"\n202 for {BIG} in {took * 1000:.0f} ms")
    assert r.status_code == 202, r.text
    assert took < 1.0  # the "answered at once": the planning is not in the request
    job = r.json()
    assert r.headers["location"] == f"/api/jobs/{job['id']}"
    assert (job["kind"], job["state"], job["campaign_id"]) == ("planning", "queued", None)
    assert c.get(r.headers["location"]).json()["id"] == job["id"]
    seen = []

    def poll():
        j = c.get(f"/api/jobs/{job['id']}").json()
        seen.append(j["progress"])
        return j

    t0 = time.perf_counter()
    job = wait_for(poll, lambda j: j["state"] in ENDED, timeout=120, interval=0.02)
    print(
        f"planning job {job['state']} in {time.perf_counter() - t0:.2f} s (ran "
        f"{job['started_at']} .. {job['finished_at']}); progress seen "
        f"{sorted(set(seen))}"
    )
    assert job["state"] == "done", job
    rising = sorted(p for p in set(seen) if 0 < p < 1)
    assert len(rising) >= 2, seen  # reported along the way, not only at the end
    assert seen == sorted(seen)  # never falls
    assert job["progress"] == 1.0
    cid = job["campaign_id"]
    assert job["campaign_url"] == f"/api/campaigns/{cid}"
    camp = c.get(job["campaign_url"]).json()
    assert (camp["name"], camp["status"], camp["poses_total"]) == ("chosen", "planned", 20)
    assert camp["settings"]["plan"]["n_candidates"] == 2000

    # The same name again: the job fails with the clash, nothing more stored.
    r, _ = post_plan(c, poses=10, choose_from=200, name="chosen")
    assert r.status_code == 202, r.text
    again = wait_for(
        lambda: c.get(r.headers["location"]).json(), lambda j: j["state"] in ENDED, timeout=120
    )
    assert again["state"] == "failed" and again["campaign_id"] is None, again
    assert again["reason"] == (
        f"Conflict: campaign {cid} is already named 'chosen' and unfinished"
    ), again
    assert [x["id"] for x in c.get("/api/campaigns").json()] == [cid]


def test_a_planning_job_is_cancelled_and_stores_nothing(make_live):
    c = make_live(job_workers=1).client
    r, _ = post_plan(c, **BIG)
    job = r.json()
    wait_for(
        lambda: c.get(f"/api/jobs/{job['id']}").json()["state"],
        lambda s: s != "queued",
        timeout=60,
        interval=0.01,
    )
    r = c.post(f"/api/jobs/{job['id']}/cancel")
    assert r.status_code == 200, r.text
    assert (r.json()["state"], r.json()["reason"]) == ("failed", "cancelled"), r.json()
    assert c.get("/api/campaigns").json() == []
    assert c.post(f"/api/jobs/{job['id']}/cancel").status_code == 409


def test_a_planning_job_queued_behind_another_is_cancelled_off_the_queue(make_live):
    c = make_live(job_workers=1).client
    first = post_plan(c, **BIG)[0].json()
    second = post_plan(c, **BIG, seed=2)[0].json()
    r = c.post(f"/api/jobs/{second['id']}/cancel")
    assert (r.json()["state"], r.json()["reason"]) == ("failed", "cancelled"), r.json()
    assert r.json()["started_at"] is None  # it never ran
    c.post(f"/api/jobs/{first['id']}/cancel")


def test_a_planning_job_past_its_wall_clock_limit_fails(make_live):
    # the biggest plan allowed takes most of a second in its worker: far past 0.1 s anywhere
    c = make_live(job_workers=1, job_timeout_s=0.1).client
    job = post_plan(c, **BIG)[0].json()
    job = wait_for(
        lambda: c.get(f"/api/jobs/{job['id']}").json(),
        lambda j: j["state"] in ENDED,
        timeout=60,
        interval=0.02,
    )
    assert (job["state"], job["reason"]) == ("failed", "exceeded its wall-clock limit of 0.1 s")
    assert c.get("/api/campaigns").json() == []


def test_small_plans_answer_inline_and_oversized_ones_are_refused(make_live):
    c = make_live().client
    r, took = post_plan(c, poses=10)
    print(f"\n201 for 10 random poses in {took * 1000:.0f} ms")
    assert r.status_code == 201, r.text
    assert (r.json()["status"], r.json()["poses_total"]) == ("planned", 10)
    r, took = post_plan(c, poses=100, choose_from=2000)
    print(f"422 for 100 of 2000 in {took * 1000:.0f} ms")
    assert r.status_code == 422 and r.json()["detail"].startswith("poses x choose_from"), r.text
    assert c.get("/api/jobs").json() == []  # refused before any job was queued


def test_a_planning_job_has_no_charts(make_live):
    c = make_live().client
    job = post_plan(c, poses=10, choose_from=100)[0].json()
    for chart in ("table3", "boxplot.png", "errors.png"):
        r = c.get(f"/api/charts/jobs/{job['id']}/{chart}")
        assert r.status_code in (404, 409), r.text  # 409 while it is not done (no model)
    wait_for(
        lambda: c.get(f"/api/jobs/{job['id']}").json()["state"], lambda s: s in ENDED, timeout=120
    )
    r = c.get(f"/api/charts/jobs/{job['id']}/table3")
    assert r.status_code == 404 and "no charts" in r.json()["detail"], r.text
