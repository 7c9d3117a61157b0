"""The production line's single question, GET /api/models/{id}/health, also says whether the model
was fit to deploy at all: a check of the nominal model (not deployable) may well say "ok" (the arm
still matches it), and before, nothing in the answer but a clause of the reason said otherwise.
The check's own answer (POST .../checks, "verdict": "ok") carries the same."""

from __future__ import annotations

import csv
import io

import pytest

from tests.real import REAL, import_real
from tests.server.api.conftest import done_job


def _six_poses() -> bytes:
    rows = list(csv.DictReader(io.StringIO((REAL / "irb120_wu" / "train.csv").read_text())))
    out = io.StringIO()
    w = csv.DictWriter(out, list(rows[0]))
    w.writeheader()
    w.writerows(r for r in rows if int(r["pose"]) <= 6)
    return out.getvalue().encode()


@pytest.mark.sqlite_only  # the verdict is the model file's; the checks' store runs elsewhere
def test_health_says_whether_the_model_is_deployable(live):
    c = live.client
    cid = import_real(c, "irb120_wu")
    nominal = done_job(c, campaign_id=cid, method="nominal")
    fitted = done_job(c, campaign_id=cid, method="ls-sum")
    assert nominal["validation"]["deployable"] is False
    assert fitted["validation"]["deployable"] is True

    h = c.get(f"/api/models/{fitted['id']}/health").json()
    assert (h["checked"], h["deployable"], h["not_deployable"]) == (False, True, []), h

    r = c.post(
        f"/api/models/{nominal['id']}/checks",
        params={"filename": "check.csv"},
        content=_six_poses(),
        headers={"content-type": "text/csv"},
    )
    assert r.status_code == 201, r.text
    # the check's own answer says it too: a line automating over POST .../checks sees it
    got = r.json()
    assert (got["deployable"], got["not_deployable"]) == (
        False,
        nominal["validation"]["reasons"],
    ), got
    h = c.get(f"/api/models/{nominal['id']}/health").json()
    assert h["checked"] is True and h["verdict"] == r.json()["verdict"], h
    assert h["deployable"] is False, h
    assert h["not_deployable"] == nominal["validation"]["reasons"], h
