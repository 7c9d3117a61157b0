"""A done calibration's model over the API: joint commands for an uploaded targets.csv, and its
exports (RAPID module, parameter table, URDF); bad uploads are 422 with their line."""

from __future__ import annotations

import csv
import io
import json
import subprocess
import sys

import numpy as np
import pytest

from robocal.server.exports.rapid import read_module
from tests.server.api.conftest import wait_for

PROBLEM = "application/problem+json"


@pytest.fixture
def model_job(live, tmp_path):
    """(job id of a done ls-sum calibration, meas.csv rows it was fitted on)."""
    r = subprocess.run(
        [sys.executable, "-m", "robocal.server.cli", "simulate", "--poses", "30", "--seed", "5",
         "--out", "meas.csv"],
        cwd=tmp_path, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    text = (tmp_path / "meas.csv").read_text()
    c = live.client
    r = c.post("/api/measurements/import", content=text, params={"filename": "meas.csv"})
    assert r.status_code == 201, r.text
    r = c.post("/api/jobs", json={"campaign_id": r.json()["id"], "method": "ls-sum"})
    assert r.status_code == 202, r.text
    job = wait_for(
        lambda: c.get(f"/api/jobs/{r.json()['id']}").json(),
        lambda j: j["state"] in ("done", "failed"),
    )
    assert job["state"] == "done", job
    return job["id"], list(csv.DictReader(io.StringIO(text)))


def targets_csv(rows, poses=5) -> str:
    """The readings of the first poses as targets, their joints as the starting guess."""
    keep = sorted({r["pose"] for r in rows}, key=int)[:poses]
    out = io.StringIO()
    w = csv.writer(out)
    w.writerow(["pose", "target", "x", "y", "z", *[f"q{i}" for i in range(1, 7)]])
    for r in rows:
        if r["pose"] in keep:
            w.writerow([r["pose"], r["target"], r["x"], r["y"], r["z"],
                        *[r[f"q{i}"] for i in range(1, 7)]])  # fmt: skip
    return out.getvalue()


@pytest.mark.sqlite_only  # the store's part (import, job) runs on both backends elsewhere
def test_compensate_and_export_a_done_model(live, model_job):
    job_id, rows = model_job
    c = live.client
    body = targets_csv(rows)
    url = f"/api/models/{job_id}/compensate"
    assert live.anonymous.post(url, content=body).status_code == 401

    r = r0 = c.post(url, content=body, params={"filename": "cell-7.csv"})
    assert r.status_code == 200, r.text
    assert r.headers["content-type"].startswith("text/csv")
    joints = list(csv.DictReader(io.StringIO(r.text)))
    assert [j["pose"] for j in joints] == sorted({r["pose"] for r in rows}, key=int)[:5]
    # near the readings' own joints: the model (geometric, the arm also bends) differs from
    # the true arm by its residual, a few hundredths of a mm, i.e. below 0.2 degrees of joint
    measured = {r["pose"]: [float(r[f"q{i}"]) for i in range(1, 7)] for r in rows}
    for j in joints:
        q = [float(j[f"q{i}"]) for i in range(1, 7)]
        assert np.abs(np.subtract(q, measured[j["pose"]])).max() < 0.2, (j, measured[j["pose"]])
        assert float(j["predicted_error_mm"]) < 0.1

    # a bad field: 422 naming the upload and its line; an unreachable pose: its line too
    lines = body.splitlines()
    bad = lines[:]
    bad[2] = bad[2].replace(bad[2].split(",")[2], "oops", 1)
    r = c.post(url, content="\n".join(bad), params={"filename": "cell-7.csv"})
    assert r.status_code == 422 and r.headers["content-type"] == PROBLEM, r.text
    assert r.json()["file"] == "cell-7.csv" and r.json()["line"] == 3, r.json()
    far = lines[:]
    fields = far[1].split(",")
    fields[2] = "99999"  # x far outside the arm's reach
    far[1] = ",".join(fields)
    r = c.post(url, content="\n".join(far))
    assert r.status_code == 422 and "unreachable" in r.json()["detail"], r.text
    assert r.json()["line"] == 2
    assert c.post(url, content=body, params={"tcp": "1,2"}).status_code == 422
    # three SMRs and the starting joints: a warning only for the jumps between the random poses
    q = np.array([[float(j[f"q{i}"]) for i in range(1, 7)] for j in joints])
    jumps = int(np.sum(np.abs(np.diff(q, axis=0)).max(axis=1) > 90))
    said = json.loads(r0.headers.get("X-Robocal-Warnings", "[]"))
    assert said == ([] if not jumps else [said[0]]), said
    assert not jumps or said[0].startswith(f"cell-7.csv: {jumps} jumps of more than 90 deg")
    # the limits are the caller's: a correction larger than max_move_deg leaves the starting
    # configuration (422 naming the pose), and jumps are judged by max_jump_deg
    r = c.post(url, content=body, params={"max_move_deg": 0.00001})
    assert r.status_code == 422 and r.json()["line"] == 2, r.text
    assert "would leave its starting joints' configuration" in r.json()["detail"], r.text
    r = c.post(url, content=body, params={"max_jump_deg": 0, "filename": "cell-7.csv"})
    assert r.status_code == 200 and r.text == r0.text, r.text
    said = json.loads(r.headers["X-Robocal-Warnings"])
    assert said[-1].startswith("cell-7.csv: 4 jumps of more than 0 deg"), said
    for bad in ({"max_move_deg": -1}, {"max_jump_deg": "x"}, {"max_jump_deg": 4000}):
        r = c.post(url, content=body, params=bad)
        assert r.status_code == 422 and next(iter(bad)) in r.text, (bad, r.text)
    # one SMR a pose: its orientation comes from the starting joints, said in a header
    one = [lines[0], *[ln for ln in lines[1:] if ln.split(",")[1] == "A"]]
    r = c.post(url, content="\n".join(one), params={"filename": "one.csv"})
    assert r.status_code == 200, r.text
    warned = json.loads(r.headers["X-Robocal-Warnings"])
    assert len(warned) == 1 + bool(jumps) and warned[0].startswith("one.csv: 5 poses (first "), (
        warned
    )
    assert "comes from the starting joints" in warned[0]
    # no joints and no configuration: 422 naming the pose's line
    bare = [",".join(ln.split(",")[:5]) for ln in lines]
    r = c.post(url, content="\n".join(bare))
    assert r.status_code == 422 and r.json()["line"] == 2, r.text
    assert "has neither starting joints" in r.json()["detail"]

    # exports: the parameter table and the URDF need no body; RAPID compensates the upload
    r = c.post(f"/api/models/{job_id}/export", params={"format": "params"})
    assert r.status_code == 200 and r.text.startswith("parameter,joint,convention"), r.text
    r = c.post(f"/api/models/{job_id}/export", params={"format": "urdf"})
    assert r.status_code == 200 and "<robot" in r.text and "smr_A" in r.text
    r = c.post(f"/api/models/{job_id}/export", params={"format": "rapid"})
    assert r.status_code == 422, r.text  # a RAPID module needs the targets
    r = c.post(f"/api/models/{job_id}/export", params={"format": "rapid"}, content=body)
    assert r.status_code == 200, r.text
    mod = read_module(r.text)
    robax = np.array([mod.targets[n][0] for n in mod.moves])
    want = np.array([[float(j[f"q{i}"]) for i in range(1, 7)] for j in joints])
    assert np.abs(robax - want).max() <= 0.5e-5 + 1e-9
    assert c.post("/api/models/999/export", params={"format": "urdf"}).status_code == 404
