"""A D-optimal plan from the page: the 202's planning job shown as "planning... N %", then its
campaign used; a failed planning job shown as an error."""

from __future__ import annotations

import re

from tests.web.conftest import shot


def _create(page, name: str) -> None:
    page.fill("#c-name", name)
    page.fill("#c-poses", "15")
    page.fill("#c-choose", "2000")
    page.click("#create")


def test_a_planning_job_is_followed_to_its_campaign(served, page):
    page.goto(served.url + "/")
    page.fill("#token", served.token)
    page.click("#token-form button[type=submit]")
    page.wait_for_selector("#c-cell[data-loaded] option[value=default]", state="attached")
    _create(page, "chosen")
    page.wait_for_selector("#c-planning:not([hidden])", timeout=10_000)
    assert re.fullmatch(r"planning\.\.\. \d{1,3} %", page.text_content("#c-planning"))
    shot(page, "planning-job")
    page.wait_for_function(
        "document.getElementById('p-status').textContent === 'planned'", timeout=180_000
    )
    assert page.text_content("#p-name") == "chosen"
    assert page.is_hidden("#c-planning")
    jobs = [j for j in served.client.get("/api/jobs").json() if j["kind"] == "planning"]
    assert [j["state"] for j in jobs] == ["done"]
    assert page.text_content("#p-id") == str(jobs[0]["campaign_id"])

    _create(page, "chosen")  # the same name while it is unfinished: the job fails
    page.wait_for_function(
        "document.getElementById('message').textContent.includes('failed: Conflict')",
        timeout=180_000,
    )
    assert "already named 'chosen'" in page.text_content("#message")
    assert page.is_hidden("#c-planning")
