"""An uploaded campaign in metres is refused in one line naming the units, and nothing is
stored (issue 21, point 5)."""

import csv
import io

from robocal.drivers.cell import VirtualCell
from robocal.server.formats.campaign_csv import write_campaign
from robocal.server.formats.cell_json import default_cell

from .test_compensate_api import PROBLEM


def test_an_upload_in_metres_is_refused_naming_the_units(live, tmp_path):
    cell = default_cell()
    meas = VirtualCell.random(cell.robot, cell.targets, seed=3).campaign(30, seed=3)
    write_campaign(tmp_path / "meas.csv", meas)
    rows = list(csv.DictReader(io.StringIO((tmp_path / "meas.csv").read_text())))
    out = io.StringIO()
    w = csv.DictWriter(out, list(rows[0]))
    w.writeheader()
    for r in rows:
        w.writerow({k: repr(float(v) / 1000.0) if k in "xyz" else v for k, v in r.items()})
    c = live.client
    before = c.get("/api/campaigns").json()
    r = c.post(
        "/api/measurements/import",
        content=out.getvalue().encode(),
        params={"filename": "metres.csv"},
        headers={"content-type": "text/csv"},
    )
    assert r.status_code == 422 and r.headers["content-type"] == PROBLEM, r.text
    detail = r.json()["detail"]
    assert detail.startswith("metres.csv: the readings span ") and "\n" not in detail
    assert detail.endswith("x, y, z look like metres; give them in mm"), detail
    assert c.get("/api/campaigns").json() == before
    r = c.post(
        "/api/measurements/import",
        content=(tmp_path / "meas.csv").read_bytes(),
        params={"filename": "meas.csv"},
        headers={"content-type": "text/csv"},
    )
    assert r.status_code == 201, r.text
