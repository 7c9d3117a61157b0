"""A check.csv posted from the page: what the check's answer says beside its verdict was nowhere
on the page: its `warnings` (a backlash model's approach directions taken from the rows' order of
a file without time_s or prev_q) and that the model itself is not fit to deploy (an "ok" check of
a nominal model says only that the arm still matches it)."""

from __future__ import annotations

from tests.real import import_real
from tests.server.api.conftest import done_job
from tests.server.api.test_backlash_order_api import ORDER, posted_untimed_check
from tests.server.api.test_health_deployable import _six_poses
from tests.web.conftest import sign_in


def test_a_posted_check_says_the_model_is_not_fit_to_deploy(served, page, tmp_path):
    cid = import_real(served.client, "irb120_wu")
    nominal = done_job(served.client, campaign_id=cid, method="nominal")
    reasons = nominal["validation"]["reasons"]
    assert nominal["validation"]["deployable"] is False and reasons, nominal
    sign_in(page, served)
    page.evaluate("(job) => openJob(job)", nominal["id"])
    page.wait_for_selector("#m-health:not([hidden])")
    assert page.is_hidden("#k-warnings")
    path = tmp_path / "check.csv"
    path.write_bytes(_six_poses())
    page.set_input_files("#k-file", str(path))
    page.click("#k-post")
    page.wait_for_selector("#k-warnings:not([hidden])")
    said = page.locator("#k-warnings li").all_text_contents()
    assert said == ["the model itself is not fit to deploy: " + "; ".join(reasons)], said


def test_a_checks_row_order_warning_is_shown(served, page, tmp_path):
    """The page checks calibrations' models, which have no backlash; a diagnosis's extended model
    checked over the API does, and the page shows that real answer's warning as it is."""
    r = posted_untimed_check(served, tmp_path)
    sign_in(page, served)
    page.evaluate("(c) => renderCheckWarnings(c)", r.json())
    said = page.locator("#k-warnings li").all_text_contents()
    assert any(ORDER in w and "joint_backlash(2)" in w for w in said), said
