"""A running campaign in the page's 3-D viewer: its readings added as each pose is done, from the
service alone; a reading's pose in the table opens the viewer at that pose."""

from __future__ import annotations

import io

import numpy as np

from tests.web.conftest import ARTIFACTS
from tests.web.test_ui_model import calibrate_on_page, measured_campaign
from tests.web.test_ui_viewer import (  # noqa: F401 (gl_page: a fixture)
    FRAME,
    arrow_pixels,
    gl_page,
    picture_until,
)

POSES = 120  # long enough to see poses come in while it runs


def reading_pixels(png: bytes) -> int:
    """Pixels of the readings (server/recordings/live.py colours them cyan, magenta, lime,
    yellow by target): not the tracker's red, green and blue axes nor the viewer's grey."""
    from PIL import Image

    rgb = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=int)
    r, g, b = np.moveaxis(rgb[45:, : rgb.shape[1] * 3 // 4], -1, 0)  # the 3-D view
    cyan = (r < 100) & (g > 150) & (b > 190)
    magenta = (r > 190) & (g < 90) & (b > 150)
    yellow = (r > 200) & (g > 180) & (b < 80)
    lime = (r > 80) & (r < 170) & (g > 200) & (b < 80)
    return int((cyan | magenta | yellow | lime).sum())


def frame_data(page, key: str) -> str | None:
    return page.evaluate(f"{FRAME}.body.dataset.{key} || null")


def test_running_campaign_shows_live_in_the_viewer(served, gl_page):  # noqa: F811
    page = gl_page
    elsewhere: list[str] = []
    own = (served.url + "/", "blob:" + served.url + "/")
    page.context.on("request", lambda r: r.url.startswith(own) or elsewhere.append(r.url))
    logs: list[str] = []
    page.on("console", lambda m: logs.append(f"{m.type}: {m.text[:300]}"))
    page.goto(served.url + "/")
    page.fill("#token", served.token)
    page.click("#token-form button[type=submit]")
    page.wait_for_selector("#c-cell[data-loaded] option[value=default]", state="attached")
    page.fill("#c-poses", str(POSES))
    page.fill("#c-pause", "20")
    page.fill("#c-samples", "500")
    page.click("#create")
    page.wait_for_selector("#progress:not([hidden])")
    cid = int(page.text_content("#p-id"))

    # the campaign's (empty) recording in the viewer before it starts: the tracker, the layout
    assert page.is_visible("#c3-open")
    page.click("#c3-open")
    page.wait_for_function(
        f"{FRAME} && {FRAME}.body && ['shown', 'failed'].includes({FRAME}.body.dataset.state)"
    )
    assert frame_data(page, "state") == "shown", (frame_data(page, "state"), logs[-10:])
    assert frame_data(page, "source") == f"campaign-{cid}"
    assert frame_data(page, "pieces") == "1"

    page.click("#start")
    # pieces added while it acquires: the viewer has some poses while others are still to come
    # (one check in the page, so no race with the run)
    partial = page.wait_for_function(
        f"Number({FRAME}.body.dataset.pieces) >= 2 && cell3d.nextPose >= 1"
        f" && cell3d.nextPose < {POSES} && cell3d.nextPose",
        timeout=120_000,
    ).json_value()
    print(f"live: {partial} of {POSES} poses in the viewer while the campaign ran")
    # paused, for a picture of a campaign half done (it may have ended meanwhile: still shown)
    # (through the API: the page's button may be disabled by the end between a look and a click)
    served.client.post(f"/api/campaigns/{cid}/pause")  # 409 once done
    page.wait_for_function(
        "['paused', 'done'].includes(document.getElementById('p-status').textContent)"
    )
    status = page.text_content("#p-status")
    frame = page.locator("#c3-frame")
    seen = picture_until(page, "viewer-live-campaign", reading_pixels, 100)
    assert seen > 100, f"no readings in the viewer's picture: {logs[-10:]}"
    print(f"live: {seen} reading pixels at {page.text_content('#p-count')} ({status})")
    assert "measured in the view" in page.text_content("#c3-state")

    # a reading's pose, chosen in the table: the viewer's time cursor goes there
    button = page.locator("#readings-table button.pose-link").first
    button.wait_for()
    pose = button.get_attribute("data-pose")
    button.click()
    page.wait_for_function(f"{FRAME}.body.dataset.pose === '{pose}'")
    assert f"pose {pose}" in page.text_content("#c3-state")
    page.wait_for_timeout(1000)  # a frame or two to draw it: for the picture only
    frame.screenshot(path=str(ARTIFACTS / "viewer-live-pose.png"))

    # every pose ends up in the recording, in pieces
    served.client.post(f"/api/campaigns/{cid}/resume")  # 409 when it was done already
    page.wait_for_function(
        "document.getElementById('p-status').textContent === 'done'", timeout=180_000
    )
    page.wait_for_function(f"cell3d.nextPose === {POSES}")
    pieces = int(frame_data(page, "pieces") or 0)
    print(f"live: {POSES} poses in {pieces} pieces")
    assert pieces >= 3  # the first (the tracker), one while it ran, the rest
    assert not elsewhere, f"the page asked other hosts: {elsewhere}"


def test_outlier_pose_opens_the_calibration_recording_there(served, gl_page):  # noqa: F811
    """A pose named by label in a table (the diagnosis's outliers) is a button to that pose on
    the shown calibration recording's timeline, as GET /api/jobs/{id}/recording/poses maps it."""
    page = gl_page
    cid = measured_campaign(served, 12)
    job = calibrate_on_page(served, page, cid)
    poses = served.client.get(f"/api/jobs/{job['id']}/recording/poses").json()
    readings = served.client.get(f"/api/campaigns/{cid}/measurements?limit=1000").json()
    labels = list(dict.fromkeys(r["pose"] for r in readings if r["status"] == "ok"))
    assert [p["label"] for p in poses] == labels
    assert [p["index"] for p in poses] == list(range(len(labels)))
    assert {p["set"] for p in poses} == {"calibration"}
    # the outliers as a diagnosis report lists them (crafted: this campaign has none)
    page.evaluate(
        "(o) => { $('diagnosis').hidden = false; showOutliers(o); }",
        [
            {"pose": poses[5]["label"], "target": "A", "residual_mm": 1.2},
            {"pose": "no-such-pose", "target": "B", "residual_mm": 0.3},
        ],
    )
    cells = page.locator("#outliers-table tbody td:first-child")
    cells.nth(0).locator("button.pose-link").wait_for()
    assert cells.nth(1).locator("button").count() == 0  # not on the recording: plain text
    cells.nth(0).locator("button.pose-link").click()
    page.wait_for_function(f"{FRAME} && {FRAME}.body && {FRAME}.body.dataset.pose === '5'")
    assert page.evaluate(f"{FRAME}.body.dataset.job") == str(job["id"])
    assert "pose 5" in page.text_content("#c3-state")
    # the picture once the arrows are drawn (they are asserted in test_ui_viewer)
    picture_until(page, "viewer-outlier-pose-5", arrow_pixels, 150, tries=30)
