"""The page's calibration form takes the application's tolerance, as `--tolerance-mm` and the API's
`tolerance_mm` do: the real IRB 120 calibrated (and diagnosed) from the page at 0.1 mm is not fit
to deploy, the reason naming the tolerance, on the page and in the API's jobs alike. Before, the
page had no way to give one but the cell's `tolerance_mm`."""

from __future__ import annotations

from tests.real import import_real
from tests.web.test_ui_model import open_campaign


def test_a_tolerance_given_on_the_page_decides_the_verdict(served, page):
    c = served.client
    open_campaign(served, page, import_real(c, "irb120_wu"))
    page.select_option("#j-method", "ls-sum")
    page.fill("#j-tolerance", "0.1")
    page.check("#j-auto")
    page.click("#calibrate")
    page.wait_for_selector("#m-unfit", timeout=180_000)
    page.wait_for_selector("#d-unfit", timeout=180_000)
    cal = c.get(f"/api/jobs/{page.evaluate('state.job')}").json()
    diag = c.get(f"/api/jobs/{page.evaluate('state.diag')}").json()
    for job, box in ((cal, "#m-unfit"), (diag, "#d-unfit")):
        assert job["tolerance_mm"] == 0.1, job
        v = job["validation"]
        assert v["deployable"] is False and v["tolerance_mm"] == 0.1, v
        shown = page.locator(f"{box} li").all_text_contents()
        assert shown == list(v["reasons"]), shown
        assert any("exceeds the tolerance 0.1 mm" in r for r in shown), shown
