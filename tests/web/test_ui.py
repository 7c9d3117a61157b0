"""The page in real headless Chromium against a real server: token, campaign, calibration, charts."""

from __future__ import annotations

import csv
import io
import json
import re
import time

import httpx

from robocal.server.exports.rapid import read_module
from tests.server.api.conftest import wait_for
from tests.web.conftest import said
from tests.web.conftest import shot as _shot


def _get(served, url, **kw):
    """GET with the token: reads need it."""
    return httpx.get(url, headers={"Authorization": f"Bearer {served.token}"}, **kw)


def _done_job(served, poses=20, method="ls-sum"):
    """A done calibration job made through the API; its id."""
    with httpx.Client(
        base_url=served.url, timeout=60, headers={"Authorization": f"Bearer {served.token}"}
    ) as c:
        cid = c.post("/api/campaigns", json={"poses": poses}).json()["id"]
        assert c.post(f"/api/campaigns/{cid}/start").status_code == 202
        wait_for(
            lambda: c.get(f"/api/campaigns/{cid}").json()["status"],
            lambda s: s in ("done", "failed", "aborted"),
        )
        job = c.post("/api/jobs", json={"campaign_id": cid, "method": method}).json()
        job = wait_for(
            lambda: c.get(f"/api/jobs/{job['id']}").json(),
            lambda j: j["state"] in ("done", "failed"),
        )
        assert job["state"] == "done", job
        return job["id"]


def test_chart_endpoints_answer_png_and_table3(served):
    job = _done_job(served)
    base = f"{served.url}/api/charts/jobs/{job}"
    for name in ("boxplot.png", "errors.png"):
        r = _get(served, f"{base}/{name}", timeout=60)
        assert r.status_code == 200 and r.headers["content-type"] == "image/png", r.text
        assert r.content.startswith(b"\x89PNG")
    t = _get(served, f"{base}/table3", timeout=120).json()
    assert t["targets"] == ["A", "B", "C"] and t["poses"] == 20
    assert t["columns"][0] == "nominal" and "ls-sum" in t["columns"]
    ap_max = next(r["values"] for r in t["rows"] if r["label"] == "AP max / mm")
    col = dict(zip(t["columns"], ap_max))
    assert col["ls-sum"] < col["nominal"]  # calibrating must beat the nominal model
    missing = _get(served, f"{served.url}/api/charts/jobs/999/boxplot.png")
    assert missing.status_code == 404 and missing.json()["detail"] == "no job 999"


def test_page_is_served_and_api_still_answers(served):
    r = httpx.get(f"{served.url}/")  # the page and its files need no token
    assert r.status_code == 200 and "<title>robocal</title>" in r.text
    assert httpx.get(f"{served.url}/app.js").status_code == 200
    assert httpx.get(f"{served.url}/api/campaigns").status_code == 401  # the data does
    assert _get(served, f"{served.url}/api/campaigns").json() == []  # the mount shadows nothing
    r = httpx.post(f"{served.url}/api/no-such-route")  # a 404 problem, not the file server's 405
    assert r.status_code == 404 and r.headers["content-type"] == "application/problem+json"
    assert r.json()["detail"] == "no API route POST /api/no-such-route"


