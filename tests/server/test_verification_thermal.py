"""A model with a temperature term (thermal growth) is verified with its joints solved as each
compensated pose is due, at the temperature the cell reported last: on a simulated cell that
grows with its warming air, AP after is then at the floor, while the joints a plan made before
the run gives (the term left out) show the growth. The joints are stored before each move, and a
run cut off midway resumes with the stored ones replayed and the rest solved at their time."""

from __future__ import annotations

import html as entities
import json

import numpy as np
import pytest

from robocal.server import store
from robocal.server.acquisition import compensated
from robocal.server.acquisition.acquire import AcquireOptions, acquire
from robocal.server.acquisition.compensated import KEY, TEMPS, total_poses, without
from robocal.server.calibration import workflow
from robocal.server.formats.cell_json import default_cell
from robocal.server.formats.model_json import ModelFile, write_model
from robocal.server.verify.certificate import render
from robocal.server.verify.run import (
    VerifyOptions,
    acquire_options,
    prepare,
    readings,
    run_poses,
    timed_model_text,
    verification_report,
    verify,
)
from robocal.solver.effects import Extension, Inputs
from robocal.solver.extended import fit_extended
from robocal.solver.fit_errors import calibration_figures
from robocal.solver.identify import Problem

SEED = 4
GROWTH_PPM_PER_C = 100.0  # the simulated arm's growth, and the model's coefficient
AIR_C = 20.0  # the simulated air when a campaign begins
OPTS = dict(seed=SEED, cycles=2, directions=2, effects=(f"thermal_drift={GROWTH_PPM_PER_C}",))


def fitted_model(db_path) -> ModelFile:
    """A calibration campaign on the warming cell, its geometry and growth fitted together."""
    cell = default_cell()
    s = acquire(db_path, cell, AcquireOptions(poses=60, seed=SEED, effects=OPTS["effects"]))
    names = tuple(sorted(cell.targets))
    meas = store.campaign_measurements(
        store.open_database(db_path), campaign_id=s.campaign, targets=names
    )
    cal = workflow.run_method(cell, meas, "ls-sum", screening=False)
    errors, _ = calibration_figures(cal, meas.q, meas.xyz)
    term = Extension("thermal_drift", variable="temp_c", t_ref=float(np.nanmean(meas.temp_c)))
    inputs = Inputs(meas.q, meas.time_s, meas.temp_c)
    prob = Problem(cal.layout, meas.q, meas.xyz)
    x, fitted, _ = fit_extended(prob, inputs, cal.x, errors.column >= 0, [term])
    lay = cal.layout
    targets = dict(zip(meas.target_names, lay.targets(x)))
    robot = lay.robot.with_params(x[: lay.n_geo])
    return ModelFile(robot, lay.base(x), targets, nominal=cell.robot, extensions=fitted)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """(report with the joints solved per pose, report of the plan without the term, folder)."""
    d = tmp_path_factory.mktemp("thermal")
    cell, model = default_cell(), fitted_model(d / "cell.db")
    growth = 1e6 * float(model.extensions[0].coef[0])
    print(f"\nfitted growth {growth:.2f} ppm/degC, simulated {GROWTH_PPM_PER_C:g}")
    assert abs(growth - GROWTH_PPM_PER_C) < 0.05 * GROWTH_PPM_PER_C
    write_model(d / "model.json", model)
    write_model(d / "planned.json", without(model, {"temp_c"}))  # as the old plan's joints
    per_pose = verify(d / "cell.db", cell, d / "model.json", VerifyOptions(**OPTS, name="a"))
    planned = verify(d / "cell.db", cell, d / "planned.json", VerifyOptions(**OPTS, name="b"))
    return per_pose, planned, d


def test_ap_after_is_at_the_floor_with_the_joints_solved_at_each_poses_temperature(runs):
    per_pose, planned, d = runs
    ap, ap_old = per_pose.after.AP_max_mm, planned.after.AP_max_mm
    rp = per_pose.after.RP_max_mm
    floor = max(np.sqrt(3.0) * p.AP_U_mm for p in per_pose.after.points)  # the tracker's MPE
    print(f"\nAP after {ap:.4f} mm (joints per pose), {ap_old:.4f} mm (planned joints); "
          f"RP after {rp:.4f} mm, the tracker's 3-D MPE {floor:.4f} mm")  # fmt: skip
    assert ap <= floor, ap
    assert ap_old >= 3.0 * ap and ap_old >= 2.0 * floor, (ap_old, ap)
    db = store.open_database(d / "cell.db")
    info, meas = readings(db, per_pose.campaign)
    temps = info.settings[TEMPS]
    rows = [i for i, p in enumerate(meas.pose_ids) if p.startswith("compensated-")]
    assert len(temps) == len(rows) and all(t is not None for t in temps)
    assert per_pose.uncertainty.compensation_note is None
    # each pose solved at the temperature of the reading before it, which the air warmed past
    read = np.nanmean(meas.temp_c, axis=1)
    assert np.allclose(temps, read[[rows[0] - 1] + rows[:-1]], atol=1e-9)
    assert max(temps) - AIR_C > 1.0, temps


