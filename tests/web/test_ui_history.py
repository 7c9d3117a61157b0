"""History in the page, in headless Chromium against a real server: a reload mid-campaign and after
a job finds the view again (from the URL); a job's end comes from the event stream (no polling of
the job while the stream is up) with a notice; older campaigns and jobs reopen from the history
lists; two models side by side on a validation campaign; no horizontal overflow at 1366x768 and
at 390 px wide."""

from __future__ import annotations

import re

from tests.server.api.conftest import wait_for
from tests.web.conftest import ARTIFACTS, shot

POSES = 120  # long enough to reload the page while it runs


def _status(page):
    return page.text_content("#p-status")


def _done_count(page) -> int:
    return int(page.text_content("#p-count").split("/")[0])


def _calibrate(page, method: str, requests: list) -> int:
    """Calibrate the page's campaign; the job id, once the notice says it is done."""
    page.select_option("#j-method", method)
    page.wait_for_function("!document.getElementById('calibrate').disabled")
    shown = page.text_content("#j-state")  # the job shown before (its line changes)
    del requests[:]
    page.click("#calibrate")
    page.wait_for_function(
        "([shown]) => { const t = document.getElementById('j-state').textContent;"
        " return t.startsWith('job ') && t !== shown; }",
        arg=[shown],
        timeout=30_000,
    )
    job = int(re.match(r"job (\d+)", page.text_content("#j-state")).group(1))
    page.wait_for_selector("#notice:not([hidden])", timeout=300_000)
    page.wait_for_function(
        f"document.getElementById('notice-text').textContent.startsWith('job {job} ')",
        timeout=300_000,
    )
    assert page.text_content("#notice-text") == f"job {job} ({method}) done — view results"
    # the end came from the stream: the job itself was never asked for
    polled = [u for u in requests if re.search(rf"/api/jobs/{job}(\?|$)", u)]
    assert polled == [], polled
    return job


SHOWN = """(job) => ['boxplot', 'errors'].every((id) => {
    const img = document.getElementById(id);
    return (img.dataset.url || '').includes(`/jobs/${job}/`) && img.src.startsWith('blob:')
        && img.complete && !img.closest('figure').classList.contains('loading');
}) && document.querySelector('#h-jobs-table tr.current')?.dataset.job === String(job)
  && document.querySelector('#table3-table thead th.chosen') !== null"""


def _reopen_from_the_cache(page, other: int, job: int) -> None:
    """Another job, then this one again from the history: its charts and Table 3 come from the
    cache (each answer says so); the time from the click to all of them shown is printed and kept
    in the artifacts (a figure, not an assertion)."""
    import json
    import time

    page.click(f"#h-jobs-table button[data-job='{other}']")
    page.wait_for_function(SHOWN, arg=other, timeout=180_000)
    answers: list = []
    page.on(
        "response",
        lambda r: (
            f"/api/charts/jobs/{job}/" in r.url
            and answers.append((r.url.rsplit("/", 1)[-1], r.headers.get("x-robocal-cache")))
        ),
    )
    t0 = time.monotonic()
    page.click(f"#h-jobs-table button[data-job='{job}']")
    page.wait_for_function(SHOWN, arg=job, timeout=180_000)
    seconds = time.monotonic() - t0
    assert sorted(answers) == [("boxplot.png", "hit"), ("errors.png", "hit"), ("table3", "hit")]
    ARTIFACTS.mkdir(exist_ok=True)
    (ARTIFACTS / "history-reopen.json").write_text(json.dumps({"job": job, "seconds": seconds}))
    print(f"\njob {job} reopened from the history: charts and Table 3 shown in {seconds:.3f} s")


def _no_overflow(page) -> None:
    width = page.evaluate("document.documentElement.scrollWidth")
    inner = page.evaluate("window.innerWidth")
    assert width <= inner, f"the page is {width} px wide in a {inner} px window"


