"""The page's verification summary states the uncertainty and the decisions as the certificate
does: each compensated point's AP with its U and RP with its U below and above, the AP decision
against the cell's tolerance, the RP decision against its repeatability_mm (a not-decided one
says why), and a tracker past its calibration's due date shown as overdue. In headless Chromium,
on a verification run over the API of a cell that states all three."""

from __future__ import annotations

import re

from robocal.server.formats.cell_json import cell_to_json, default_cell
from robocal.server.formats.verification_doc import Decision
from robocal.server.verify.certificate import verdict_sentence
from tests.server.api.conftest import wait_for
from tests.server.api.test_verify_api import calibrate, run_campaign
from tests.web.conftest import ARTIFACTS, shot, sign_in
from tests.web.test_ui_verify import fmt

DUE = "2020-01-31"  # long past: every run of this cell is after its tracker's calibration due


def _cell() -> dict:
    doc = cell_to_json(default_cell())
    doc["tolerance_mm"], doc["repeatability_mm"] = 0.5, 0.04
    doc["tracker"].update(certificate_id="CAL-17", certificate_due=DUE, serial="AT960-1")
    return doc


def test_the_summary_states_each_figures_u_and_the_decisions(served, page):
    c = served.client
    r = c.post("/api/cells", json=_cell())
    assert r.status_code == 201, r.text
    cell = r.json()["id"]
    cal = run_campaign(c, name="cal", poses=40, seed=5, pause_s=0, cell_id=cell)
    job = calibrate(c, cal)
    r = c.post(f"/api/models/{job}/verify", json={"cycles": 2, "directions": 2, "pause_s": 0})
    assert r.status_code == 201, r.text
    vid = r.json()["id"]
    wait_for(lambda: c.get(f"/api/campaigns/{vid}").json(), lambda j: j["status"] == "done")
    rep = c.get(f"/api/campaigns/{vid}/verification").json()
    assert rep["tracker_overdue"] == DUE

    sign_in(page, served)
    page.goto(f"{served.url}/#campaign={vid}")
    page.reload()
    page.wait_for_selector("#v-uncertainty")
    rows = [
        [td.text_content() for td in tr.locator("td").all()]
        for tr in page.locator("#v-uncertainty tbody tr").all()
    ]
    want = [
        [
            p["point"],
            f"{fmt(p['AP_mm'])} ± {fmt(p['AP_U_mm'])}",
            f"{fmt(p['RP_mm'])} −{fmt(p['RP_U_below_mm'])} / +{fmt(p['RP_U_above_mm'])}",
        ]
        for p in rep["after"]["points"]
    ]
    assert rows == want, rows
    assert all(p["RP_U_above_mm"] > 0 for p in rep["after"]["points"])

    # the tracker is overdue: shown so, and neither decision passes; each says why
    assert f"Tracker calibration overdue (due {DUE})" in page.text_content("#v-overdue")
    unc = rep["uncertainty"]
    assert unc["decision"]["verdict"] == unc["rp_decision"]["verdict"] == "not decided"
    ap, rp = page.text_content("#v-ap-decision"), page.text_content("#v-rp-decision")
    assert (
        ap
        == f"AP NOT DECIDED against the tolerance 0.5 mm: the tracker's calibration was due {DUE}."
    )
    assert rp.startswith("RP NOT DECIDED against the arm's stated repeatability 0.04 mm: ")
    assert rp.endswith(f"was due {DUE}."), rp
    notes = " ".join(t.text_content() for t in page.locator("#v-table .v-note").all())
    assert "U of an RP (95 %)" in notes and "U of an AP" in notes
    assert "pass only when every point's RP plus its U above is within" in notes
    page.locator("#verification").scroll_into_view_if_needed()
    shot(page, "verification-uncertainty")
    page.locator("#v-report").screenshot(
        path=str(ARTIFACTS / "verification-uncertainty-closeup.png")
    )

    # every verdict worded as the certificate words it (a not decided one without an overdue
    # tracker: the figure is within the tolerance less its U, not plus it)
    for verdict, late in (("pass", None), ("fail", None), ("not decided", None),
                          ("not decided", DUE), ("no tolerance", None)):  # fmt: skip
        dec = Decision(verdict=verdict, tracker_overdue=late, tolerance_mm=0.04, rule="r",
                       worst_upper_mm=0.05, worst_lower_mm=0.03)  # fmt: skip
        args = ("RP", "arm's stated repeatability", "the cell's repeatability_mm")
        shown = page.evaluate("([d, a]) => decisionText(d, ...a)", [dec.to_json(), list(args)])
        assert shown == re.sub("<[^>]+>", "", verdict_sentence(dec, *args)), (verdict, shown)
