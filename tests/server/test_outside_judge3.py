"""Issue 21 as an outside judge drives it, third round: arms, SMR layouts and user mistakes the
other tests do not try, through the public commands only (real files, real processes)."""

import csv
import json

import numpy as np

from .test_cli import robocal
from .test_outside_cells import UR10E, _cell, _simulate

# a nest plate 300 mm across: SMRs far off the flange's axis
FAR_RING = {"A": [300.0, 0.0, 100.0], "B": [-150.0, 260.0, 100.0], "C": [-150.0, -260.0, 100.0]}


def _rewrite(src, dst, change):
    """dst: the rows of csv src, each changed in place by change(row)."""
    rows = list(csv.DictReader(open(src)))
    for row in rows:
        change(row)
    with open(dst, "w", newline="") as f:
        w = csv.DictWriter(f, list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def _radians(row):
    for i in range(1, 7):
        row[f"q{i}"] = repr(float(np.radians(float(row[f"q{i}"]))))


def test_a_check_in_radians_with_smrs_far_off_the_flange_is_refused_not_recalibrate(tmp_path):
    """A quick check of six poses whose joints were written in radians, on a UR10e-like arm with
    its SMRs 300 mm off the flange: `check` said 'recalibrate' (exit 3: 'no single cause ...
    explains it'), `evaluate` 'the data is not of the model's cell', `calibrate` 'the data
    moves none of the parameters'. The ring's own 300 mm had hidden how little the arm moves
    in radians read as degrees (spread ratio 2.40, inside the band of 2.5)."""
    _cell(tmp_path / "cell.json", UR10E, FAR_RING)
    _simulate(tmp_path, 36, 2, "all.csv")
    rows = list(csv.DictReader(open(tmp_path / "all.csv")))
    with open(tmp_path / "fit.csv", "w", newline="") as f:
        w = csv.DictWriter(f, list(rows[0]))
        w.writeheader()
        w.writerows(r for r in rows if int(r["pose"]) <= 30)
    with open(tmp_path / "deg.csv", "w", newline="") as f:
        w = csv.DictWriter(f, list(rows[0]))
        w.writeheader()
        w.writerows(r for r in rows if int(r["pose"]) > 30)
    _rewrite(tmp_path / "deg.csv", tmp_path / "rad.csv", _radians)
    r = robocal("calibrate", "fit.csv", "--cell", "cell.json", "--out", "model.json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    ok = robocal("check", "model.json", "deg.csv", "--db", "ok.db", "--out", "c.json", cwd=tmp_path)
    assert ok.returncode == 0, ok.stdout + ok.stderr
    for args in (
        ("check", "model.json", "rad.csv", "--db", "h.db", "--out", "c.json"),
        ("evaluate", "model.json", "rad.csv"),
        ("calibrate", "rad.csv", "--cell", "cell.json", "--out", "rad.json"),
    ):
        r = robocal(*args, cwd=tmp_path)
        line = r.stderr.strip()
        assert r.returncode not in (0, 3) and len(line.splitlines()) == 1, (args, r.stdout, line)
        assert line.startswith("robocal: error: rad.csv") and "look like radians" in line, line


def test_a_tracker_that_beats_its_specification_is_no_reason_to_refuse(tmp_path):
    """One SMR on the flange axis, the cell stating a real tracker's spec (MPE 15 um + 6 um/m)
    that the readings beat (simulated at the default 10 um + 2.5 um/m): calibrate and diagnose
    said 'NOT DEPLOYABLE: fit RMS 0.0114 mm is below 0.6 x the tracker's noise floor 0.0248 mm
    ...: the fit absorbed measurement noise' with the held-out error 0.0136 mm beside the fit,
    a verdict no further campaign could change. Now deployable, the floor's excess a warning."""
    _cell(tmp_path / "sim.json", UR10E, {"A": [0.0, 0.0, 30.0]})
    spec = {"mpe_um": 15, "mpe_um_per_m": 6}
    _cell(tmp_path / "cell.json", UR10E, {"A": [0.0, 0.0, 30.0]}, tracker=spec)
    _simulate(tmp_path, 60, 5, "m.csv", "sim.json")
    for command in ("calibrate", "diagnose"):
        r = robocal(command, "m.csv", "--cell", "cell.json", "--out", "out.json", cwd=tmp_path)
        assert r.returncode == 0, r.stderr
        model = "out.json" if command == "calibrate" else "model.json"
        if command == "diagnose":
            r = robocal(
                command, "m.csv", "--cell", "cell.json", "--out", "r.json", "--model-out",
                model, cwd=tmp_path,
            )  # fmt: skip
            assert r.returncode == 0, r.stderr
        v = json.loads((tmp_path / model).read_text())["validation"]
        assert v["noise_floor_source"].startswith("tracker specification (MPE 15 um + 6 um/m")
        assert v["fit_rms_mm"] < 0.6 * v["noise_floor_mm"], v  # the case
        assert v["holdout_rms_mm"] < v["noise_floor_mm"], v
        assert v["deployable"] and v["reasons"] == [], (command, v["reasons"])
        assert any("quieter than that floor" in w for w in v["warnings"]), v["warnings"]


def test_a_misspelt_tolerance_or_tracker_spec_in_the_cell_is_refused_not_ignored(tmp_path):
    """cell.json's `"tolerance": 0.01` (for tolerance_mm) was ignored without a word: the model,
    0.016 mm held out, came back 'deployable' as if no tolerance had been asked for, and the
    tracker's `"mpe": 15` left the default spec's floor. A joint's misspelt key was refused
    ('did you mean theta?') while the cell's own keys were not. A key that is no misspelling
    (notes, a name beside the robot) stays ignored, as the contract lets files grow."""
    _cell(tmp_path / "sim.json", UR10E, FAR_RING)
    _simulate(tmp_path, 30, 5, "m.csv", "sim.json")
    for extra, key, meant in (
        ({"tolerance": 0.01}, "tolerance", "tolerance_mm"),
        ({"Tolerance_mm": 0.01}, "Tolerance_mm", "tolerance_mm"),
        ({"tolerance_um": 10}, "tolerance_um", "tolerance_mm"),
        ({"payload": 5.0}, "payload", "payload_kg"),
        ({"tracker": {"mpe": 15, "mpe_um_per_m": 6}}, "tracker.mpe", "mpe_um"),
    ):
        _cell(tmp_path / "cell.json", UR10E, FAR_RING, **extra)
        r = robocal("calibrate", "m.csv", "--cell", "cell.json", "--out", "x.json", cwd=tmp_path)
        line = r.stderr.strip()
        assert r.returncode != 0 and not (tmp_path / "x.json").exists(), (extra, r.stdout)
        assert len(line.splitlines()) == 1 and "Traceback" not in line, line
        assert line.startswith("robocal: error: cell.json:1:"), line
        assert f"{key}: unknown key" in line and f"did you mean {meant!r}" in line, line
    fine = {"notes": "cell 4, east bay", "robot_name": "UR10 #2", "tolerance_mm": 0.05}
    _cell(tmp_path / "cell.json", UR10E, FAR_RING, **fine)
    r = robocal("calibrate", "m.csv", "--cell", "cell.json", "--out", "x.json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "x.json").read_text())["validation"]["tolerance_mm"] == 0.05


def test_a_cell_robot_that_no_geometry_fits_is_not_called_a_missing_effect(tmp_path):
    """A DH table with one twist's sign typed wrong (alpha4 -90 for +90): calibrate ended 599 mm
    RMS from its own readings (the nominal 363 mm) and said 'held-out error 604 mm is 3.72e+04x
    the noise floor: an effect the model lacks (a diagnosis's unexplained block says ...)', which
    sends the user to diagnose an arm whose description is wrong. No calibration of a right
    description errs so on its own readings: the reason names the cell's robot."""
    _cell(tmp_path / "sim.json", UR10E, FAR_RING)
    bad = json.loads(json.dumps(UR10E))
    bad["joints"][3]["alpha"] = -bad["joints"][3]["alpha"]
    _cell(tmp_path / "cell.json", bad, FAR_RING)
    _simulate(tmp_path, 30, 5, "m.csv", "sim.json")
    r = robocal("calibrate", "m.csv", "--cell", "cell.json", "--out", "x.json", cwd=tmp_path)
    assert "Traceback" not in r.stderr, r.stderr
    v = json.loads((tmp_path / "x.json").read_text())["validation"]
    assert not v["deployable"] and v["fit_rms_mm"] > 50, v
    assert not any("an effect the model lacks" in why for why in v["reasons"]), v["reasons"]
    assert any("the cell's robot is not the arm measured" in why for why in v["reasons"]), v
    # a UR10's a2 sign typed wrong: 'the data moves none of the parameters: measure poses that
    # move the SMRs' (every column below a 424 mm residual taken for noise), as if the poses
    # were at fault
    ur10 = json.loads(json.dumps(UR10E))
    for j, (a, d) in enumerate([(0, 127.3), (-612, 0), (-572.3, 0), (0, 163.941), (0, 115.7)]):
        ur10["joints"][j].update(a=a, d=d, limits=[-360, 360])
    ur10["joints"][5]["limits"] = [-360, 360]
    ur10["joints"][5]["d"] = 92.2
    _cell(tmp_path / "sim.json", ur10, FAR_RING)
    _simulate(tmp_path, 60, 5, "m.csv", "sim.json")
    ur10["joints"][1]["a"] = 612
    _cell(tmp_path / "cell.json", ur10, FAR_RING)
    r = robocal("calibrate", "m.csv", "--cell", "cell.json", "--out", "y.json", cwd=tmp_path)
    line = r.stderr.strip()
    assert r.returncode == 1 and len(line.splitlines()) == 1, r.stderr
    assert "the cell's robot is not the arm measured" in line and "measure poses" not in line


def test_a_poses_first_row_without_temp_c_takes_its_other_rows(tmp_path):
    """A meas.csv whose pose has temp_c blank on its first row (SMR A's reading) but given on
    B's and C's: `evaluate` used B's, `predict` and `check` refused ('pose 72 has no temp_c (a
    blank field), which the model's thermal_drift needs'). Each pose's value is now its first
    given one, in every reader (the column reader and the row reader, which prev_q selects)."""
    from robocal.server.formats.campaign_csv import read_poses
    from robocal.server.formats.cell_json import read_cell

    _cell(tmp_path / "cell.json", UR10E, FAR_RING)
    _simulate(tmp_path, 4, 3, "m.csv")
    robot = read_cell(tmp_path / "cell.json").robot
    whole = read_poses(tmp_path / "m.csv", robot)
    rows = list(csv.DictReader(open(tmp_path / "m.csv")))
    firsts = [i for i, r in enumerate(rows) if i == 0 or rows[i - 1]["pose"] != r["pose"]]
    rows[firsts[1]]["temp_c"] = rows[firsts[1]]["time_s"] = ""
    for prev in (False, True):
        if prev:  # prev_q columns: the row reader
            for r in rows:
                r.update({f"prev_q{i}": r[f"q{i}"] for i in range(1, 7)})
        with open(tmp_path / "b.csv", "w", newline="") as f:
            w = csv.DictWriter(f, list(rows[0]))
            w.writeheader()
            w.writerows(rows)
        ids, _, time_s, temp_c, _ = read_poses(tmp_path / "b.csv", robot)
        assert ids == whole[0]
        assert np.all(np.isfinite(temp_c)) and np.all(np.isfinite(time_s)), (prev, temp_c)
        other = float(rows[firsts[1] + 1]["temp_c"])
        assert temp_c[1] == other and temp_c[0] == whole[3][0], (prev, temp_c)


def test_a_campaign_too_small_to_identify_is_named_in_its_refusal(tmp_path):
    """'robocal: error: 8 poses give 24 equations for 25 parameters: measure at least 9 poses'
    named no file (calibrate, diagnose, compare alike): the campaign's path now leads it."""
    _cell(tmp_path / "cell.json", UR10E, {"A": [0.0, 0.0, 30.0]})
    _simulate(tmp_path, 8, 3, "tiny.csv")
    for command in ("calibrate", "diagnose", "compare"):
        args = ("--out", "x.json") if command != "compare" else ()
        r = robocal(command, "tiny.csv", "--cell", "cell.json", *args, cwd=tmp_path)
        line = r.stderr.strip()
        assert r.returncode == 1 and len(line.splitlines()) == 1, (command, r.stderr)
        assert line.startswith("robocal: error: tiny.csv: 8 poses give 24 equations"), line


def test_an_effects_figure_file_name_is_a_plain_word(tmp_path):
    """A compliance with its link's masses fitted wrote 'report_1_joint_compliance_2_ its
    link's masses fitted.png' (a space and an apostrophe in a file name a script or a URL then
    has to quote): letters, digits and underscores only now, the report naming that file."""
    from robocal.server.figures.diagnosis import write_figures
    from robocal.solver.diagnosis_report import EffectFigure

    y = np.arange(3.0)
    label = "joint_compliance(2, its link's masses fitted)"
    figure = EffectFigure("joint_compliance", label, y, y, y, y, "x", "y")
    periodic = EffectFigure("joint_periodic", "joint_periodic(4,k=2)", y, y, y, y, "x", "y")
    paths = write_figures([figure, periodic], tmp_path / "report.json")
    assert [p.name for p in paths] == [
        "report_1_joint_compliance_2_its_link_s_masses_fitted.png",
        "report_2_joint_periodic_4_k2.png",  # as before
    ]
    assert all(p.exists() for p in paths)


def test_acquire_names_the_cell_of_a_robot_no_controller_drives(tmp_path):
    """`acquire --cell iiwa.json` (seven joints) said 'robocal: error: robot.joints: 7 joints;
    the controller protocol drives at most 6 ...', naming no file."""
    from .test_outside_cells import PANDA

    _cell(tmp_path / "iiwa.json", PANDA, {"A": [50.0, 10.0, 30.0]})
    r = robocal("acquire", "--db", "a.db", "--poses", 5, "--cell", "iiwa.json", cwd=tmp_path)
    line = r.stderr.strip()
    assert r.returncode == 1 and len(line.splitlines()) == 1, r.stderr
    assert line.startswith("robocal: error: iiwa.json: robot.joints: 7 joints"), line
    assert not (tmp_path / "a.db").exists()