def test_history_reload_stream_notice_and_compare(served, page):
    requests: list[str] = []
    page.on("request", lambda r: requests.append(r.url))
    page.set_viewport_size({"width": 1366, "height": 768})
    page.goto(served.url + "/")
    assert "robocal token reset" in page.text_content("#token-help")
    assert "token.sha256" in page.text_content("#token-help")
    page.fill("#token", served.token)
    page.click("#token-form button[type=submit]")
    page.wait_for_selector("#c-cell[data-loaded] option[value=default]", state="attached")
    page.wait_for_function("document.getElementById('live').textContent === 'live'")

    # Planning fields and the estimate before planning: 3 SMRs on the default cell.
    page.fill("#c-name", "calibration")
    page.fill("#c-poses", str(POSES))
    page.fill("#c-pause", "5")
    page.fill("#c-samples", "500")
    page.check("#c-order")
    estimate = page.text_content("#c-estimate")
    assert estimate.startswith("Estimated duration: about "), estimate
    assert f"{POSES} poses x (move ~1.3 s" in estimate and "3 SMRs" in estimate, estimate
    page.click("#create")
    page.wait_for_selector("#progress:not([hidden])")
    cid = int(page.text_content("#p-id"))
    campaign = served.client.get(f"/api/campaigns/{cid}").json()
    options = campaign["settings"]["options"]
    assert (options["pause_s"], options["samples"], options["order"]) == (5, 500, True)
    assert "on the planned tour" in page.text_content("#p-estimate")

    # Reload mid-campaign: the URL names the campaign, the page finds it running again.
    page.click("#start")
    page.wait_for_function(
        "Number(document.getElementById('p-count').textContent.split('/')[0]) >= 5",
        timeout=120_000,
    )
    before = _done_count(page)
    # poses come in: the status follows within a read of the campaign (an event asks for one)
    page.wait_for_function(
        "document.getElementById('p-status').textContent === 'running'", timeout=10_000
    )
    assert f"campaign={cid}" in page.url
    page.reload()
    page.wait_for_function(f"document.getElementById('p-id').textContent === '{cid}'")
    page.wait_for_function("document.getElementById('live').textContent === 'live'")
    assert _status(page) in ("running", "done")
    assert _done_count(page) >= before
    page.wait_for_function(
        "document.getElementById('p-status').textContent === 'done'", timeout=300_000
    )
    page.wait_for_function(
        f"document.getElementById('p-count').textContent === '{POSES} / {POSES} poses'"
    )
    assert page.locator(f"#h-campaigns-table tr[data-campaign='{cid}']").count() == 1

    # A job's end from the stream, announced; a click on the notice shows the results.
    minimax = _calibrate(page, "minimax", requests)
    assert page.evaluate("live.seen.job") >= 2  # queued ... done, as events
    page.click("#notice-text")
    assert page.is_hidden("#notice")
    page.wait_for_selector("#results:not([hidden])")
    assert page.get_attribute("#model-link", "href") == f"/api/models/{minimax}"
    page.wait_for_function(
        "(() => { const r = document.getElementById('results').getBoundingClientRect();"
        " return r.top < window.innerHeight && r.bottom > 0; })()"
    )

    # Reload after the job: the same campaign and the same results.
    assert f"job={minimax}" in page.url
    page.reload()
    page.wait_for_selector("#results:not([hidden])")
    assert page.text_content("#p-id") == str(cid)
    assert page.get_attribute("#model-link", "href") == f"/api/models/{minimax}"
    assert page.text_content("#j-state") == f"job {minimax} (minimax): done"
    page.wait_for_function("document.getElementById('live').textContent === 'live'")
    ls_sum = _calibrate(page, "ls-sum", requests)

    # A validation campaign made elsewhere (the API), on the same simulated arm (the seed makes
    # the arm): other poses, chosen among 600 candidates. The history shows it as it comes.
    c = served.client
    plan = {"poses": 30, "seed": 0, "choose_from": 600, "name": "validation"}
    planning = c.post("/api/campaigns", json=plan).json()
    vid = wait_for(
        lambda: c.get(f"/api/jobs/{planning['id']}").json(),
        lambda j: j["state"] != "running" and j["state"] != "queued",
    )["campaign_id"]
    assert c.post(f"/api/campaigns/{vid}/start").status_code == 202
    wait_for(lambda: c.get(f"/api/campaigns/{vid}").json()["status"], lambda s: s == "done")
    page.wait_for_function(
        f"""(() => {{ const tr = document.querySelector("#h-campaigns-table tr[data-campaign='{vid}']");
        return tr && tr.cells[4].textContent === 'done'; }})()""",
        timeout=60_000,
    )
    rows = page.locator("#h-jobs-table tbody tr")  # newest first, the planning job too
    assert [rows.nth(i).get_attribute("data-job") for i in range(rows.count())] == [
        str(planning["id"]),
        str(ls_sum),
        str(minimax),
    ]
    assert rows.first.locator("td").nth(2).text_content() == "planning"

    # Reopen: the validation campaign, then the older one, then the minimax job's results.
    page.click(f"#h-campaigns-table button[data-campaign='{vid}']")
    page.wait_for_function(f"document.getElementById('p-id').textContent === '{vid}'")
    assert page.is_hidden("#results")
    assert f"campaign={vid}" in page.url and "job=" not in page.url
    page.click(f"#h-campaigns-table button[data-campaign='{cid}']")
    page.wait_for_function(f"document.getElementById('p-id').textContent === '{cid}'")
    assert page.text_content("#p-name") == "calibration"
    page.wait_for_function("!document.getElementById('calibrate').disabled")
    page.click(f"#h-jobs-table button[data-job='{minimax}']")
    page.wait_for_selector("#results:not([hidden])")
    assert page.get_attribute("#model-link", "href") == f"/api/models/{minimax}"
    assert page.locator("#h-jobs-table tr.current").get_attribute("data-job") == str(minimax)
    page.wait_for_selector("#table3-table thead th.chosen", timeout=180_000)
    assert page.text_content("#table3-table thead th.chosen") == "minimax"  # its own, not ls-sum's
    _reopen_from_the_cache(page, ls_sum, minimax)

    # Two models side by side on the validation campaign.
    page.select_option("#cmp-a", str(minimax))
    page.select_option("#cmp-b", str(ls_sum))
    page.select_option("#cmp-campaign", str(vid))
    page.click("#cmp-run")
    page.wait_for_selector("#compare-table", timeout=120_000)
    heads = page.locator("#compare-table thead th").all_text_contents()
    assert heads == [f"on campaign {vid}", "nominal", f"job {minimax} (minimax)",
                     f"job {ls_sum} (ls-sum)"]  # fmt: skip
    ap = page.locator("#compare-table tbody tr").first.locator("td").all_text_contents()
    assert ap[0] == "AP mean / mm"
    values = [float(v) for v in ap[1:]]
    for job, shown in zip((minimax, ls_sum), values[1:]):
        ev = c.get(f"/api/models/{job}/evaluate", params={"campaign_id": vid}).json()
        assert abs(shown - ev["model"]["ap"]["mean"]) < 1e-3, (job, shown)
    assert values[1] < values[0] and values[2] < values[0]  # both beat the nominal arm

    # A calibration validated on that campaign (not fitted on): its error there is the headline.
    options = page.locator("#j-holdout option").all_text_contents()
    assert options[0].startswith("none") and not any(f"campaign {cid}:" in o for o in options)
    page.select_option("#j-holdout", str(vid))
    held = _calibrate(page, "minimax", requests)
    page.click("#notice-text")
    page.wait_for_function(
        f"document.getElementById('m-headline').textContent.startsWith('Held-out campaign {vid}')"
    )
    h = c.get(f"/api/jobs/{held}").json()["holdout"]
    assert h["campaign_id"] == vid and h["poses"] == 30 and h["warning"] is None, h
    headline = page.text_content("#m-headline")
    assert f"RMS {h['rms_mm']:.4f} mm (30 poses" in headline, headline
    assert "leave-one-pose-out RMS" in headline and "fit RMS" in headline, headline

    # The layout: no horizontal overflow at a laptop's size and at a phone's width.
    _no_overflow(page)
    shot(page, "page-1366x768")
    page.evaluate("window.scrollTo(0, 0)")  # what the screen shows first
    page.screenshot(path=str(ARTIFACTS / "page-1366x768-screen.png"))
    page.set_viewport_size({"width": 390, "height": 844})
    _no_overflow(page)
    shot(page, "page-390")
