"""A diagnosis opened from the History list is shown, beside its campaign's latest calibration:
its report sits under Results, which a fresh page (or one showing another campaign's model) has
hidden or of another campaign, so "open" showed nothing before."""

from __future__ import annotations

from tests.real import import_real
from tests.server.api.conftest import done_job
from tests.web.conftest import sign_in


def _done(c, body) -> int:
    return done_job(c, **body)["id"]


def test_a_diagnosis_opened_from_the_history_is_shown(served, page):
    c = served.client
    cid = import_real(c, "irb120_wu")
    cal = _done(c, {"campaign_id": cid, "method": "ls-sum"})
    diag = _done(c, {"campaign_id": cid, "kind": "diagnosis"})
    bare = import_real(c, "irb120_wu")  # a campaign diagnosed, never calibrated
    lone = _done(c, {"campaign_id": bare, "kind": "diagnosis"})
    sign_in(page, served)
    page.wait_for_selector(f"#h-jobs tr[data-job='{diag}'] button.open")
    page.click(f"#h-jobs tr[data-job='{diag}'] button.open")
    page.wait_for_selector("#d-links a", state="visible")
    assert page.evaluate("[state.job, state.diag]") == [cal, diag]
    assert page.is_visible("#m-validation")
    # one without a calibration says where it would be shown
    page.click(f"#h-jobs tr[data-job='{lone}'] button.open")
    page.wait_for_selector("#message:not([hidden])")
    said = page.text_content("#message-text")
    assert "calibrate that campaign to see it" in said and f"campaign {bare}" in said, said
