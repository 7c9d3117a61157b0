"""The page says the diagnosis's extended model's own verdict, as the API gives it: the real IRB 120
diagnosed for real with a cell tolerance below its held-out error is not fit to deploy (each
reason shown), and without a tolerance it is deployable with the accuracy to expect. Before, the
diagnosis block offered "Download extended model.json" with no verdict at all."""

from __future__ import annotations

from tests.real import import_real
from tests.web.conftest import shot
from tests.web.test_ui_model import open_campaign


def _diagnosed_on_page(served, page, cid: int) -> dict:
    """The campaign calibrated from the page with automatic extensions; the diagnosis job (as the
    API gives it) once the page shows its report."""
    open_campaign(served, page, cid)
    page.select_option("#j-method", "ls-sum")
    page.check("#j-auto")
    page.click("#calibrate")
    page.wait_for_function("state.diag !== null")
    page.wait_for_selector("#d-links a", timeout=180_000)
    job = served.client.get(f"/api/jobs/{page.evaluate('state.diag')}").json()
    assert job["state"] == "done", job
    return job


def test_the_extended_models_verdict_is_shown(served, page):
    c = served.client
    tight = _diagnosed_on_page(served, page, import_real(c, "irb120_wu", tolerance_mm=0.1))
    v = tight["validation"]
    assert v["deployable"] is False and v["reasons"], v
    assert page.is_visible("#d-unfit")
    assert page.text_content("#d-unfit strong") == "Extended model not fit to deploy"
    reasons = page.locator("#d-unfit li").all_text_contents()
    assert reasons == v["reasons"], reasons
    assert any("exceeds the tolerance 0.1 mm" in r for r in reasons), reasons
    shot(page, "diagnosis_verdict_unfit")

    free = _diagnosed_on_page(served, page, import_real(c, "irb120_wu"))
    assert free["validation"]["deployable"] is True, free["validation"]
    assert not page.is_visible("#d-unfit")
    said = page.text_content("#d-fit-ok")
    assert said == f"Extended model deployable: {free['validation']['summary']}.", said
