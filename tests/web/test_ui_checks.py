"""A model's quick checks in real headless Chromium: the latest check's verdict on the model, the
history as a table (newest first, each verdict and reason), its chart, and a check.csv posted
from the page joining the history."""

from __future__ import annotations

from tests.server.api.test_checks_api import bumped, calibrated, cell, check_csv  # noqa: F401
from tests.web.conftest import shot


def test_checks_verdict_history_and_chart_shown(served, page, cell, tmp_path):  # noqa: F811
    job = calibrated(served, cell[0])
    c = served.client
    page.goto(served.url + "/")
    page.fill("#token", served.token)
    page.click("#token-form button[type=submit]")
    page.wait_for_selector("#c-cell[data-loaded] option[value=default]", state="attached")
    page.evaluate("(job) => openJob(job)", job)
    page.wait_for_selector("#m-health:not([hidden])")
    assert "Never checked" in page.text_content("#m-health")
    assert page.is_hidden("#k-charts")
    assert page.text_content("#k-health-url") == f"GET /api/models/{job}/health"

    for k in range(3):  # three clean checks through the API, then the tracker bumped on the page
        r = c.post(f"/api/models/{job}/checks", content=check_csv(cell, 200 + k),
                   params={"filename": f"shift-{k}.csv"})  # fmt: skip
        assert r.status_code == 201, r.text
    page.evaluate("(job) => showChecks(job)", job)
    page.wait_for_function("document.querySelectorAll('#k-table tbody tr.k-check').length === 3")
    hist = c.get(f"/api/models/{job}/checks").json()["checks"]
    rows = page.locator("#k-table tbody tr.k-check")
    assert rows.nth(0).locator("td").nth(2).text_content() == "shift-2.csv"  # newest first
    assert [rows.nth(i).locator("td").nth(11).text_content() for i in range(3)] == [
        e["verdict"] for e in reversed(hist)
    ]
    assert hist[-1]["reason"] in page.text_content("#m-health")

    path = tmp_path / "bumped.csv"
    path.write_text(check_csv(cell, 203, bumped))
    page.set_input_files("#k-file", str(path))
    page.click("#k-post")
    page.wait_for_function("document.getElementById('k-state').textContent.startsWith('check 4')")
    page.wait_for_function("document.querySelectorAll('#k-table tbody tr.k-check').length === 4")
    assert page.text_content("#k-state") == "check 4: recalibrate"
    newest = rows.nth(0).locator("td")
    assert newest.nth(2).text_content() == "bumped.csv"
    assert newest.nth(11).text_content() == "recalibrate"
    reason = page.locator("#k-table tbody tr.k-reason").nth(0).text_content()
    assert "the tracker or the base moved" in reason, reason
    health = page.locator("#m-health")
    assert health.get_attribute("class") == "k-recalibrate"
    assert health.locator(".k-badge").text_content() == "recalibrate"
    assert "latest check (4 of this model" in health.text_content()
    page.wait_for_function(  # the chart of the four checks, not of the three before
        "(() => { const i = document.getElementById('k-chart');"
        " return i.dataset.url.endsWith('#4') && i.complete && i.naturalWidth > 0; })()"
    )
    assert page.is_visible("#k-chart")
    page.locator("#checks").scroll_into_view_if_needed()
    shot(page, "checks")


def test_a_check_run_on_the_cell_from_the_page_joins_the_history(served, page):
    """The model's "Run a check on the cell": its poses run on the simulated cell, followed on the
    page, and the verdict said there and in the history."""
    from tests.server.api.test_verify_api import calibrate, run_campaign

    c = served.client
    job = calibrate(c, run_campaign(c, name="cal", poses=40, seed=3, pause_s=0))
    page.goto(served.url + "/")
    page.fill("#token", served.token)
    page.click("#token-form button[type=submit]")
    page.wait_for_selector("#c-cell[data-loaded] option[value=default]", state="attached")
    page.evaluate("(job) => openJob(job)", job)
    page.wait_for_selector("#m-health:not([hidden])")
    assert "Never checked" in page.text_content("#m-health")
    page.click("#k-run")
    page.wait_for_function(
        "document.getElementById('k-run-state').textContent.startsWith('check 1: ')"
    )
    assert page.text_content("#k-run-state") == "check 1: ok"
    page.wait_for_function("document.querySelectorAll('#k-table tbody tr.k-check').length === 1")
    [entry] = c.get(f"/api/models/{job}/checks").json()["checks"]
    source = page.locator("#k-table tbody tr.k-check").nth(0).locator("td").nth(2).text_content()
    assert source == entry["source"] and source.startswith("campaign "), source
    assert page.locator("#m-health .k-badge").text_content() == "ok"
    assert page.is_enabled("#k-run")
