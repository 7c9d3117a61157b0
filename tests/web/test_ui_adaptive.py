"""An adaptive campaign from the page: its target in the form, the predicted accuracy shown live
as each step is heard, and why it stopped (screenshot in the test artifacts)."""

from __future__ import annotations

import re

from tests.web.conftest import shot


def test_the_predicted_accuracy_is_shown_live_and_the_stop_said(served, page):
    page.goto(served.url + "/")
    page.fill("#token", served.token)
    page.click("#token-form button[type=submit]")
    page.wait_for_selector("#c-cell option[value=default]", state="attached")
    page.fill("#c-name", "adaptive")
    page.fill("#c-poses", "40")
    page.fill("#c-target", "0.05")
    page.select_option("#c-settle", "adaptive")
    page.fill("#c-pause", "0")
    page.click("#create")
    page.wait_for_selector("#progress:not([hidden])")
    assert page.text_content("#p-adaptive") == (
        "target 0.05 mm: predicted accuracy after the seed poses"
    )
    seed = int(re.search(r"/ (\d+) poses", page.text_content("#p-count")).group(1))
    page.click("#start")
    # a step that goes on: shown while the campaign still runs
    page.wait_for_function(
        "document.getElementById('p-adaptive').textContent.startsWith('predicted')",
        timeout=120_000,
    )
    first = page.text_content("#p-adaptive")
    assert re.fullmatch(
        r"predicted held-out RMS \d\.\d{4} mm at \d+ poses \(target 0\.05 mm, floor \d\.\d{4} mm\)"
        r"( — stopped .*)?",
        first,
    ), first
    page.wait_for_function(
        "document.getElementById('p-status').textContent === 'done'", timeout=180_000
    )
    page.wait_for_function(
        "document.getElementById('p-adaptive').textContent.includes('stopped (target)')"
    )
    text = page.text_content("#p-adaptive")
    poses = int(re.search(r"at (\d+) poses", text).group(1))
    assert poses > seed
    assert page.text_content("#p-count") == f"{poses} / {poses} poses"
    assert page.evaluate("live.seen['campaign.adaptive']") >= 2
    shot(page, "adaptive-stopped")