def test_campaign_to_calibration_charts_in_the_browser(served, page, tmp_path):
    t0 = time.monotonic()
    page.goto(served.url + "/")
    page.fill("#token", served.token)
    page.click("#token-form button[type=submit]")
    assert page.evaluate("sessionStorage.getItem('robocal.token')") == served.token

    page.wait_for_selector("#c-cell[data-loaded] option[value=default]", state="attached")
    page.select_option("#c-cell", "default")
    page.fill("#c-poses", "20")
    page.fill("#c-seed", "3")
    page.select_option("#c-settle", "adaptive")
    page.click("#create")
    page.wait_for_selector("#progress:not([hidden])")
    page.click("#start")
    page.wait_for_function(
        "document.getElementById('p-status').textContent === 'done'", timeout=180_000
    )
    assert page.text_content("#p-count") == "20 / 20 poses"
    # the page follows the run until it has ended, not just the state: its last word is shown
    page.wait_for_function(
        "document.getElementById('p-run').textContent === 'last run: the run ended done'"
    )
    # The latest readings, refreshed with the progress poll: the last is pose 20's.
    page.wait_for_selector("#readings-table tbody tr")
    rows = page.locator("#readings-table tbody tr")
    assert 1 <= rows.count() <= 6
    # 20 poses x 3 SMRs; an early target the rough base leaves unfound may be recorded missing.
    # The table refreshes on the next progress poll after the count, so wait for it.
    page.wait_for_function(
        """() => {
        const c = document.querySelector('#readings-table caption');
        const m = c && c.textContent.match(/of (\\d+) readings/);
        return m && Number(m[1]) >= 55; }""",
        timeout=15000,
    )
    caption = page.text_content("#readings-table caption")
    assert 55 <= int(re.search(r"of (\d+) readings", caption).group(1)) <= 60, caption

    # A done campaign allows nothing more: every campaign button is disabled (the header's
    # e-stop stays enabled, as always).
    for action in ("start", "pause", "resume", "abort", "reset", "estop"):
        assert page.is_disabled(f"button[data-action={action}]"), action
    assert page.is_enabled("#estop-all")
    _shot(page, "campaign_done")

    page.select_option("#j-method", "minimax")
    page.check("#j-auto")  # automatic extensions: a diagnosis job as well
    page.click("#calibrate")
    page.wait_for_selector("#results:not([hidden])", timeout=180_000)
    for img in ("#boxplot", "#errors"):
        page.wait_for_function(
            f"(() => {{ const i = document.querySelector('{img}');"
            " return i.complete && i.naturalWidth > 0; })()",
            timeout=120_000,
        )
    page.wait_for_selector("#table3-table", timeout=180_000)
    headers = page.locator("#table3-table thead th").all_text_contents()
    assert "minimax" in headers and "nominal" in headers
    assert page.locator("#table3-table tbody tr").count() >= 5
    href = page.get_attribute("#model-link", "href")
    assert href.startswith("/api/models/")
    model = _get(served, served.url + href).json()
    assert model["method"] == "minimax"
    rrd = page.get_attribute("#recording-link", "href")
    assert rrd.startswith("/api/jobs/") and rrd.endswith("/recording")
    assert page.is_visible("#recording-link")
    # The diagnosis: on clean simulated data it may well find nothing; either is a rendering.
    page.wait_for_selector("#diagnosis:not([hidden])")
    page.wait_for_selector("#effects-table, #d-none", timeout=300_000)
    assert "held-out RMS" in page.text_content("#d-state")
    if page.locator("#effects-table").count():
        assert page.locator("#effects-table tbody tr").count() >= 1
        assert page.locator("#d-figures img").count() >= 1
    else:
        assert "No effect" in page.text_content("#d-none")
    assert page.get_attribute("#d-links a", "href").endswith("/report")

    # Compensation from the page: the campaign's first readings as targets, their joints as
    # the starting guess; joints.csv, a RAPID module and a URDF come back as downloads.
    cid = page.text_content("#p-id")
    meas = list(
        csv.DictReader(
            io.StringIO(_get(served, f"{served.url}/api/campaigns/{cid}/measurements.csv").text)
        )
    )
    poses = sorted({r["pose"] for r in meas}, key=int)[:3]
    with open(tmp_path / "targets.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["pose", "target", "x", "y", "z", *[f"q{i}" for i in range(1, 7)]])
        for r in meas:
            if r["pose"] in poses and r["x"]:
                w.writerow([r["pose"], r["target"], r["x"], r["y"], r["z"],
                            *[r[f"q{i}"] for i in range(1, 7)]])  # fmt: skip
    page.set_input_files("#t-file", str(tmp_path / "targets.csv"))
    with page.expect_download(timeout=120_000) as got:
        page.click("#t-joints")
    joints = list(csv.DictReader(open(got.value.path())))
    assert [j["pose"] for j in joints] == poses and got.value.suggested_filename.endswith(".csv")
    with page.expect_download(timeout=120_000) as got:
        page.click("#t-rapid")
    mod = read_module(open(got.value.path()).read())
    assert len(mod.moves) == len(poses)
    with page.expect_download(timeout=120_000) as got:
        page.click("#x-urdf")
    assert "<robot" in open(got.value.path()).read()
    assert page.text_content("#t-state").startswith("saved ")
    shot = _shot(page, "results")
    assert shot.stat().st_size > 10_000
    print(f"browser flow took {time.monotonic() - t0:.1f} s")


def test_token_missing_shows_the_refusal(served, page):
    page.goto(served.url + "/")
    page.click("#create")
    page.wait_for_selector("#message:not([hidden])")
    text, technical = said(page)
    assert "API token" in text and "section 1" in text, text
    assert "401" in technical, technical


def test_cell_picker_upload_and_refusal(served, page):
    page.goto(served.url + "/")
    page.fill("#token", served.token)
    page.click("#token-form button[type=submit]")
    page.wait_for_selector("#c-cell[data-loaded] option[value=default]", state="attached")
    page.click("#cell-upload summary")
    page.fill("#cell-json", '{"schema": 1,\n "robot": ')  # broken JSON: a 422 with its line
    page.click("#cell-upload-btn")
    page.wait_for_selector("#message:not([hidden])")
    text, technical = said(page)
    assert text.startswith("The cell was not uploaded: "), text
    assert "422" in technical and "POST /api/cells" in technical, technical
    # The default cell, sent back, is a valid upload: it becomes an id in the picker, selected.
    cell = _get(served, f"{served.url}/api/cells/default").json()["cell"]
    page.fill("#cell-json", json.dumps(cell, indent=2))
    page.click("#cell-upload-btn")
    page.wait_for_function("document.getElementById('c-cell').options.length === 2")
    chosen = page.input_value("#c-cell")
    assert chosen != "default" and chosen in _get(served, f"{served.url}/api/cells").json()
    page.click("#create")
    page.wait_for_selector("#progress:not([hidden])")
    assert "on cell " + chosen in page.text_content("#message")
