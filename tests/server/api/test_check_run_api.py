"""A model's check run on the service's cell (POST /api/models/{id}/checks/run), on both store
backends: the check's poses run by the acquisition worker as any campaign; e-stopped over HTTP
mid-pose, reset and resumed, then judged into the history with every reading once; the next check
measures the same poses; the cell busy is 409, an unknown model 404, no token 401."""

from __future__ import annotations

import threading

import pytest

from robocal.drivers.plan import Measure
from robocal.server.service import acquisitions as acquisitions_module
from tests.server.api.conftest import wait_for
from tests.server.api.test_checks_api import calibrated, cell  # noqa: F401 - a fixture
from tests.server.api.test_verify_api import calibrate, run_campaign
from tests.server.test_acquire import counts

SEED = 3
PROBLEM = "application/problem+json"


class Hold:
    """Wraps the worker's acquire(): the next run stops mid-pose 3 until released (`reached`
    set), or waits before it starts (`hold_start`), so a request lands while the run is live."""

    def __init__(self, monkeypatch):
        self.real = acquisitions_module.acquire
        self.reached, self.release = threading.Event(), threading.Event()
        self.mid_pose = self.hold_start = False
        monkeypatch.setattr(acquisitions_module, "acquire", self)

    def __call__(self, *a, on_engine=None, **k):
        def attach(engine):
            if self.hold_start:
                self.hold_start = False
                self.reached.set()
                assert self.release.wait(120)
            if self.mid_pose:
                self.mid_pose = False
                seen = []  # pose 3's measures: the engine picks its SMRs' order per pose

                def trace(msg):
                    if isinstance(msg, Measure) and msg.pose == 3:
                        seen.append(msg)
                        if len(seen) == 2:
                            self.reached.set()
                            assert self.release.wait(120)

                engine.trace = trace
            if on_engine is not None:
                on_engine(engine)

        return self.real(*a, on_engine=attach, **k)

    def reset(self):
        self.reached.clear()
        self.release.clear()


def campaign(c, cid):
    return c.get(f"/api/campaigns/{cid}").json()


def ended(c, cid):
    """The campaign once its run on the worker is over (judged too, when it is a check)."""
    return wait_for(
        lambda: campaign(c, cid),
        lambda j: j["run"] is not None and not j["run"]["active"] and j["status"] != "running",
    )


