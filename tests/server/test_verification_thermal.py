"""A model with a temperature term (thermal growth) is verified with its joints solved as each
compensated pose is due, at the air temperature the tracker reads then: on a simulated cell that
grows with its warming air, AP after is then at the floor, while the joints a plan made before
the run gives (the term left out) show the growth. The joints are stored before each move, and a
run cut off midway resumes with the stored ones replayed and the rest solved at their time, at
the air of then however late the resume; without a weather station, at the last reading's
temperature, and the certificate says how old it was."""

from __future__ import annotations

import html as entities
import json

import numpy as np
import pytest

from robocal.drivers.tracker.protocol import ErrorCode, TrackerError
from robocal.drivers.tracker.sim import SimulatedTracker
from robocal.server import store
from robocal.server.acquisition import acquire as acquisition
from robocal.server.acquisition.acquire import AcquireOptions, acquire
from robocal.server.acquisition.compensated import AGES, KEY, TEMPS, total_poses, without
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
    # each pose solved at the tracker's weather station read as it was due (age 0): within its
    # noise of the reading before it, not that reading's; the air warmed past 1 degC
    assert info.settings[AGES] == [0.0] * len(temps)
    before = np.nanmean(meas.temp_c, axis=1)[[rows[0] - 1] + rows[:-1]]
    assert np.abs(np.subtract(temps, before)).max() < 0.1 and not np.isin(temps, before).any()
    assert max(temps) - AIR_C > 1.0, temps


def cut_off(d, tmp_path):
    """A verification run of the thermal model stopped after its second compensated pose is
    stored and measured (its sink fails): (cell, options, planned joints, labels, settings,
    database path, campaign, poses stored)."""
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
    cid = store.list_campaigns(store.open_database(db_path))[0].id
    return cell, opts, q_deg, labels, settings, db_path, cid, stop_at


def test_the_stored_joints_are_those_commanded_and_a_cut_off_run_resumes(runs, tmp_path):
    """The run stops after its second compensated pose is stored and measured (its sink fails);
    resumed, it replays the stored poses and solves the rest, to the same figures."""
    d = runs[2]
    cell, opts, q_deg, labels, settings, db_path, cid, stop_at = cut_off(d, tmp_path)
    db = store.open_database(db_path)
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
    # the solve hears of no temperature; the readings keep theirs, so that the run draws the
    # tracker's noise as the planned one did
    monkeypatch.setattr(acquisition, "air_temperature", lambda tracker: None)
    monkeypatch.setattr(store, "latest_air", lambda db, campaign_id: None)
    blind = verify(tmp_path / "blind.db", default_cell(), d / "model.json", VerifyOptions(**OPTS))
    db = store.open_database(tmp_path / "blind.db")
    kept = store.get_campaign(db, campaign_id=blind.campaign).settings
    temps = kept[TEMPS]
    assert len(temps) == 4 * len(blind.points) * 2 and all(t is None for t in temps)
    assert kept[AGES] == [None] * len(temps)
    assert blind.after.AP_max_mm == pytest.approx(planned.after.AP_max_mm, rel=1e-6)
    html = entities.unescape(render(blind))
    said = (
        f"{len(temps)} of the compensated run's {len(temps)} poses were compensated without the "
        "model's temperature terms (thermal_drift on temp_c): the cell had reported no "
        "temperature before them."
    )
    assert html.count(said) == 1
    assert runs[0].uncertainty.compensation_note is None


def no_weather_station(self):
    raise TrackerError(ErrorCode.BAD_REQUEST, "no weather station")


HOURS = 3.0  # a run resumed this long after it stopped


def late_resume(runs, tmp_path, monkeypatch, weather: bool):
    """The cut-off run resumed HOURS later (the weather station answering or not): the air then
    (the readings of the first pose solved after it), the last stored reading's temperature and
    the resumed campaign's settings and report."""
    cell, opts, q_deg, _, settings, db_path, cid, stop_at = cut_off(runs[2], tmp_path)
    db = store.open_database(db_path)
    last = store.latest_air(db, campaign_id=cid)
    assert last is not None
    monkeypatch.setattr(acquisition, "RESUME_S", HOURS * 3600.0)
    if not weather:
        monkeypatch.setattr(SimulatedTracker, "weather", no_weather_station)
    said: list[str] = []
    s = acquire(db_path, cell, opts, campaign_id=cid, log=said.append)
    assert s.state == "done" and s.poses == run_poses(q_deg, settings)
    kept = store.get_campaign(db, campaign_id=cid).settings
    info, meas = readings(db, cid)
    first = meas.pose_ids.index(settings[KEY]["labels"][2])  # the first pose solved after it
    air = np.nanmean(meas.temp_c[first]) if weather else None
    return air, last, kept, verification_report(info, meas), said


def test_a_run_resumed_hours_later_solves_its_next_pose_at_the_air_of_then(
    runs, tmp_path, monkeypatch
):
    """Not at the last stored reading's temperature, hours old: the tracker's weather station is
    read as the pose is due."""
    air, last, kept, report, said = late_resume(runs, tmp_path, monkeypatch, weather=True)
    temps, ages = kept[TEMPS], kept[AGES]
    print(f"\nresumed {HOURS:g} h later: solved at {temps[2]:.3f} degC, the air "
          f"{air:.3f} degC, the last reading before the stop {last.temp_c:.3f} degC")  # fmt: skip
    assert abs(air - last.temp_c) > 0.5  # the air moved while the run was stopped
    assert abs(temps[2] - air) < 0.1 and ages[2] == 0.0
    assert all(a == 0.0 for a in ages)
    assert report.uncertainty.compensation_note is None and not any("min old" in x for x in said)
    assert report.after.AP_max_mm <= max(np.sqrt(3.0) * p.AP_U_mm for p in report.after.points)


def test_a_late_resume_without_a_weather_station_says_how_old_its_temperature_was(
    runs, tmp_path, monkeypatch
):
    """The weather station gives nothing after the resume: each pose left is solved at the last
    stored reading's temperature, and the log and the certificate say how old it was."""
    _, last, kept, report, said = late_resume(runs, tmp_path, monkeypatch, weather=False)
    temps, ages = kept[TEMPS], kept[AGES]
    assert ages[:2] == [0.0, 0.0] and temps[2:] == [last.temp_c] * (len(temps) - 2)
    assert HOURS * 3600.0 <= ages[2] < HOURS * 3600.0 + 60.0 and ages[-1] > ages[2]
    oldest = max(ages) / 60.0
    assert any(f"{ages[2] / 60.0:.1f} min old" in x for x in said), said
    sentence = (
        f"{len(temps) - 2} of the compensated run's {len(temps)} poses were compensated at the "
        "air temperature of an earlier reading, the tracker's weather station giving none as "
        f"they were due: up to {oldest:.1f} min old."
    )
    print(f"\n{report.uncertainty.compensation_note}")
    assert report.uncertainty.compensation_note == sentence
    assert entities.unescape(render(report)).count(sentence) == 1
