"""The cell in 3-D: rerun's web viewer served by the service, the recording handed to it by the
page, with every other host out of reach; a screenshot of the arrows."""

from __future__ import annotations

import io

import httpx
import numpy as np
import pytest

from tests.web.conftest import ARGS, ARTIFACTS, CHROMIUM
from tests.web.test_ui_model import calibrate_on_page, measured_campaign

# WebGL in headless Chromium without a GPU: SwiftShader (software). Every name resolves to
# nothing but 127.0.0.1, so a request to any other host fails, and is seen (below) as tried.
GL_ARGS = [
    *ARGS,
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1",
]
FRAME = "document.getElementById('c3-frame').contentDocument"


@pytest.fixture
def gl_page():
    if not CHROMIUM.exists():
        pytest.skip("no /usr/bin/chromium (.ci/run installs it)")
    sync_api = pytest.importorskip("playwright.sync_api")
    with sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=GL_ARGS)
        context = browser.new_context(viewport={"width": 1200, "height": 900})
        page = context.new_page()
        page.set_default_timeout(120_000)
        yield page
        context.close()
        browser.close()


def arrow_pixels(png: bytes) -> int:
    """Pixels of the error arrows in the 3-D view: saturated yellow to red (server/recordings/cell.py
    colours them green, yellow, red by size; shaded and blended in between), not the pale orange
    of the nominal arm, nor the red of an axis, nor the viewer's bars and charts."""
    from PIL import Image

    rgb = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=int)
    # the 3-D view: below the viewer's top bar (its own orange warning), the blueprint's left 3/5
    r, g, b = np.moveaxis(rgb[45:, : rgb.shape[1] * 3 // 5], -1, 0)
    return int(((r > 150) & (b < 70) & (g > 60) & (g < r - 40)).sum())


def picture_until(page, name: str, count, least: int, tries: int = 60) -> int:
    """Screenshots of the viewer's frame (tests/web/artifacts/<name>.png) once a second until
    count(png) > least (it draws over several frames once the bytes are in); the last count."""
    ARTIFACTS.mkdir(exist_ok=True)
    seen = 0
    for _ in range(tries):
        page.wait_for_timeout(1000)
        seen = count(page.locator("#c3-frame").screenshot(path=str(ARTIFACTS / f"{name}.png")))
        if seen > least:
            break
    return seen


def test_viewer_shows_the_recording_from_the_service_alone(served, gl_page):
    page = gl_page
    elsewhere: list[str] = []
    own = (served.url + "/", "blob:" + served.url + "/")  # the page's charts are blob: URLs
    page.context.on("request", lambda r: r.url.startswith(own) or elsewhere.append(r.url))
    logs: list[str] = []
    page.on("console", lambda m: logs.append(f"{m.type}: {m.text[:300]}"))
    job = calibrate_on_page(served, page, measured_campaign(served, 12))
    assert page.is_visible("#c3-open")
    page.click("#c3-open")
    # the frame's document has no body for a moment while it loads
    page.wait_for_function(
        f"{FRAME} && {FRAME}.body && ['shown', 'failed'].includes({FRAME}.body.dataset.state)"
    )
    state = page.evaluate(f"{FRAME}.body.dataset.state")
    assert state == "shown", (page.evaluate(f"{FRAME}.getElementById('status').textContent"), logs)
    assert page.evaluate(f"{FRAME}.body.dataset.job") == str(job["id"])
    frame = page.locator("#c3-frame")
    seen = picture_until(page, "viewer-cell-3d", arrow_pixels, 150)
    assert seen > 150, f"no error arrows in the viewer's picture: {logs[-10:]}"
    # a pose chosen on the page: the viewer's time cursor on timeline "pose" (viewer control API)
    page.fill("#c3-pose", "5")
    page.click("#c3-go")
    page.wait_for_function(f"{FRAME}.body.dataset.pose === '5'")
    assert "pose 5" in page.text_content("#c3-state")
    page.wait_for_timeout(1000)  # a frame or two to draw it: for the picture only, not asserted
    frame.screenshot(path=str(ARTIFACTS / "viewer-pose-5.png"))
    assert not elsewhere, f"the page asked other hosts: {elsewhere}"


def test_viewer_code_is_served_without_the_token_and_only_its_files(served):
    """The viewer's code is public like the page; a name it does not ship is a 404, a recording
    still needs the token."""
    with httpx.Client(base_url=served.url, timeout=120) as anonymous:
        js = anonymous.get("/viewer/re_viewer.js")
        assert js.status_code == 200 and js.headers["content-type"].startswith("text/javascript")
        assert "WebHandle" in js.text
        wasm = anonymous.head("/viewer/re_viewer_bg.wasm")
        assert wasm.status_code == 200 and wasm.headers["content-type"] == "application/wasm"
        assert anonymous.get("/viewer/../token.sha256").status_code == 404
        assert anonymous.get("/viewer/index.html").status_code == 404
        assert anonymous.get("/api/jobs/1/recording").status_code == 401
