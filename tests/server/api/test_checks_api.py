"""Quick checks over the API (FORMATS section 8), on both store backends: a done job's model
checked on a simulated cell's six fixed poses, clean and then with the tracker bumped; the history,
the production line's health and the chart; bad uploads are one-line 422s (file, line, column)
and store nothing; an unknown model is 404; every route needs the token."""

from __future__ import annotations

import numpy as np
import pytest

from robocal.drivers.cell import VirtualCell
from robocal.server.checks.check import MAX_POSES
from robocal.server.formats.campaign_csv import write_campaign
from robocal.server.formats.cell_json import default_cell
from tests.server.api.conftest import wait_for
from tests.server.test_check import SCATTER_DEG, bumped, measured
from tests.server.test_cli import robocal

SEED = 11
PROBLEM = "application/problem+json"
CONTRACT = {"model_sha256", "poses", "rms_mm", "max_mm", "expected_rms_mm", "verdict", "reason",
            "history"}  # fmt: skip


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    """A simulated campaign's meas.csv (the cell of SEED), the cell and its six check poses."""
    d = tmp_path_factory.mktemp("checks-api")
    r = robocal("simulate", "--poses", 40, "--seed", SEED, "--arm-scatter-deg", SCATTER_DEG,
                "--out", "train.csv", cwd=d)  # fmt: skip
    assert r.returncode == 0, r.stderr
    c = default_cell()
    vc = VirtualCell.random(c.robot, c.targets, seed=SEED)  # as `simulate --seed` draws it
    return d, vc, vc.sample_poses(6, np.random.default_rng(SEED + 1))


def calibrated(live, d) -> int:
    """The campaign imported and calibrated (ls-sum) through the API; the done job's id."""
    c = live.client
    r = c.post("/api/measurements/import", content=(d / "train.csv").read_text(),
               params={"filename": "train.csv"})  # fmt: skip
    assert r.status_code == 201, r.text
    r = c.post("/api/jobs", json={"campaign_id": r.json()["id"], "method": "ls-sum"})
    assert r.status_code == 202, r.text
    job = wait_for(lambda: c.get(f"/api/jobs/{r.json()['id']}").json(),
                   lambda j: j["state"] in ("done", "failed"))  # fmt: skip
    assert job["state"] == "done", job
    return job["id"]


def check_csv(cell, seed: int, change=None) -> str:
    d, vc, poses = cell
    path = d / f"check-{seed}.csv"
    measured(change(vc) if change else vc, poses, seed, path)
    return path.read_text()


