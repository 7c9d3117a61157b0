"""The shown model in real headless Chromium: its validation (a 5-pose campaign's model is not fit
to deploy, with the reasons, and its exports are refused unless "export anyway" is ticked), its
identified parameters as the API gives them, how to open its recording, and the verdict's
warnings (the real QKM cell's SMR layout)."""

from __future__ import annotations

import csv
import io
import re

import httpx

from robocal.server.cli.tables import plus_minus
from tests.real import import_real
from tests.server.api.conftest import wait_for
from tests.web.conftest import said, shot


def fmt(v) -> str:
    """The page's number format (app.js fmt), in Python."""
    if v is None:
        return "-"
    a = abs(v)
    if a != 0 and (a >= 1e4 or a < 1e-3):
        return re.sub(r"e([+-])0*(\d)", r"e\1\2", f"{v:.3e}")  # JS writes 1.234e-5
    return f"{v:.4f}"


def measured_campaign(served, poses: int) -> int:
    """A done simulated campaign made through the API; its id."""
    with httpx.Client(
        base_url=served.url, timeout=60, headers={"Authorization": f"Bearer {served.token}"}
    ) as c:
        cid = c.post("/api/campaigns", json={"poses": poses, "pause_s": 0}).json()["id"]
        assert c.post(f"/api/campaigns/{cid}/start").status_code == 202
        status = wait_for(
            lambda: c.get(f"/api/campaigns/{cid}").json()["status"],
            lambda s: s in ("done", "failed", "aborted"),
        )
        assert status == "done", status
        return cid


def open_campaign(served, page, cid: int) -> None:
    """The page signed in with the campaign made its current one, ready to calibrate."""
    page.goto(served.url + "/")
    page.fill("#token", served.token)
    page.click("#token-form button[type=submit]")
    page.wait_for_selector("#c-cell[data-loaded] option[value=default]", state="attached")
    page.evaluate(
        "async (cid) => { useCampaign(await api('GET', `/campaigns/${cid}`)); refreshCampaign(); }",
        cid,
    )
    page.wait_for_function("!document.getElementById('calibrate').disabled")


def calibrate_on_page(served, page, cid: int) -> dict:
    """The campaign made the page's current one, calibrated with ls-sum from the page; the job
    (as the API gives it) once the page shows its results."""
    open_campaign(served, page, cid)
    page.select_option("#j-method", "ls-sum")
    page.click("#calibrate")
    page.wait_for_selector("#results:not([hidden])", timeout=180_000)
    page.wait_for_selector("#m-validation:not([hidden])")
    page.wait_for_selector("#m-parameters:not([hidden])")
    job = page.evaluate("state.job")
    return httpx.get(
        f"{served.url}/api/jobs/{job}", headers={"Authorization": f"Bearer {served.token}"}
    ).json()


def charts_loaded(page):
    """Wait until the results' two charts are drawn (for the screenshots)."""
    page.wait_for_function(
        "['boxplot', 'errors'].every((id) => { const i = document.getElementById(id);"
        " return i.complete && i.naturalWidth > 0; })",
        timeout=120_000,
    )


