"""The accuracy certificate of a real verification run on the simulated cell, opened in headless
Chromium: the figures are there as text, the plots load, it prints to A4 PDF; screenshots in
tests/web/artifacts."""

from __future__ import annotations

import re

import pytest

from robocal.server.verify.certificate import write_certificate

from ..server.test_verification import calibrated_and_verified
from .conftest import ARTIFACTS, shot

SEED = 6


@pytest.fixture(scope="module")
def certificate(tmp_path_factory):
    """(certificate.html, the verification report) of a calibrated simulated cell."""
    d = tmp_path_factory.mktemp("certificate")
    report, _ = calibrated_and_verified(d, SEED)
    return write_certificate(report, d / "certificate.html"), report


def test_certificate_shows_the_run_and_its_figures(page, certificate):
    path, report = certificate
    page.goto(path.as_uri())
    body = page.inner_text("body")
    for text in (
        "Accuracy certificate",
        report["robot"],
        report["model"]["sha256"],
        "simulated laser tracker",
        report["date"],
        f"{report['before']['AP_max_mm']:.4f}",
        f"{report['after']['AP_max_mm']:.4f}",
        f"{report['after']['RP_max_mm']:.4f}",
    ):
        assert text in body, text
    verdict = page.inner_text("#verdict")
    assert re.search(r"\(\d+x better\)", verdict), verdict
    for p in report["after"]["points"]:
        assert page.get_by_role("cell", name=p["point"], exact=True).first.is_visible()
    # the plots are inline and decode: each image has a natural width; the diagnosed
    # (extended) model states its U too: at each point and as a map over the volume
    widths = page.eval_on_selector_all("img", "imgs => imgs.map(i => i.naturalWidth)")
    assert len(widths) == 3 and min(widths) > 300
    model_u = report["uncertainty"]["model"]["model_U_mm"]
    assert all(f"{u:.4f}" in page.inner_text("#uncertainty") for u in model_u)
    shot(page, "certificate")
    page.emulate_media(media="print")
    shot(page, "certificate-print")
    pdf = page.pdf(format="A4", print_background=True)
    assert pdf.startswith(b"%PDF")
    (ARTIFACTS / "certificate.pdf").write_bytes(pdf)


@pytest.fixture(scope="module")
def calibrated_certificate(tmp_path_factory):
    """(certificate.html, report) of a geometric calibration verified against a tolerance."""
    from ..server.test_verification_uncertainty import calibrated_and_verified as calibrated

    d = tmp_path_factory.mktemp("certificate-uncertainty")
    report, _ = calibrated(d, tolerance_mm=0.5)
    return write_certificate(report, d / "certificate.html"), report


def test_certificate_states_the_uncertainty_and_the_decision(page, calibrated_certificate):
    path, report = calibrated_certificate
    page.goto(path.as_uri())
    verdict = page.inner_text("#verdict")
    assert "PASS against the tolerance 0.5 mm" in verdict, verdict
    body = page.inner_text("body")
    assert "Uncertainty and decision" in body and "ISO 14253-1" in body
    for p, u in zip(report["after"]["points"], report["uncertainty"]["model"]["model_U_mm"]):
        assert f"{p['AP_mm']:.4f} ± {p['AP_U_mm']:.4f}" in body
        assert f"{u:.4f}" in body
    widths = page.eval_on_selector_all("img", "imgs => imgs.map(i => i.naturalWidth)")
    assert len(widths) == 3 and min(widths) > 300  # AP/RP, scatter, and the U map
    assert page.is_visible("img[alt='U over the working volume']")
    shot(page, "certificate-uncertainty")


@pytest.fixture(scope="module")
def repeatability_certificate(tmp_path_factory):
    """(certificate.html, report) of an arm whose data sheet states RP 0.04 mm: the simulated
    arm scatters so, and its RP is decided against it."""
    from ..server.test_verification_uncertainty import calibrated_and_verified as calibrated

    d = tmp_path_factory.mktemp("certificate-repeatability")
    report, _ = calibrated(d, tolerance_mm=0.5, repeatability_mm=0.04)
    return write_certificate(report, d / "certificate.html"), report


def test_certificate_states_each_rp_with_its_uncertainty(page, repeatability_certificate):
    path, report = repeatability_certificate
    page.goto(path.as_uri())
    table = page.locator("#uncertainty table")
    assert "RP after −U / +U (mm)" in table.inner_text()
    for p in report["after"]["points"]:
        row = table.locator("tr", has=page.get_by_role("cell", name=p["point"], exact=True))
        rp = f"{p['RP_mm']:.4f} −{p['RP_U_below_mm']:.4f} / +{p['RP_U_above_mm']:.4f}"
        assert row.get_by_role("cell", name=rp, exact=True).is_visible(), rp
    dec = report["uncertainty"]["rp_decision"]
    verdict = page.inner_text("#verdict")
    said = {"pass": "RP PASS", "fail": "RP FAIL", "not decided": "RP NOT DECIDED"}
    assert f"{said[dec['verdict']]} against the arm's stated repeatability 0.04 mm" in verdict
    body = page.inner_text("body")
    assert "U of an RP (95 %)" in body and "RP, worst point, 95 % interval (mm)" in body
    shot(page, "certificate-rp-uncertainty")
    # the verdict and the table close up, to look at
    for part in ("verdict", "uncertainty"):
        page.locator(f"#{part}").screenshot(
            path=str(ARTIFACTS / f"certificate-rp-closeup-{part}.png")
        )
