"""The diagnosis view says how far off its training poses the model was tested and the joint
ranges it may be trusted within: the real IRB 120 campaign imported through the API and diagnosed
from the page; its report's `extrapolation` block (the folds, the farthest reach, the joint
ranges) must be on the page as the report has it, and an effect refused there (crafted into the
real report on its way to the page, as no real campaign here refuses one) listed with the folds it
made worse."""

from __future__ import annotations

import httpx

from tests.real import import_real
from tests.web.conftest import shot
from tests.web.test_ui_model import fmt, open_campaign

REFUSED = {
    "name": "joint_periodic",
    "label": "joint_periodic(2,k=1)",
    "joint": 2,
    "worse_on": ["q2 <= -0.1 deg (0.52 vs 0.48 mm)"],
}
# a refusal no fold made: its reason is the sentence shown
WILD = {
    "name": "joint_periodic",
    "label": "joint_periodic(1,k=1)",
    "joint": 1,
    "worse_on": [],
    "reason": "joint_periodic(1,k=1) turn joint 1 by 118 deg peak to peak across its limits",
}


def test_the_diagnosis_view_shows_the_folds_and_the_trusted_joint_ranges(served, page):
    with httpx.Client(
        base_url=served.url, timeout=120, headers={"Authorization": f"Bearer {served.token}"}
    ) as c:
        cid = import_real(c, "irb120_wu")
    seen = {}

    def augment(route):
        report = route.fetch().json()
        seen["report"] = report
        report = {
            **report,
            "extrapolation": {**report["extrapolation"], "refused": [REFUSED, WILD]},
        }
        route.fulfill(json=report)

    page.route("**/api/jobs/*/report", augment)
    open_campaign(served, page, cid)
    page.select_option("#j-method", "ls-sum")
    page.check("#j-auto")
    page.click("#calibrate")
    page.wait_for_selector("#trusted-table", timeout=180_000)

    x = seen["report"]["extrapolation"]
    assert x["folds"] and x["refused"] == [], x  # the real campaign's: folds, nothing refused
    assert page.is_visible("#d-extrapolation")
    far = max(x["folds"], key=lambda f: f["beyond_training_deg"])
    summary = page.text_content("#x-summary")
    assert summary.startswith(f"Tested off its training poses on {len(x['folds'])} folds"), summary
    assert f"up to {far['beyond_training_deg']:.1f} deg beyond them ({far['test']})" in summary
    rows = page.locator("#extrapolation-table tbody tr")
    assert rows.count() == len(x["folds"])
    for i, f in enumerate(x["folds"]):
        assert rows.nth(i).locator("td").all_text_contents() == [
            f["test"],
            str(f["test_poses"]),
            f"{f['beyond_training_deg']:.1f}",
            fmt(f["geometric_rmse_mm"]),
            fmt(f["final_rmse_mm"]),
        ]
    assert page.locator("#x-refused li").all_text_contents() == [
        "Refused joint_periodic(2,k=1): worse than geometry on q2 <= -0.1 deg (0.52 vs 0.48 mm)",
        f"Refused joint_periodic(1,k=1): {WILD['reason']}",
    ]
    assert page.text_content("#x-trusted").startswith("Trusted within the joint ranges measured")
    trusted = page.locator("#trusted-table tbody tr")
    assert trusted.count() == 6
    for j, (lo, hi) in enumerate(x["joint_range_deg"]):
        assert trusted.nth(j).locator("td").all_text_contents() == [
            f"q{j + 1}",
            f"{lo:.1f}",
            f"{hi:.1f}",
        ]
    page.locator("#d-extrapolation").scroll_into_view_if_needed()
    assert shot(page, "diagnosis_extrapolation").stat().st_size > 10_000