def test_five_poses_not_fit_to_deploy_and_exports_refused(served, page):
    job = calibrate_on_page(served, page, measured_campaign(served, 5))
    v = job["validation"]
    assert v["deployable"] is False and v["reasons"], v
    assert page.is_visible("#m-unfit")
    assert page.text_content("#m-unfit strong") == "Not fit to deploy"
    reasons = page.locator("#m-unfit li").all_text_contents()
    assert reasons == v["reasons"]
    assert any(r.startswith("too few poses: 5 poses") for r in reasons), reasons
    headline = page.text_content("#m-headline")
    assert headline.startswith(f"Held-out RMS {fmt(v['holdout_rms_mm'])} mm")
    assert f"fit RMS {fmt(v['fit_rms_mm'])} mm" in headline
    # The exports are marked, and the "export anyway" box is there, unticked.
    assert page.is_visible("#m-unfit-exports")
    assert not page.is_checked("#m-force")
    for b in ("t-joints", "t-rapid", "x-params", "x-urdf"):
        assert "unfit" in page.get_attribute(f"#{b}", "class"), b
    # Unticked: the service refuses (409, its reasons), and nothing is saved.
    page.click("#x-params")
    page.wait_for_selector("#message:not([hidden])")
    text, technical = said(page)
    assert "not deployable: too few poses" in text, text
    assert "409" in technical, technical
    assert page.text_content("#t-state") == ""
    # Ticked: force=true, and the parameter table comes back.
    page.check("#m-force")
    with page.expect_download(timeout=120_000) as got:
        page.click("#x-params")
    rows = list(csv.DictReader(io.StringIO(open(got.value.path()).read())))
    assert {r["parameter"] for r in rows} >= {"a1", "theta2", "base_x"}
    # saved under the robot's name, the job and what it is
    saved = page.text_content("#t-state")
    assert re.fullmatch(rf"saved [\w.-]+-job-{job['id']}-parameters\.csv", saved), saved
    assert got.value.suggested_filename == saved.removeprefix("saved "), (
        got.value.suggested_filename
    )
    charts_loaded(page)
    shot(page, "model_unfit")


def test_healthy_model_parameters_as_the_api_gives_them(served, page):
    job = calibrate_on_page(served, page, measured_campaign(served, 40))
    p = httpx.get(
        served.url + job["parameters_url"], headers={"Authorization": f"Bearer {served.token}"}
    ).json()
    assert p["validation"]["deployable"] is True, p["validation"]
    assert page.is_hidden("#m-unfit-exports") and page.locator("#m-unfit").count() == 0
    assert page.is_visible("#m-fit-ok")
    assert "unfit" not in (page.get_attribute("#x-params", "class") or "")
    v = p["validation"]
    assert page.text_content("#m-headline").startswith(
        f"Held-out RMS {fmt(v['holdout_rms_mm'])} mm · fit RMS {fmt(v['fit_rms_mm'])} mm "
        f"(nominal model {fmt(v['nominal_rms_mm'])} mm)"  # what the calibration improved on
    )
    # the floor with its source; the accuracy to expect, never a bare "fit to deploy"
    assert f"(from the {v['noise_floor_source']})" in page.text_content("#m-headline")
    assert page.text_content("#m-fit-ok") == f"Deployable: {v['summary']}."
    assert v["nominal_rms_mm"] > 10 * v["fit_rms_mm"]

    # One row per joint, each kind's change ± its standard error, as the API gives them.
    ident = p["identified"]
    joints = [r for r in ident["rows"] if r["group"] == "joint"]
    kinds = [k for k in ("theta", "d", "a", "alpha", "beta") if any(r["kind"] == k for r in joints)]
    heads = page.locator("#m-joints thead th").all_text_contents()
    unit = {r["kind"]: r["unit"] for r in joints}
    assert heads == ["joint", *[f"{k} / {unit[k]}" for k in kinds]]
    assert unit == {"theta": "deg", "d": "mm", "a": "mm", "alpha": "deg", "beta": "deg"}
    numbers = sorted({r["joint"] for r in joints})
    assert numbers == [1, 2, 3, 4, 5, 6]
    lines = page.locator("#m-joints tbody tr")
    assert lines.count() == len(numbers)
    for i, n in enumerate(numbers):
        cells = lines.nth(i).locator("td").all_text_contents()
        want = [str(n)]
        for k in kinds:
            r = next((r for r in joints if r["joint"] == n and r["kind"] == k), None)
            if r is None:
                want.append("-")
            elif r["status"] == "held fixed":
                want.append("fixed")
            else:
                # as the command line prints it (server/cli/tables.py)
                want.append(plus_minus(r["change"], r["standard_error"]))
        assert cells == want, (n, cells, want)
    # beta only where the convention has it (joint 2's parallel axes)
    assert "-" in lines.nth(0).locator("td").all_text_contents()
    # a held-fixed cell says why
    fixed = {f["parameter"]: f["why"] for f in ident["fixed"]}
    theta1 = page.locator("#m-joints tbody tr").first.locator("td.fixed").first
    assert theta1.get_attribute("title").split(" held fixed: ")[1] in fixed.values()
    assert page.locator("#m-fixed tbody tr").all_text_contents() == [
        f["parameter"] + f["why"] for f in ident["fixed"]
    ]
    assert page.locator("#m-base tbody tr td").count() == 7  # x, y, z, rz, ry, rx
    assert page.locator("#m-smrs tbody tr").count() == 3  # A, B, C
    assert page.text_content("#m-condition").startswith(
        f"Condition number {fmt(ident['condition_number'])};"
    )
    assert page.locator("#m-correlations tbody tr").count() == len(ident["correlations"]) > 0

    # The recording: its download, and how to open it.
    assert page.is_visible("#recording-link") and page.is_visible("#recording-open")
    assert page.text_content("#recording-command") == f"rerun job-{job['id']}.rrd"
    assert "pip install" in page.text_content("#recording-open")
    charts_loaded(page)
    shot(page, "model")

    # 390 px wide: the tables scroll inside their own boxes, which stay within the screen.
    page.set_viewport_size({"width": 390, "height": 844})
    boxes = page.evaluate(
        "[...document.querySelectorAll('#m-parameters .m-scroll')].map((b) => ({"
        " right: b.getBoundingClientRect().right, scroll: b.scrollWidth, client: b.clientWidth}))"
    )
    assert boxes and all(b["right"] <= 390 for b in boxes), boxes
    assert any(b["scroll"] > b["client"] for b in boxes), boxes  # the joints table scrolls
    shot(page, "model_390")


