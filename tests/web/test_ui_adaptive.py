"""An adaptive campaign from the page: its target in the form, the predicted accuracy shown live
as each step is heard, and why it stopped (screenshot in the test artifacts)."""

from __future__ import annotations

import re

from tests.web.conftest import shot, sign_in

FORM = {"#c-name": "adaptive", "#c-poses": "40", "#c-target": "0.05", "#c-pause": "0"}


def test_the_predicted_accuracy_is_shown_live_and_the_stop_said(served, page):
    sign_in(page, served)
    for field, value in FORM.items():
        page.fill(field, value)
    page.select_option("#c-settle", "adaptive")
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