def test_check_run_estop_reset_resume_judged_and_again(live, store_url, monkeypatch):
    c = live.client
    job = calibrate(c, run_campaign(c, name="cal", poses=40, seed=SEED, pause_s=1, arm="SN-7"))
    url = f"/api/models/{job}/checks/run"
    body = {"pause_s": 1}
    assert live.anonymous.post(url, json=body).status_code == 401
    r = c.post("/api/models/99999/checks/run", json=body)
    assert r.status_code == 404 and r.headers["content-type"] == PROBLEM, r.text
    r = c.post(url, json={"poses": 1})
    assert r.status_code == 422, r.text
    r = c.post(url, json={"arm": "x"})  # an unknown field is refused, never ignored
    assert r.status_code == 422, r.text
    r = c.post(url, json={"seed": -1})
    assert r.status_code == 422, r.text
    r = c.post(url, json={"cell_id": "0123456789abcdef"})
    assert r.status_code == 404 and "no cell" in r.json()["detail"], r.text
    before = counts(store_url)

    hold = Hold(monkeypatch)
    hold.mid_pose = True
    r = c.post(url, json=body)
    assert r.status_code == 202, r.text
    run = r.json()
    cid = run["campaign_id"]
    assert run["started"] is True and run["check"] is None, run
    assert r.headers["location"] == run["campaign_url"] == f"/api/campaigns/{cid}"
    info = campaign(c, cid)
    assert info["poses_total"] == 6 and info["settings"]["options"]["seed"] == SEED, info
    assert info["arm"] == "SN-7", info  # the model's arm, checked

    assert hold.reached.wait(120), "the check never reached pose 3"
    r = c.post(url, json=body)  # the cell is busy with this very check
    assert r.status_code == 409 and "one campaign at a time" in r.json()["detail"], r.text
    r = c.post(f"/api/campaigns/{cid}/estop")
    assert r.status_code == 200 and r.json()["status"] == "estopped", r.text
    hold.release.set()
    stopped = ended(c, cid)
    assert stopped["status"] == "estopped" and stopped["poses_done"] == 3, stopped
    assert c.get(f"/api/models/{job}/checks").json()["checks"] == []
    r = c.post(url, json=body)  # an e-stopped check waits for its reset
    assert r.status_code == 409 and r.json()["state"] == "estopped", r.text
    ok_stopped = counts(store_url)[0] - before[0]
    assert ok_stopped == 3 * 3 + 1, ok_stopped  # pose 3 cut after one SMR

    assert c.post(f"/api/campaigns/{cid}/reset").status_code == 200
    r = c.post(url, json=body)  # resumes the check's own campaign, never a new one
    assert r.status_code == 202 and r.json()["campaign_id"] == cid, r.text
    done = ended(c, cid)
    assert done["status"] == "done" and done["poses_done"] == 6, done
    assert "check 1 of the model: ok" in done["run"]["detail"], done["run"]
    ok, missing, dup, outcomes = counts(store_url)
    assert dup == 0 and (ok + missing - before[0] - before[1], outcomes - before[3]) == (18, 6)

    hist = c.get(f"/api/models/{job}/checks").json()["checks"]
    assert [e["source"] for e in hist] == [f"campaign {cid}"] and hist[0]["poses"] == 6, hist
    assert hist[0]["verdict"] == "ok", hist
    health = c.get(f"/api/models/{job}/health").json()
    assert health["checked"] and health["verdict"] == "ok" and health["history"] == 1, health

    # the cell busy with another campaign: 409, and nothing planned
    hold.reset()
    hold.hold_start = True
    r = c.post("/api/campaigns", json={"name": "other", "poses": 3, "seed": SEED, "pause_s": 0})
    other = r.json()["id"]
    assert c.post(f"/api/campaigns/{other}/start").status_code == 202
    assert hold.reached.wait(120)
    n_campaigns = len(c.get("/api/campaigns").json())
    r = c.post(url, json=body)
    assert r.status_code == 409 and f"campaign {other}" in r.json()["detail"], r.text
    hold.release.set()
    ended(c, other)
    assert len(c.get("/api/campaigns").json()) == n_campaigns

    # the next check: a campaign of its own on the first check's poses, judged second
    r = c.post(url, json=body)
    assert r.status_code == 202, r.text
    again = r.json()["campaign_id"]
    assert again != cid and ended(c, again)["status"] == "done"
    assert campaign(c, again)["poses_total"] == 6
    hist = c.get(f"/api/models/{job}/checks").json()["checks"]
    assert [e["source"] for e in hist] == [f"campaign {cid}", f"campaign {again}"], hist
    assert hist[1]["verdict"] == "ok", hist[1]
    assert c.get(f"/api/models/{job}/health").json()["history"] == 2


@pytest.mark.sqlite_only  # a refusal before anything is stored
def test_a_model_of_imported_simulated_readings_needs_the_seed(live, cell):  # noqa: F811
    c = live.client
    job = calibrated(live, cell[0])  # readings of `simulate --seed 11`, imported
    url = f"/api/models/{job}/checks/run"
    r = c.post(url, json={"pause_s": 0})
    assert r.status_code == 409 and "give `seed`" in r.json()["detail"], r.text
    assert all(not j["name"].startswith("check-") for j in c.get("/api/campaigns").json())
    r = c.post(url, json={"pause_s": 0, "seed": 11})
    assert r.status_code == 202, r.text
    done = ended(c, r.json()["campaign_id"])
    assert done["status"] == "done" and "check 1 of the model: " in done["run"]["detail"], done
