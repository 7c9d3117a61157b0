"""A verification run from the page in real headless Chromium: a simulated campaign calibrated,
then "Verify on the cell" followed as the page's campaign (e-stop enabled while it moves), its
ISO 9283 summary as the API gives it, and its accuracy certificate opened in a new tab."""

from __future__ import annotations

import re

import httpx

from tests.server.api.conftest import wait_for
from tests.web.conftest import said, shot

# Every change the page makes to the progress block, with the campaign and state it then shows
# and whether its e-stop button is enabled: a run shorter than a poll is still seen whole.
RECORD_PROGRESS = """() => {
  window.progressSeen = [];
  const record = () => window.progressSeen.push({
    id: document.getElementById('p-id').textContent,
    status: document.getElementById('p-status').textContent,
    estop: !document.querySelector('button[data-action=estop]').disabled });
  new MutationObserver(record).observe(document.getElementById('progress'),
    { subtree: true, childList: true, characterData: true, attributes: true });
}"""


def fmt(v: float) -> str:
    """The page's fmt(): four decimals, or JavaScript's toExponential(3) for tiny or huge."""
    a = abs(v)
    if a != 0 and (a >= 1e4 or a < 1e-3):
        return re.sub(r"e([+-])0*(\d)", r"e\1\2", f"{v:.3e}")
    return f"{v:.4f}"


def _summary(page) -> list[list[str]]:
    """The verification summary's rows, as the page shows them."""
    return [
        [td.text_content() for td in tr.locator("td").all()]
        for tr in page.locator("#v-summary tbody tr").all()
    ]


