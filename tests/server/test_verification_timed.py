"""A model whose extension needs a pose's temperature (thermal growth) is verified: the plan's
joints leave that term out (a plan cannot know a visit's temperature), and the model's U at each
test point is taken at its visits' temperatures as the simulated cell read them, so that the
term's own uncertainty, which grows with the distance from its reference, is counted; where the
readings carry no temperature, the certificate says in one sentence why U is not given."""

from __future__ import annotations

import dataclasses
import html as entities
import json

import numpy as np
import pytest

from robocal.server import store
from robocal.server.acquisition.acquire import AcquireOptions, acquire
from robocal.server.calibration import workflow
from robocal.server.formats.cell_json import default_cell
from robocal.server.formats.model_json import extension_to_json, read_model, write_model
from robocal.server.formats.verification_doc import VerificationDoc
from robocal.server.verify.certificate import render
from robocal.server.verify.run import VerifyOptions, readings, verification_report, verify
from robocal.server.verify.uncertainty import at_visits
from robocal.solver.effects import Extension

SEED = 4
T_REF_C = 0.0  # the growth's reference, some 20 degC below the simulated cell's air
GROWTH_SE = 1e-6  # the growth coefficient's standard error, per degC (1 ppm/degC)


@pytest.fixture(scope="module")
def timed(tmp_path_factory):
    """(verification report, model file, database) of a geometric calibration given a thermal
    term (no growth, its coefficient's standard error GROWTH_SE) and verified on the cell."""
    d = tmp_path_factory.mktemp("timed")
    cell, db_path = default_cell(), d / "cell.db"
    s = acquire(db_path, cell, AcquireOptions(poses=40, seed=SEED, name="cal"))
    meas = store.campaign_measurements(
        store.open_database(db_path), campaign_id=s.campaign, targets=tuple(sorted(cell.targets))
    )
    write_model(
        d / "model.json", workflow.model_file(workflow.run_method(cell, meas, "ls-sum"), cell, meas)
    )
    doc = json.loads((d / "model.json").read_text())
    growth = Extension("thermal_drift", variable="temp_c", t_ref=T_REF_C, coef=np.zeros(1))
    doc["extensions"] = [extension_to_json(growth)]
    block = doc["uncertainty"]["position"]
    n = len(block["parameters"])
    cov = np.zeros((n + 1, n + 1))
    cov[:n, :n] = block["covariance"]
    cov[n, n] = GROWTH_SE**2
    block["parameters"].append("thermal_drift[0]")
    block["covariance"] = cov.tolist()
    (d / "model.json").write_text(json.dumps(doc))
    opts = VerifyOptions(seed=SEED, cycles=2, directions=2)
    report = verify(db_path, cell, d / "model.json", opts)
    return report, read_model(d / "model.json"), store.open_database(db_path)


def compensated_visits(db, report: VerificationDoc):
    """(joints (v, n) rad, temperatures (v,) degC, point (v,)) of the compensated test visits."""
    _, meas = readings(db, report.campaign)
    rows = [i for i, p in enumerate(meas.pose_ids) if p.startswith("compensated-") and
            not p.endswith("-approach")]  # fmt: skip
    point = [int(meas.pose_ids[i].split("-")[1][1:]) - 1 for i in rows]
    return meas.q[rows], meas.temp_c[rows, 0], np.array(point)


def test_u_is_taken_at_each_visits_temperature(timed):
    report, model, db = timed
    unc = report.uncertainty
    assert unc.model is not None and "thermal_drift on temp_c" in unc.model_note
    u = np.array(unc.model.model_U_mm)
    q, temp, point = compensated_visits(db, report)
    assert np.all(np.isfinite(temp)) and np.all(np.abs(temp - T_REF_C) > 10.0), temp
    cell, xyz = default_cell(), np.array([p.commanded_mm for p in report.after.points])
    at_ref = at_visits(model, cell, q, None, np.full(len(q), T_REF_C), point, xyz)["model"]
    u_ref = np.array(at_ref["model_U_mm"])
    # the growth's own standard uncertainty at a point: SE x (T - T_ref) x distance from the base
    r = np.linalg.norm(xyz - model.base[:3, 3], axis=1)
    growth = np.array([GROWTH_SE * np.abs(temp[point == j] - T_REF_C).max() for j in range(5)]) * r
    print(f"\nU at the visits {np.round(u, 4)}, at T_ref {np.round(u_ref, 4)}, growth's u "
          f"{np.round(growth, 4)} mm")  # fmt: skip
    assert np.all(u > 1.5 * u_ref), (u, u_ref)  # the term's uncertainty counted, not left out
    assert np.all(u >= 1.96 * growth * 0.99) and np.all(u <= np.hypot(u_ref, 2.8 * growth))
    assert np.all(np.array(unc.model.reading_U_mm) > u)
    html = entities.unescape(render(report))
    assert "Model U at each visit's time and temperature" in html
    # the term's joints were solved at each pose's temperature, not left out of a plan
    assert "compensated at the air temperature the tracker read as each pose was due" in html
    assert all(f"{x:.4f}" in html for x in u)


def test_without_the_visits_temperature_the_certificate_says_why(timed):
    report, _, db = timed
    info, meas = readings(db, report.campaign)
    blind = verification_report(info, dataclasses.replace(meas, temp_c=None))
    assert blind.uncertainty.model is None
    html = entities.unescape(render(blind))
    said = (
        "Model U is not given: the model's time or temperature terms (thermal_drift on temp_c) "
        "need each visit's time or temperature, which this run's readings do not carry."
    )
    assert said in html and "keeps no position uncertainty" not in html
    assert html.count(said) == 1
