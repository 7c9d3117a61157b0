"""The campaign buttons follow the life cycle: each is enabled only when the state allows it."""

from __future__ import annotations

import httpx

from tests.web.conftest import shot

BUTTONS = ("start", "pause", "resume", "abort", "reset", "estop")
# The actions drivers/lifecycle.py allows in each state this walk passes through.
EXPECTED = {
    "planned": {"start", "abort"},
    "running": {"pause", "abort", "estop"},
    "paused": {"resume", "abort", "estop"},
    "estopped": {"reset", "abort", "estop"},
    "done": set(),
}
POSES = 300  # long enough to pause, resume and e-stop it on the way


def _wait_status(page, status, timeout=120_000):
    try:
        page.wait_for_function(
            f"document.getElementById('p-status').textContent === {status!r}", timeout=timeout
        )
    except Exception:  # say what the page shows instead
        shown = [page.text_content(f"#{i}") for i in ("p-status", "p-run", "message")]
        raise AssertionError(f"waited for {status!r}; the page shows {shown}") from None
    # the buttons are updated in the same call that writes the status
    return {a for a in BUTTONS if page.is_enabled(f"button[data-action={a}]")}


def test_buttons_walk_the_life_cycle(served, page):
    page.goto(served.url + "/")
    page.fill("#token", served.token)
    page.click("#token-form button[type=submit]")
    page.wait_for_selector("#c-cell[data-loaded] option[value=default]", state="attached")
    page.fill("#c-poses", str(POSES))
    page.click("#create")
    page.wait_for_selector("#progress:not([hidden])")

    seen = {}

    def step(status, click=None):
        enabled = _wait_status(page, status)
        assert page.is_enabled("#estop-all"), "the header e-stop is always enabled"
        assert enabled == EXPECTED[status], (status, enabled)
        seen[status] = enabled
        if click:
            page.click(f"button[data-action={click}]")

    step("planned", "start")
    step("running", "pause")
    step("paused", "resume")
    step("running", "estop")
    step("estopped", "reset")
    shot(page, "states-after-reset")
    step("paused", "resume")
    step("running")
    enabled = _wait_status(page, "done", timeout=300_000)
    assert enabled == EXPECTED["done"]
    # a done campaign can be calibrated, once the page has the job list
    page.wait_for_function("!document.getElementById('calibrate').disabled")
    assert page.text_content("#p-count") == f"{POSES} / {POSES} poses"

    # readings taken before the e-stop stayed, and none was taken twice
    with httpx.Client(
        base_url=served.url, timeout=60, headers={"Authorization": f"Bearer {served.token}"}
    ) as c:
        cid = int(page.text_content("#p-id"))
        rows = c.get(f"/api/campaigns/{cid}/measurements").json()
    keys = [(r["pose"], r["target"]) for r in rows]
    assert len(keys) == len(set(keys)) == 3 * POSES
