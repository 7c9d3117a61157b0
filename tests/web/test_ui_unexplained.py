"""The page says what the diagnosis leaves unexplained, and shows the report's other optional keys.

A campaign whose arm hides a wrist coupling (outside the vocabulary, from a seed) is imported on the
page and diagnosed for real: the page must show the `unexplained` block with the coupling's
covariate first. The keys other parts of the diagnosis add (`outliers`; per effect `uncertainty`,
`holdout_gain_interval_mm`, `alternatives`) are added to that real report on its way to the page,
through the API path the page reads it from, and must be shown too.
"""

from __future__ import annotations

import json

from robocal.server.formats.campaign_csv import write_campaign
from tests.solver.test_unexplained import campaign, draw
from tests.web.conftest import shot

SEED = 1  # draws the wrist coupling
DOUBT = (
    "the cause is in doubt: on 5 resamples of the campaign (29 poses each), "
    "joint_compliance(2) named on 3 of 5; joint_periodic(2, harmonic 1) named on 2 of 5; "
    "measure more poses before acting on these effects"
)
AGREED = (
    "the resamples of the campaign (29 poses each) agree on another cause than the whole "
    "campaign's first choice, joint_scale(2) (on 1 of 5): joint_compliance(2) (named on 3 of 5); "
    "the model takes it instead"
)
HALF_WAY = (
    "the effects remove 8% of geometry's held-out RMS on this small campaign, within what the "
    "fit's own noise gives: the model is half way between geometry and the extended fit"
)


def extra_keys(report):
    """The optional keys of FORMATS.md section 5 that this branch does not compute, crafted."""
    report["outliers"] = [
        {"pose": "17", "target": "B", "residual_mm": 1.42},
        {"pose": "63", "target": "A", "residual_mm": 0.31},
    ]
    report["effects"] = [
        {
            "name": "joint_compliance",
            "joint": 2,
            "evidence": "Joint 2's residual rotation follows "
            "the gravity torque it carries; crafted for the page.",
            "holdout_rmse_before_mm": 0.3,
            "holdout_rmse_after_mm": 0.1,
            "parameters": {"deflection_rms_deg": 0.01},
            "uncertainty": {"deflection_rms_deg": 0.0004},
            "holdout_gain_interval_mm": [0.15, 0.22],
            "alternatives": [
                {"name": "joint_periodic", "joint": 2, "harmonic": 1, "holdout_rmse_mm": 0.104}
            ],
        }
    ] + report["effects"]
    report["stability"] = {
        "resamples": 5,
        "poses_each": 29,
        "named_nothing": 0,
        "effects": [
            {"effect": "joint_compliance(2)", "named_in": 3, "in_final": True},
            {"effect": "joint_periodic(2, harmonic 1)", "named_in": 2, "in_final": False},
        ],
        "doubt": DOUBT,
        "replaced": ["joint_scale(2)"],
        "agreed": AGREED,
        "half_way": HALF_WAY,
    }
    return report


def test_page_shows_the_unexplained_and_the_optional_keys(served, page, tmp_path):
    effect, name, channel = draw(SEED)
    _, _, meas = campaign(SEED, effect)
    csv = tmp_path / "coupled.csv"
    write_campaign(csv, meas)
    seen = {}

    def augment(route):
        report = route.fetch().json()
        seen["report"] = report
        route.fulfill(json=extra_keys(json.loads(json.dumps(report))))

    page.route("**/api/jobs/*/report", augment)

    page.goto(served.url + "/")
    page.fill("#token", served.token)
    page.click("#token-form button[type=submit]")
    page.wait_for_selector("#c-cell[data-loaded] option[value=default]", state="attached")
    page.click("#meas-import summary")
    page.set_input_files("#m-file", str(csv))
    page.click("#m-import-btn")
    page.wait_for_function("document.getElementById('p-status').textContent === 'done'")
    page.select_option("#j-method", "ls-sum")
    page.check("#j-auto")
    page.click("#calibrate")
    page.wait_for_selector("#diagnosis:not([hidden])")
    page.wait_for_selector("#unexplained-table", timeout=120_000)

    # The real block, as the diagnosis computed it: the coupling's covariate first.
    block = seen["report"]["unexplained"]
    assert page.text_content("#u-summary") == block["reading"]
    assert page.text_content("#u-summary").startswith("Unexplained: ")
    rows = page.locator("#unexplained-table tbody tr")
    assert rows.count() == len(block["covariates"])
    first = rows.first.locator("td").all_text_contents()
    assert first[0] == name and first[2] == channel, first
    assert float(first[1].split()[-1]) == round(block["covariates"][0]["strength"], 4)
    assert "coupling between joints 4 and 5" in first[3]
    assert page.evaluate("document.querySelector('#unexplained-table meter').value") > 0.5
    assert page.text_content("#u-per-pose").startswith("Per pose: ")

    # The crafted keys: the resamples' doubt, outliers by pose and target, and per effect its standard errors, gain
    # interval and the candidates it could not be told apart from.
    # the cause taken from the resamples, said first, then the half-way model, then the doubt
    said = f"{AGREED} {HALF_WAY} {DOUBT}"
    assert page.is_visible("#d-doubt") and page.text_content("#d-doubt") == said
    out = page.locator("#outliers-table tbody tr")
    assert out.count() == 2
    assert out.first.locator("td").all_text_contents() == ["17", "B", "1.4200"]
    assert "(2)" in page.text_content("#d-outliers h3")
    heads = page.locator("#effects-table thead th").all_text_contents()
    assert heads[6:] == [
        "standard error",
        "held-out gain interval / mm",
        "could not be told apart from",
    ], heads
    cells = page.locator("#effects-table tbody tr").first.locator("td").all_text_contents()
    assert cells[6] == "deflection rms ± 4.000e-4 deg", cells
    assert cells[7] == "0.1500 to 0.2200", cells
    assert cells[8] == "joint_periodic, joint 2, harmonic 1 (held-out RMS 0.1040 mm)", cells
    page.locator("#diagnosis").scroll_into_view_if_needed()
    assert shot(page, "diagnosis_unexplained").stat().st_size > 10_000
