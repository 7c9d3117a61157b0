"""The fleet in the page, in headless Chromium against a real server: twelve simulated arms, the
bent one's row highlighted and its a2 plotted against the fleet's median and limits."""

from __future__ import annotations

from robocal.server import store
from tests.server.fleet.arms import ARMS, BENT, build_fleet
from tests.web.conftest import shot


def test_the_bent_arm_is_highlighted_and_plotted(served, page, tmp_path):
    with store.open_database(served.settings.database) as db:
        build_fleet(db, tmp_path)
    page.goto(served.url + "/")
    page.fill("#token", served.token)
    page.click("#token-form button[type=submit]")
    page.wait_for_selector("#fleet-table")
    rows = page.query_selector_all("#fleet-table tbody tr")
    assert len(rows) == ARMS
    flagged = page.query_selector_all("#fleet-table tbody tr.flagged")
    assert [r.query_selector("td").text_content() for r in flagged] == [BENT]
    assert page.input_value("#fleet-parameter") == "a2"
    assert page.locator("#fleet-svg circle").count() == ARMS
    assert "limit" in page.text_content("#fleet-svg")
    shot(page.locator("#fleet").page, "fleet")
