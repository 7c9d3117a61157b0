"""The page without its event stream: it says so, follows the campaign and the job by slow polling
(the job's end still announced), and takes the stream up again once it answers."""

from __future__ import annotations

import re

from tests.web.conftest import shot


def test_the_page_polls_while_the_stream_is_down_and_reconnects(served, page):
    requests: list[str] = []
    page.on("request", lambda r: requests.append(r.url))
    page.route("**/api/events", lambda route: route.abort())  # the stream cannot be had
    page.clock.install()  # the page's timers on a clock that runs, and that the test can advance
    page.goto(served.url + "/")
    page.fill("#token", served.token)
    page.click("#token-form button[type=submit]")
    page.wait_for_selector("#c-cell[data-loaded] option[value=default]", state="attached")
    page.wait_for_function("document.getElementById('live').textContent.includes('reconnecting')")
    assert page.text_content("#live") == "updates every 5 s (reconnecting)"

    page.fill("#c-poses", "10")
    page.click("#create")
    page.wait_for_selector("#progress:not([hidden])")
    cid = int(page.text_content("#p-id"))
    page.click("#start")
    page.wait_for_function(
        "document.getElementById('p-status').textContent === 'done'", timeout=180_000
    )
    page.wait_for_function("!document.getElementById('calibrate').disabled")
    page.click("#calibrate")
    page.wait_for_selector("#notice:not([hidden])", timeout=300_000)
    job = int(re.match(r"job (\d+) ", page.text_content("#notice-text")).group(1))
    assert page.text_content("#notice-text") == f"job {job} (minimax) done — view results"
    # with no stream, the job was followed by asking for it
    assert any(re.search(rf"/api/jobs/{job}$", u) for u in requests)
    assert page.evaluate("live.seen") == {}
    page.wait_for_selector("#results:not([hidden])")
    shot(page, "stream-down")

    # The stream answers again: the page takes it up (within its backoff) and stops polling.
    page.unroute("**/api/events")
    page.clock.fast_forward("00:30")  # the longest backoff (live.js RETRY_MAX_MS), not waited
    page.wait_for_function("document.getElementById('live').textContent === 'live'", timeout=90_000)
    del requests[:]
    served.client.post("/api/jobs", json={"campaign_id": cid, "method": "ls-sum"})
    page.wait_for_function(
        "document.getElementById('notice-text').textContent.includes('(ls-sum) done')",
        timeout=300_000,
    )
    assert page.evaluate("live.seen.job") >= 2
    assert not [u for u in requests if re.search(r"/api/jobs/\d+$", u)]