def test_verify_from_the_results_and_open_the_certificate(served, page):
    page.goto(served.url + "/")
    page.fill("#token", served.token)
    page.click("#token-form button[type=submit]")
    page.wait_for_selector("#c-cell[data-loaded] option[value=default]", state="attached")
    page.fill("#c-poses", "40")
    page.fill("#c-seed", "23")
    page.click("#create")
    page.wait_for_selector("#progress:not([hidden])")
    page.click("#start")
    page.wait_for_function(
        "document.getElementById('p-run').textContent === 'last run: the run ended done'",
        timeout=180_000,
    )
    cal = int(page.text_content("#p-id"))
    page.select_option("#j-method", "ls-sum")
    page.wait_for_function("!document.getElementById('calibrate').disabled")
    page.click("#calibrate")
    page.wait_for_selector("#results:not([hidden])", timeout=180_000)
    assert page.is_visible("#v-start") and page.input_value("#v-cycles") == "3"

    # bad fields: the API's 422 and its detail in the message area, nothing planned
    page.fill("#v-cycles", "0")
    page.click("#v-start")
    # an earlier note ("start: planned ...") may still be shown: wait for this answer's
    page.wait_for_function(
        "document.getElementById('message-technical').textContent.includes('422')"
    )
    text, technical = said(page)
    assert text.startswith("The verification run was not planned: ") and "cycles" in text, text
    assert page.text_content("#p-id") == str(cal)
    page.fill("#v-cycles", "2")
    page.fill("#v-directions", "2")

    with httpx.Client(
        base_url=served.url, timeout=120, headers={"Authorization": f"Bearer {served.token}"}
    ) as c:
        # the arm busy with another campaign: the API's 409 and its detail, nothing planned
        busy = c.post("/api/campaigns", json={"poses": 2000, "name": "busy"}).json()["id"]
        assert c.post(f"/api/campaigns/{busy}/start").status_code == 202
        page.click("#v-start")
        page.wait_for_function(
            "document.getElementById('message-technical').textContent.includes('409')"
        )
        text, _ = said(page)
        assert f"campaign {busy} is running; one at a time" in text, text
        assert page.text_content("#p-id") == str(cal)
        assert c.post(f"/api/campaigns/{busy}/abort").status_code in (200, 202)
        wait_for(
            lambda: c.get(f"/api/campaigns/{busy}").json(),
            lambda j: j["status"] == "aborted" and not (j["run"] or {}).get("active"),
        )

    page.evaluate(RECORD_PROGRESS)
    page.click("#v-start")
    page.wait_for_selector("#v-summary", timeout=300_000)
    vid = int(page.text_content("#p-id"))
    assert vid != cal and page.text_content("#p-status") == "done"
    assert page.is_visible("#results")  # the results stay: the run is of their model
    assert page.text_content("#v-state") == f"verification campaign {vid}: done"
    # 2 cycles x 5 points x 2 directions x 2 runs (nominal, compensated) x 2 (approach, point)
    assert page.text_content("#p-count") == "80 / 80 poses"

    seen = [s for s in page.evaluate("window.progressSeen") if s["id"] == str(vid)]
    moving = [s for s in seen if s["status"] == "running"]
    assert moving, seen  # the page followed the run while it moved ...
    assert all(s["estop"] for s in moving), moving  # ... and its e-stop was enabled throughout
    assert not page.is_enabled("button[data-action=estop]")  # nothing moves any more

    with httpx.Client(
        base_url=served.url, timeout=120, headers={"Authorization": f"Bearer {served.token}"}
    ) as c:
        kinds = {x["id"]: x["kind"] for x in c.get("/api/campaigns").json()}
        assert kinds == {cal: "measurement", busy: "measurement", vid: "verification"}
        r = c.get(f"/api/campaigns/{vid}/verification")
        assert r.status_code == 200, r.text
        rep = r.json()
    b, a = rep["before"], rep["after"]
    rows = _summary(page)
    gain = b["AP_max_mm"] / a["AP_max_mm"]
    assert rows == [
        ["before (nominal joints)", fmt(b["AP_max_mm"]), fmt(b["RP_max_mm"])],
        ["after (compensated)", fmt(a["AP_max_mm"]), fmt(a["RP_max_mm"])],
        ["gain (AP before / AP after)", f"{gain:.0f}x" if gain >= 10 else f"{gain:.1f}x", ""],
    ], rows
    assert b["AP_max_mm"] >= 10 * a["AP_max_mm"], (b, a)
    assert rep["model"]["path"] in page.text_content("#v-summary caption")
    for img in ("#boxplot", "#errors"):  # the results, whole, for the screenshot
        page.wait_for_function(f"document.querySelector('{img}').naturalWidth > 0")
    page.wait_for_selector("#table3-table", timeout=300_000)
    shot(page, "verification")

    # the certificate, fetched with the token, opens in a new tab from memory
    with page.expect_popup() as opened:
        page.click("#v-certificate")
    tab = opened.value
    tab.wait_for_url(re.compile(r"^blob:"))
    tab.wait_for_load_state()
    assert tab.title().startswith("Accuracy certificate"), tab.title()
    assert f"{a['AP_max_mm']:.4f}" in tab.inner_text("#verdict")
    assert rep["model"]["path"] in tab.content()
    shot(tab, "verification-certificate")

    # Reopened later from the history, or from a URL naming only the campaign: the run shows
    # under its model's results again, with the same figures.
    page.click(f"#h-campaigns-table tr[data-campaign='{cal}'] button.open")
    page.wait_for_function(f"document.getElementById('p-id').textContent === '{cal}'")
    assert page.is_hidden("#results")
    assert page.locator("#v-summary").count() == 0  # the run shown was of that job's model
    page.click(f"#h-campaigns-table tr[data-campaign='{vid}'] button.open")
    page.wait_for_selector("#v-summary")
    assert page.is_visible("#results") and page.text_content("#p-id") == str(vid)
    assert page.text_content("#v-state") == f"verification campaign {vid}: done"
    assert _summary(page) == rows
    page.goto(f"{served.url}/#campaign={vid}")
    page.reload()
    page.wait_for_selector("#v-summary")
    assert page.text_content("#p-id") == str(vid) and _summary(page) == rows
