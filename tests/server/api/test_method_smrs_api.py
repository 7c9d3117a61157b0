"""A calibration method the campaign's SMRs cannot serve is refused when the job is asked for,
naming the field, as `robocal calibrate` refuses it: judged on the SMRs the campaign measured,
not the cell's."""

import csv
import io

from robocal.server.cli import main as robocal


def _without_target(text: str, target: str) -> str:
    rows = list(csv.DictReader(io.StringIO(text)))
    out = io.StringIO()
    w = csv.DictWriter(out, fieldnames=list(rows[0]), lineterminator="\n")
    w.writeheader()
    w.writerows(r for r in rows if r["target"] != target)
    return out.getvalue()


def test_ls_pose_on_two_measured_smrs_of_a_three_smr_cell_is_a_422(live, tmp_path):
    """The default cell has SMRs A, B and C; a campaign that measured A and B only was queued
    for ls-pose and failed in the worker ('job failed') instead of being refused up front."""
    path = tmp_path / "meas.csv"
    assert robocal(["simulate", "--poses", "20", "--seed", "5", "--out", str(path)]) == 0
    c = live.client
    r = c.post("/api/measurements/import?name=ab", content=_without_target(path.read_text(), "C"))
    assert r.status_code == 201, r.text
    cid = r.json()["id"]
    for method, said in (("ls-pose", "ls-pose needs at least three SMRs"), ("ls-single:C", "'C'")):
        r = c.post("/api/jobs", json={"campaign_id": cid, "method": method})
        print(f"\n{method}: {r.status_code} {r.json().get('detail')}")
        assert r.status_code == 422, r.text
        body = r.json()
        assert body["detail"].startswith("method: ") and said in body["detail"], body
        assert "2 (A, B)" in body["detail"] or "(A, B)" in body["detail"], body
        assert body["errors"][0]["loc"] == ["body", "method"], body
    assert c.get("/api/jobs").json() == []  # nothing queued
    r = c.post("/api/jobs", json={"campaign_id": cid, "method": "ls-sum"})
    assert r.status_code == 202, r.text  # a method the two SMRs serve is queued