def test_the_stored_joints_are_those_commanded_and_a_cut_off_run_resumes(runs, tmp_path):
    """The run stops after its second compensated pose is stored and measured (its sink fails);
    resumed, it replays the stored poses and solves the rest, to the same figures."""
    _, _, d = runs
    cell = default_cell()
    q_deg, labels, settings = prepare(cell, d / "model.json", VerifyOptions(**OPTS))
    assert KEY in settings and len(q_deg) == len(labels) == run_poses(q_deg, settings) // 2
    db_path = tmp_path / "cut.db"
    opts = acquire_options(cell, VerifyOptions(**OPTS, name="cut"), run_poses(q_deg, settings))
    stop_at = len(q_deg) + 2

    def on_event(e):
        if e.get("type") == "campaign.pose" and e["pose_index"] == stop_at - 1:
            raise RuntimeError("cut off")

    with pytest.raises(Exception, match="cut off"):
        acquire(db_path, cell, opts, poses_deg=q_deg, labels=labels, settings=settings,
                on_event=on_event)  # fmt: skip
    db = store.open_database(db_path)
    cid = store.list_campaigns(db)[0].id
    # the model's text is kept once in the campaign's settings: the plan block's, which the
    # resume solves from and the report takes each visit's U from
    text = (d / "model.json").read_text(encoding="utf-8")
    kept = json.dumps(store.get_campaign(db, campaign_id=cid).settings)
    assert kept.count(json.dumps(text)) == 1 and settings[KEY]["model"] == text
    stored = store.planned_poses(db, campaign_id=cid)
    assert (
        len(stored) == stop_at and [p.label for p in stored] == labels + settings[KEY]["labels"][:2]
    )
    # the campaign's view counts the poses still to be solved
    assert total_poses(store.get_campaign(db, campaign_id=cid).settings, stop_at) == 2 * len(q_deg)
    s = acquire(db_path, cell, opts, campaign_id=cid)
    assert s.state == "done" and s.poses == run_poses(q_deg, settings)
    stored_after = store.planned_poses(db, campaign_id=cid)
    assert [p.joints_deg for p in stored_after[:stop_at]] == [p.joints_deg for p in stored]
    report = verification_report(*readings(db, cid))
    # the report takes the model from there (the certificate's sentence on poses solved without
    # a temperature comes of it: the last test)
    assert timed_model_text(store.get_campaign(db, campaign_id=cid).settings) == text
    assert report.after.AP_max_mm <= max(np.sqrt(3.0) * p.AP_U_mm for p in report.after.points)
    assert len(store.get_campaign(db, campaign_id=cid).settings[TEMPS]) == len(q_deg)


def test_without_a_temperature_the_poses_leave_the_term_out_and_the_certificate_says_so(
    runs, tmp_path, monkeypatch
):
    """A cell that reports no temperature: each pose is solved without the term (as the old
    plan was), and the certificate says so in one sentence."""
    _, planned, d = runs
    monkeypatch.setattr(compensated, "latest_temp_c", lambda db, cid: None)
    blind = verify(tmp_path / "blind.db", default_cell(), d / "model.json", VerifyOptions(**OPTS))
    db = store.open_database(tmp_path / "blind.db")
    temps = store.get_campaign(db, campaign_id=blind.campaign).settings[TEMPS]
    assert len(temps) == 4 * len(blind.points) * 2 and all(t is None for t in temps)
    assert blind.after.AP_max_mm == pytest.approx(planned.after.AP_max_mm, rel=1e-6)
    html = entities.unescape(render(blind))
    said = (
        f"{len(temps)} of the compensated run's {len(temps)} poses were compensated without the "
        "model's temperature terms (thermal_drift on temp_c): the cell had reported no "
        "temperature before them."
    )
    assert html.count(said) == 1
    assert runs[0].uncertainty.compensation_note is None
