"""Notices for people (issue 26): in the operator's words with the HTTP one click away, in a fixed
place that never covers a control, read out by screen readers; simulated time said as such; one
pose count for the bar and the history; and no serious accessibility violation (axe-core)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.web.conftest import said, shot

VIEWPORTS = {"desktop": (1366, 768), "phone": (390, 844)}

# Where nothing may lie over an enabled button: each one visible below the sticky header is the
# element the browser hits at its centre, and the notices lie inside the header.
COVERED = """() => {
  const header = document.querySelector("header").getBoundingClientRect();
  const boxes = ["message", "notice"].map((id) => document.getElementById(id))
    .filter((n) => !n.hidden).map((n) => n.getBoundingClientRect());
  const out = { covered: [], outside: [], intersecting: [], checked: 0 };
  for (const b of boxes) {
    if (b.top < header.top - 0.5 || b.bottom > header.bottom + 0.5) out.outside.push(b.top);
  }
  const vh = window.innerHeight;
  for (const el of document.querySelectorAll("main button")) {
    if (el.disabled || !el.checkVisibility({ visibilityProperty: true })) continue;
    const r = el.getBoundingClientRect();
    if (r.width === 0 || r.height === 0) continue;
    const name = (el.id || el.dataset.action || el.textContent.trim()).slice(0, 30);
    for (const b of boxes) {
      const overlap = r.left < b.right && b.left < r.right && r.top < b.bottom && b.top < r.bottom;
      if (overlap && r.top >= header.bottom) out.intersecting.push(name);
    }
    if (r.top < header.bottom || r.bottom > vh) continue;  // under the page's own header, or off
    out.checked += 1;
    const hit = document.elementFromPoint((r.left + r.right) / 2, (r.top + r.bottom) / 2);
    if (!hit || !(hit === el || el.contains(hit))) {
      out.covered.push(`${name} by ${hit ? hit.id || hit.tagName : "nothing"}`);
    }
  }
  return out;
}"""


def _open(page, served, size):
    page.set_viewport_size({"width": size[0], "height": size[1]})
    page.goto(served.url + "/")
    page.fill("#token", served.token)
    page.click("#token-form button[type=submit]")
    page.wait_for_selector("#c-cell[data-loaded] option[value=default]", state="attached")


def _create(page, poses: int) -> int:
    page.fill("#c-poses", str(poses))
    page.click("#create")
    page.wait_for_selector("#progress:not([hidden])")
    return int(page.text_content("#p-id"))


@pytest.mark.parametrize("view", list(VIEWPORTS))
def test_no_notice_covers_a_control(served, page, view):
    _open(page, served, VIEWPORTS[view])
    _create(page, 20)
    # a refusal (a broken cell.json) and a job's end, both shown at once: the tallest header
    page.click("#cell-upload summary")
    page.fill("#cell-json", '{"schema": 1,\n "robot": ')
    page.click("#cell-upload-btn")
    page.wait_for_function(
        "document.getElementById('message-text').textContent.includes('not uploaded')"
    )
    text, technical = said(page)
    assert text.startswith("The cell was not uploaded: ") and "422" in technical, technical
    page.evaluate(
        """() => { const n = document.getElementById("notice"); n.hidden = false;
        document.getElementById("notice-text").textContent = "job 7 (minimax) done — view results"; }"""
    )
    assert page.get_attribute("#message", "role") == "alert"
    assert page.get_attribute("#notice", "role") == "status"
    height = page.evaluate("document.documentElement.scrollHeight")
    viewport = VIEWPORTS[view][1]
    checked, positions = 0, 0
    for y in range(0, height, viewport // 3):
        page.evaluate(f"window.scrollTo(0, {y})")
        seen = page.evaluate(COVERED)
        assert not seen["outside"], f"a notice outside the header at scroll {y}"
        assert not seen["intersecting"], (y, seen["intersecting"])
        assert not seen["covered"], (y, seen["covered"])
        checked += seen["checked"]
        positions += 1
    assert checked > positions, "no button was checked: the walk proves nothing"
    page.evaluate("window.scrollTo(0, 0)")
    shot(page, f"notices-{view}")
    # dismissable, each
    page.click("#message-close")
    page.click("#notice-close")
    assert page.is_hidden("#message") and page.is_hidden("#notice")
    # what the page scrolls to lands below the header: the Calibrate button, focused from far down
    page.evaluate("window.scrollTo(0, document.documentElement.scrollHeight)")
    page.evaluate("document.getElementById('estop-all').focus()")
    page.focus("#j-method")
    top = page.evaluate("document.getElementById('j-method').getBoundingClientRect().top")
    header = page.evaluate("document.querySelector('header').getBoundingClientRect().bottom")
    assert top >= header, (top, header)


def test_estop_and_refusals_in_words(served, page):
    _open(page, served, VIEWPORTS["desktop"])
    cid = _create(page, 300)
    page.click("#start")
    page.wait_for_function("document.getElementById('p-status').textContent === 'running'")
    page.click("button[data-action=estop]")
    page.wait_for_function("document.getElementById('p-status').textContent === 'estopped'")
    text, technical = said(page)
    assert text.startswith(f"Campaign {cid} stopped: the arm halts where it is."), text
    assert "press Reset, then Resume" in text, text
    assert "estop" in technical, technical  # the API's own note, for an engineer
    # the buttons say what they do
    assert "then Resume" in page.text_content("button[data-action=reset]")
    assert "halts the arm" in page.text_content("button[data-action=estop]")
    shot(page, "notice-estop")
    # a request the state refuses (resume before reset): why, in the state's words
    page.evaluate(f"api('POST', '/campaigns/{cid}/resume').catch((e) => say(e))")
    page.wait_for_function(
        "document.getElementById('message-text').textContent.includes('could not resume')"
    )
    text, technical = said(page)
    assert text.startswith(f"Campaign {cid} could not resume: cannot resume"), text
    assert "estopped" in text and "reset" in text, text
    assert "409" in technical and f"/api/campaigns/{cid}/resume" in technical, technical
    page.click("#message-details summary")
    shot(page, "notice-refusal-details")
    page.click("button[data-action=reset]")
    page.wait_for_function("document.getElementById('p-status').textContent === 'paused'")
    text, _ = said(page)
    assert "press Resume" in text, text
    page.click("button[data-action=abort]")
    page.wait_for_function("document.getElementById('p-status').textContent === 'aborted'")


def test_simulated_time_and_one_pose_count(served, page):
    _open(page, served, VIEWPORTS["desktop"])
    page.fill("#c-poses", "40")
    estimate = page.text_content("#c-estimate")
    assert "on a real cell; simulated here in seconds" in estimate, estimate
    cid = _create(page, 40)
    assert "on a real cell; simulated here in seconds" in page.text_content("#p-estimate")
    page.click("#start")
    page.wait_for_function(
        "document.getElementById('p-status').textContent === 'done'", timeout=300_000
    )
    row = f"#h-campaigns-table tr[data-campaign='{cid}'] td.poses"
    page.wait_for_selector(row)
    assert page.text_content(row) == "40 / 40"
    assert page.text_content("#p-count") == "40 / 40 poses"
    assert page.text_content("#p-left") == ""


AXE = Path(pytest.importorskip("axe_playwright_python").__file__).parent / "axe.min.js"


def _violations(page) -> tuple[list, list]:
    """axe-core's violations on the page as it is: (serious or critical, all) described."""
    if not page.evaluate("typeof axe !== 'undefined'"):
        page.add_script_tag(path=str(AXE))
    found = page.evaluate("async () => (await axe.run(document)).violations")
    described = [
        {"id": v["id"], "impact": v["impact"], "nodes": [n["target"] for n in v["nodes"][:5]]}
        for v in found
    ]
    return [d for d in described if d["impact"] in ("serious", "critical")], described


def test_no_serious_accessibility_violation(served, page):
    _open(page, served, VIEWPORTS["desktop"])
    _create(page, 20)
    serious, found = _violations(page)
    print("campaign planned:", json.dumps(found, indent=1))
    assert not serious, json.dumps(found, indent=1)
    # the page at its fullest: a done campaign, its calibration's results, charts and tables
    page.click("#start")
    page.wait_for_function(
        "document.getElementById('p-status').textContent === 'done'", timeout=300_000
    )
    page.wait_for_selector("#calibrate:not([disabled])")
    page.click("#calibrate")
    page.wait_for_selector("#results:not([hidden])", timeout=300_000)
    page.wait_for_selector("#m-parameters table", timeout=120_000)
    serious, found = _violations(page)
    print("results shown:", json.dumps(found, indent=1))
    shot(page, "accessibility-results")
    assert not serious, json.dumps(found, indent=1)