def test_warnings_are_listed_under_the_verdict(served, page):
    """The real QKM campaign in a cell of tolerance 0.5 mm: its cell's SMR layout is the found one
    turned half a turn about the flange axis, and its geometry ends 18x the noise floor held out
    (an effect it lacks); within the tolerance the model is deployable (its worst held-out reading
    beyond it), the page lists the three warnings."""
    with httpx.Client(
        base_url=served.url, timeout=120, headers={"Authorization": f"Bearer {served.token}"}
    ) as c:
        cid = import_real(c, "qkm_hl6", tolerance_mm=0.5)
    job = calibrate_on_page(served, page, cid)
    v = job["validation"]
    assert v["deployable"] is True and len(v["warnings"]) == 3, v
    assert page.is_visible("#m-fit-ok") and page.is_visible("#m-warnings")
    shown = page.locator("#m-warnings li").all_text_contents()
    assert shown == v["warnings"] and "the worst held-out reading misses by" in shown[0]
    assert "x the noise floor" in shown[1]
    assert "turned 180 deg about the flange axis (z)" in shown[2]


def test_shrunk_parameters_are_listed_with_their_share_and_why(served, page):
    """The real UR5's 80-pose campaign (one SMR near the flange axis): its wrist's d5 and a5,
    seen only together with theta5 and alpha5, are shrunk toward nominal; the page lists them
    with the share of their estimate from the data, and their cells say so."""
    with httpx.Client(
        base_url=served.url, timeout=120, headers={"Authorization": f"Bearer {served.token}"}
    ) as c:
        cid = import_real(c, "ur5_jacobi/small")
    job = calibrate_on_page(served, page, cid)
    p = httpx.get(
        served.url + job["parameters_url"], headers={"Authorization": f"Bearer {served.token}"}
    ).json()
    shrunk = p["identified"]["shrunk"]
    assert {s["parameter"] for s in shrunk} >= {"d5", "a5"}, shrunk
    assert page.locator("#m-shrunk tbody tr").all_text_contents() == [
        s["parameter"] + f"{int(100 * s['data_share'] + 0.5)}%" + s["why"]
        for s in shrunk  # Math.round
    ]
    cells = page.locator("#m-joints td.shrunk")
    titles = [cells.nth(i).get_attribute("title") for i in range(cells.count())]
    assert sorted(t.split(" ")[0] for t in titles) == sorted(s["parameter"] for s in shrunk)
    assert all("% from the data; " in t for t in titles), titles