def test_checks_history_health_and_chart(live, cell):
    job = calibrated(live, cell[0])
    c, url = live.client, f"/api/models/{job}/checks"
    health = c.get(f"/api/models/{job}/health")
    assert health.status_code == 200, health.text
    h = health.json()
    assert h["checked"] is False and h["verdict"] is None and h["history"] == 0, h
    assert "never checked" in h["reason"] and h["checked_at"] is None
    assert c.get(url).json()["checks"] == []

    docs = []
    for k in range(5):  # four clean checks, then the tracker bumped by 0.1 mm
        body = check_csv(cell, 100 + k, bumped if k == 4 else None)
        r = c.post(url, content=body, params={"filename": f"line-7-{k}.csv"})
        assert r.status_code == 201, r.text
        docs.append(r.json())
    for k, doc in enumerate(docs[:4]):
        assert CONTRACT <= set(doc) and doc["job_id"] == job and doc["history"] == k + 1, doc
        assert doc["verdict"] in ("ok", "watch") and doc["poses"] == 6, doc
        assert 0 < doc["rms_mm"] <= doc["max_mm"] < 0.5 and doc["expected_rms_mm"] > 0, doc
    last = docs[4]
    assert last["verdict"] == "recalibrate" and last["cause"] == "rigid", last
    assert "the tracker or the base moved" in last["reason"], last

    hist = c.get(url).json()
    assert hist["model_sha256"] == last["model_sha256"] and hist["job_id"] == job
    assert hist["cusum_watch"] < hist["cusum_recalibrate"]
    checks = hist["checks"]
    assert [e["verdict"] for e in checks] == [d["verdict"] for d in docs]
    assert [e["source"] for e in checks] == [f"line-7-{k}.csv" for k in range(5)]
    assert [e["rms_mm"] for e in checks] == pytest.approx([d["rms_mm"] for d in docs])
    assert [e["cusum"] for e in checks] == pytest.approx([d["cusum"] for d in docs], abs=1e-6)
    for e in checks:
        assert e["expected_rms_mm"] < e["watch_rms_mm"] < e["recalibrate_rms_mm"], e
    assert checks[0]["checked_at"] <= checks[-1]["checked_at"]

    h = c.get(f"/api/models/{job}/health").json()
    assert h["checked"] is True and h["verdict"] == "recalibrate" and h["history"] == 5, h
    assert h["reason"] == last["reason"] and h["checked_at"] == checks[-1]["checked_at"]

    # `robocal check` on the served model.json and the service's database: the same history
    d = cell[0]
    (d / "served.model.json").write_bytes(c.get(f"/api/models/{job}").content)
    (d / "cli-check.csv").write_text(check_csv(cell, 105, bumped))
    r = robocal("check", "served.model.json", "cli-check.csv", "--db", live.settings.database,
                cwd=d)  # fmt: skip
    assert r.returncode == 3, r.stderr  # still recalibrate: the history remembers the bump
    h = c.get(f"/api/models/{job}/health").json()
    assert h["history"] == 6 and h["verdict"] == "recalibrate", h
    assert c.get(url).json()["checks"][-1]["source"] == "cli-check.csv"

    png = c.get(f"/api/charts/models/{job}/checks.png")
    assert png.status_code == 200, png.text
    assert png.headers["content-type"] == "image/png" and png.content.startswith(b"\x89PNG")


def test_bad_checks_are_refused_in_one_line_and_store_nothing(live, cell):
    job = calibrated(live, cell[0])
    c, url = live.client, f"/api/models/{job}/checks"
    good = check_csv(cell, 1)
    lines = good.splitlines()
    header = lines[0].split(",")
    bad = lines[:]
    row = bad[2].split(",")
    row[header.index("x")] = "abc"
    bad[2] = ",".join(row)
    r = c.post(url, content="\n".join(bad) + "\n", params={"filename": "cell-3.csv"})
    assert r.status_code == 422 and r.headers["content-type"] == PROBLEM, r.text
    p = r.json()
    assert (p["file"], p["line"], p["column"]) == ("cell-3.csv", 3, header.index("x") + 1), p
    assert p["detail"].startswith("cell-3.csv:3:") and "column 'x'" in p["detail"], p
    assert "\n" not in p["detail"] and "/tmp" not in p["detail"], p

    d, vc, _ = cell
    write_campaign(d / "many.csv", vc.campaign(MAX_POSES + 1, 2))
    cases = (
        (good.replace(",A,", ",Z,"), "target 'Z'"),  # an SMR the model does not have
        ((d / "many.csv").read_text(), f"at most {MAX_POSES}"),  # a campaign, not a check
        ('{"robot": "irb2600"}', "check.csv"),  # not a CSV at all
        ("pose,target,x,y,z\n", "check.csv"),  # no joints, no readings
    )
    for body, said in cases:
        r = c.post(url, content=body)
        assert r.status_code == 422, r.text
        detail = r.json()["detail"]
        assert said in detail and "\n" not in detail and "robocal-check" not in detail, detail
    assert c.get(url).json()["checks"] == []  # nothing stored

    assert c.post("/api/models/99999/checks", content=good).status_code == 404
    assert c.get("/api/models/99999/checks").status_code == 404
    assert c.get("/api/models/99999/health").status_code == 404
    assert c.post("/api/models/0/checks", content=good).status_code == 422

    anon = live.anonymous
    assert anon.post(url, content=good).status_code == 401
    assert anon.get(url).status_code == 401
    assert anon.get(f"/api/models/{job}/health").status_code == 401
    assert anon.get(f"/api/charts/models/{job}/checks.png").status_code == 401
    assert c.get(url).json()["checks"] == []
