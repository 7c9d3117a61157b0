"""Issue 21 as an outside judge drives it: hand-written cells of arms the tests elsewhere do not
use (a 0.5 m six-axis arm, a UR10e-like offset wrist), through the public commands only, with
the mistakes a new user makes in cell.json."""

import csv
import json

import numpy as np
import pytest

from .test_cli import robocal


def _robot(name, convention, rows):
    return {
        "name": name,
        "convention": convention,
        "joints": [
            {"a": a, "d": d, "theta": t, "alpha": al, "limits": list(lim)}
            for a, d, t, al, lim in rows
        ],
    }


# a 0.5 m six-axis arm (Staubli TX2-40-like proportions), standard DH, joint offsets on 2 and 3
SMALL = _robot(
    "small-6",
    "dh",
    [
        (0, 320, 0, -90, (-180, 180)),
        (225, 0, -90, 0, (-125, 125)),
        (0, 35, 90, 90, (-138, 138)),
        (0, 225, 0, -90, (-270, 270)),
        (0, 0, 0, 90, (-120, 133)),
        (0, 65, 0, 0, (-270, 270)),
    ],
)
# UR10e's DH table: the offset wrist
UR10E = _robot(
    "ur10e-like",
    "dh",
    [
        (0, 180.7, 0, 90, (-360, 360)),
        (-612.7, 0, 0, 0, (-180, 0)),
        (-571.55, 0, 0, 0, (-160, 160)),
        (0, 174.15, 0, 90, (-360, 360)),
        (0, 119.85, 0, -90, (-360, 360)),
        (0, 116.55, 0, 0, (-360, 360)),
    ],
)
RING = {"A": [70.0, 0.0, 45.0], "B": [-35.0, 60.0, 45.0], "C": [-35.0, -60.0, 45.0]}


def _cell(path, robot, targets, **extra):
    path.write_text(json.dumps({"robot": robot, "targets": targets, **extra}))
    return path.name


def _simulate(tmp_path, poses: int, seed: int, out: str, cell: str = "cell.json") -> None:
    r = robocal(
        "simulate", "--cell", cell, "--poses", poses, "--seed", seed, "--out", out, cwd=tmp_path
    )
    assert r.returncode == 0, r.stderr


def test_a_tracker_spec_of_zero_error_is_refused_in_one_line(tmp_path):
    """MPE 0 um + 0 um/m made the noise floor 0 mm: calibrate called a one-SMR model deployable
    at any error and diagnose ended in a traceback (KeyError 'chance_strength')."""
    spec = {"mpe_um": 0, "mpe_um_per_m": 0}
    cell = _cell(tmp_path / "cell.json", UR10E, {"A": [0.0, 0.0, 30.0]}, tracker=spec)
    ok = _cell(tmp_path / "ok.json", UR10E, {"A": [0.0, 0.0, 30.0]})
    _simulate(tmp_path, 30, 3, "m.csv", ok)
    for command in ("calibrate", "diagnose"):
        r = robocal(command, "m.csv", "--cell", cell, "--out", "out.json", cwd=tmp_path)
        assert r.returncode != 0, (command, r.stdout)
        line = r.stderr.strip()
        assert "Traceback" not in r.stderr and len(line.splitlines()) == 1, r.stderr
        assert "cell.json" in line and "mpe_um" in line, line


def test_smr_positions_in_metres_are_refused_naming_the_unit(tmp_path):
    """A cell whose SMR ring was written in metres (0.07 for 70 mm) calibrated to 'not
    deployable: an effect the model lacks' (0.14 mm held out, 9x the floor of a clean campaign):
    three SMRs 0.1 mm apart cannot be, since two balls' centres lie a diameter apart."""
    good = _cell(tmp_path / "good.json", UR10E, RING)
    metres = {k: [v / 1000 for v in xyz] for k, xyz in RING.items()}
    bad = _cell(tmp_path / "cell.json", UR10E, metres)
    _simulate(tmp_path, 30, 3, "m.csv", good)
    r = robocal("calibrate", "m.csv", "--cell", bad, "--out", "model.json", cwd=tmp_path)
    assert r.returncode != 0 and not (tmp_path / "model.json").exists(), r.stdout
    line = r.stderr.strip()
    assert len(line.splitlines()) == 1 and "Traceback" not in line, r.stderr
    assert "cell.json" in line and "targets" in line and "metres" in line, line


def _fitted(tmp_path, poses: int, seed: int, fit: int) -> list[dict]:
    """cell.json's campaign of `poses` poses (all.csv, its rows returned), its first `fit` poses
    (fit.csv) calibrated to model.json, the rest in new.csv."""
    _simulate(tmp_path, poses, seed, "all.csv")
    rows = list(csv.DictReader(open(tmp_path / "all.csv")))
    for name, keep in (("fit.csv", lambda p: p <= fit), ("new.csv", lambda p: p > fit)):
        with open(tmp_path / name, "w", newline="") as f:
            w = csv.DictWriter(f, list(rows[0]))
            w.writeheader()
            w.writerows(row for row in rows if keep(int(row["pose"])))
    r = robocal("calibrate", "fit.csv", "--cell", "cell.json", "--out", "model.json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    return rows


def _confdata_targets(tmp_path, cell_path, meas, out):
    """targets.csv of a campaign's readings with each pose's confdata instead of its joints."""
    from robocal.server.formats.cell_doc import CellDoc
    from robocal.solver.configuration import confdata

    robot = CellDoc.model_validate(json.loads(cell_path.read_text())).robot_model
    rows = list(csv.DictReader(open(tmp_path / meas)))
    with open(tmp_path / out, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["pose", "target", "x", "y", "z", "cf1", "cf4", "cf6", "cfx"])
        for r in rows:
            q = np.radians([float(r[f"q{i}"]) for i in range(1, 7)])
            cf = np.asarray(confdata(robot, q)).reshape(-1)
            w.writerow([r["pose"], r["target"], r["x"], r["y"], r["z"], *map(int, cf)])
    return {r["pose"]: [float(r[f"q{i}"]) for i in range(1, 7)] for r in rows}


SMALL_RING = {"A": [40.0, 0.0, 20.0], "B": [-20.0, 35.0, 20.0], "C": [-20.0, -35.0, 20.0]}


@pytest.mark.parametrize(
    ("robot", "ring", "poses", "seed"),
    [(SMALL, SMALL_RING, 72, 11), (UR10E, RING, 260, 11), (UR10E, RING, 260, 18)],
)
def test_confdata_reaches_a_pose_measured_next_to_the_stretched_elbow(
    tmp_path, robot, ring, poses, seed
):
    """The small arm's campaign (seed 11) has a pose measured with joint 3 at -0.16 deg, the
    elbow 0.16 deg from stretched: in its confdata (cfx 2, behind the lower arm) compensate said
    'no solution in its configuration' (every start converged to the mirror elbow, 0.3 deg away
    in cfx 0), though the arm stood there; the UR10e's pose 111 (joint 3 at -0.21 deg) was
    'unreachable ... no closer than 99.232 mm' (the starts that stayed in its configuration
    stopped in local minima), and again once the calibrated model's elbow stretched at +0.09 deg
    (its best joints in the configuration then lie on the edge, q3 = 0, where the bound the
    search held joint 3 to ended, and the side's test there reads either way); the UR10e's
    seed-18 pose 223 (joint 3 at +0.93 deg, cfx 0) came back in cfx 2 (the final solve, unbound
    by the edge, walked across it). Asked for by confdata alone, every pose comes back in its
    configuration, near the joints it was measured at, at the model's error."""
    cell = tmp_path / "cell.json"
    _cell(cell, robot, ring)
    _fitted(tmp_path, poses, seed, 60)
    measured = _confdata_targets(tmp_path, cell, "new.csv", "targets.csv")
    assert any(abs(q[2]) < 0.5 for q in measured.values()), "the pose next to the stretched elbow"
    r = robocal("compensate", "model.json", "targets.csv", "--out", "joints.csv", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    got = list(csv.DictReader(open(tmp_path / "joints.csv")))
    assert len(got) == len(measured)
    from robocal.server.formats.cell_doc import CellDoc
    from robocal.solver.configuration import confdata

    nominal = CellDoc.model_validate(json.loads(cell.read_text())).robot_model
    for row in got:
        q = [float(row[f"q{i}"]) for i in range(1, 7)]
        moved = np.max(np.abs(np.subtract(q, measured[row["pose"]])))
        assert moved < 1.0, (row["pose"], q, measured[row["pose"]])
        asked = confdata(nominal, np.radians([measured[row["pose"]]]))
        assert np.array_equal(confdata(nominal, np.radians([q])), asked), (row["pose"], q)
        assert float(row["predicted_error_mm"]) < 0.05, row


@pytest.mark.parametrize("floor", [0.0])
def test_the_unexplained_line_reads_a_floor_of_zero(floor):
    """A floor of exactly 0 (noise-free readings repeated to the last digit) is a floor, not an
    unknown one: the summary line gave a KeyError (it asked for the chance level)."""
    from robocal.solver.unexplained import summary

    block = {
        "holdout_rmse_mm": 0.12,
        "noise_floor_ratio": None,
        "share_of_baseline_mse": 0.5,
        "covariates": [],
    }
    line = summary(block, floor)
    assert line.startswith("Unexplained: 0.120 mm held out") and "0 mm" in line, line


# Franka Panda's modified DH (seven joints): joint 4's limits [-176, -4] deg exclude every angle
# in radians
PANDA = _robot(
    "panda-like",
    "mdh",
    [
        (0, 333, 0, 0, (-166, 166)),
        (0, 0, 0, -90, (-101, 101)),
        (0, 316, 0, 90, (-166, 166)),
        (82.5, 0, 0, 90, (-176, -4)),
        (-82.5, 384, 0, -90, (-166, 166)),
        (0, 0, 0, 90, (-1, 215)),
        (88, 107, 0, 90, (-166, 166)),
    ],
)


def test_joints_in_radians_outside_a_limit_are_named_as_radians(tmp_path):
    """A 7-axis campaign with its joints in radians stopped at joint 4's limits ('-2.0 deg is
    outside the limits [-176, -4]') before the units check could say radians: the line now
    says what the row's joints look like."""
    _cell(tmp_path / "cell.json", PANDA, {"A": [50.0, 10.0, 30.0], "B": [-30.0, 45.0, 25.0]})
    _simulate(tmp_path, 20, 4, "deg.csv")
    rows = list(csv.DictReader(open(tmp_path / "deg.csv")))
    for row in rows:
        for i in range(1, 8):
            row[f"q{i}"] = repr(float(np.radians(float(row[f"q{i}"]))))
    with open(tmp_path / "rad.csv", "w", newline="") as f:
        w = csv.DictWriter(f, list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    for command in ("calibrate", "diagnose", "evaluate"):
        args = (
            ("deg.json", "rad.csv") if command == "evaluate" else ("rad.csv", "--cell", "cell.json")
        )
        if command == "evaluate":
            fit = robocal(
                "calibrate", "deg.csv", "--cell", "cell.json", "--out", "deg.json", cwd=tmp_path
            )
            assert fit.returncode == 0, fit.stderr
        r = robocal(command, *args, cwd=tmp_path)
        line = r.stderr.strip()
        assert r.returncode != 0 and len(line.splitlines()) == 1, (command, r.stderr)
        assert "rad.csv:2:" in line and "radians" in line, line


def test_a_joint_of_one_degree_range_is_simulated(tmp_path):
    """A joint locked to +-0.5 deg (narrower than the 2 deg margin the pose draw keeps from the
    limits) ended `simulate` in 'robocal: error: high - low < 0', numpy's words naming nothing."""
    robot = json.loads(json.dumps(UR10E))
    robot["joints"][5]["limits"] = [-0.5, 0.5]
    _cell(tmp_path / "cell.json", robot, RING)
    _simulate(tmp_path, 20, 5, "m.csv")
    q6 = [float(row["q6"]) for row in csv.DictReader(open(tmp_path / "m.csv"))]
    assert max(abs(v) for v in q6) <= 0.5
    r = robocal("calibrate", "m.csv", "--cell", "cell.json", "--out", "model.json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr


def test_joint_limits_in_radians_are_refused_at_the_cell(tmp_path):
    """Limits written in radians ([-6.28, 6.28]) blamed the campaign ('meas.csv:2:2: column q1:
    -110 deg is outside the limits [-6.28319, 6.28319] deg') and made `simulate` fail with
    numpy's 'high - low < 0': the cell is named, with the units."""
    robot = json.loads(json.dumps(UR10E))
    for j in robot["joints"]:
        j["limits"] = [float(np.radians(v)) for v in j["limits"]]
    _cell(tmp_path / "cell.json", robot, RING)
    for args in (("simulate", "--out", "m.csv"), ("calibrate", "m.csv", "--out", "model.json")):
        if args[0] == "calibrate":
            _cell(tmp_path / "good.json", UR10E, RING)
            _simulate(tmp_path, 20, 1, "m.csv", "good.json")
        r = robocal(*args, "--cell", "cell.json", cwd=tmp_path)
        line = r.stderr.strip()
        assert r.returncode != 0 and len(line.splitlines()) == 1, r.stderr
        assert "cell.json" in line and "limits" in line and "radians" in line, line


def test_three_smrs_on_one_line_warn_that_orientation_comes_from_the_start(tmp_path):
    """Three SMRs on one line leave the roll about it free, as one SMR leaves all of it: the
    compensated joints came back up to 0.9 deg from the measured ones (from a guess 2 deg off)
    with no warning, where one SMR a pose gets one."""
    _cell(
        tmp_path / "cell.json", UR10E, {"A": [100.0, 0, 30], "B": [0, 0, 30], "C": [-100.0, 0, 30]}
    )
    rows = _fitted(tmp_path, 46, 12, 40)
    qs = [f"q{i}" for i in range(1, 7)]
    with open(tmp_path / "targets.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["pose", "target", "x", "y", "z", *qs])
        for row in rows:
            if int(row["pose"]) > 40:
                w.writerow(
                    [row[c] for c in ("pose", "target", "x", "y", "z")]
                    + [float(row[q]) + 2 for q in qs]
                )
    r = robocal("compensate", "model.json", "targets.csv", "--out", "joints.csv", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "6 poses (first '41')" in r.stderr and "one line" in r.stderr, r.stderr
    assert "orientation" in r.stderr, r.stderr


@pytest.mark.parametrize("command", ["calibrate", "diagnose"])
def test_a_base_guess_the_data_contradicts_does_not_flip_the_arm(tmp_path, command):
    """A cell's base guess in metres (the translation 1000x short, the rotation the identity
    where the tracker sees the base turned) started the fit so far off that it ended in a
    mirrored arm: a2 +1225 mm, alpha2 -180 deg from nominal, 'not deployable'. The data's own
    registration of the nominal arm is the start where it fits the readings better."""
    _cell(tmp_path / "good.json", UR10E, RING)
    _simulate(tmp_path, 40, 11, "m.csv", "good.json")
    fit = robocal(
        "calibrate", "m.csv", "--cell", "good.json", "--out", "good_model.json", cwd=tmp_path
    )
    assert fit.returncode == 0, fit.stderr
    base = np.array(json.loads((tmp_path / "good_model.json").read_text())["base"])
    guess = np.eye(4)
    guess[:3, 3] = base[:3, 3] / 1000.0
    _cell(tmp_path / "cell.json", UR10E, RING, base=guess.tolist())
    out = "model.json"
    args = ("--model-out", out, "--out", "report.json") if command == "diagnose" else ("--out", out)
    r = robocal(command, "m.csv", "--cell", "cell.json", *args, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    model = json.loads((tmp_path / out).read_text())
    assert model["validation"]["deployable"], model["validation"]["reasons"]
    assert np.allclose(model["base"], base, atol=0.05), "the base the data gives"


@pytest.mark.parametrize(("scale", "unit"), [("xyz", "metres"), ("q", "radians")])
def test_targets_in_other_units_are_refused_naming_them(tmp_path, scale, unit):
    """targets.csv in metres was 'pose 61 is unreachable ... no closer than 1875.589 mm', its
    starting joints in radians 'pose 62 is unreachable ... 95.519 mm': the units check that
    guards a campaign guards the targets, whose starting joints say where the SMRs should be."""
    _cell(tmp_path / "cell.json", UR10E, RING)
    rows = _fitted(tmp_path, 52, 11, 40)
    qs = [f"q{i}" for i in range(1, 7)]
    with open(tmp_path / "targets.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["pose", "target", "x", "y", "z", *qs])
        for row in rows[3 * 40 :]:
            xyz = [float(row[c]) / (1000.0 if scale == "xyz" else 1.0) for c in "xyz"]
            q = [float(row[c]) for c in qs]
            q = [float(np.radians(v)) for v in q] if scale == "q" else q
            w.writerow([row["pose"], row["target"], *xyz, *q])
    r = robocal("compensate", "model.json", "targets.csv", "--out", "joints.csv", cwd=tmp_path)
    line = r.stderr.strip()
    assert r.returncode != 0 and len(line.splitlines()) == 1, r.stderr
    assert line.startswith("robocal: error: targets.csv") and unit in line, line
    assert "targets span" in line, line


# a 3 m arm in modified DH (KUKA KR 1000 titan-like proportions): axes 2 and 3 parallel
LARGE = _robot(
    "titan-like",
    "mdh",
    [
        (0, 1045, 0, 0, (-150, 150)),
        (500, 0, -90, -90, (-130, 20)),
        (1300, 0, 0, 0, (-94, 130)),
        (55, 1525, 0, -90, (-350, 350)),
        (0, 0, 0, 90, (-118, 118)),
        (0, 290, 0, -90, (-350, 350)),
    ],
)


def test_a_two_degree_guess_keeps_its_configuration_by_the_stretched_elbow(tmp_path):
    """Starting joints 2 deg off the measured ones, in the measured configuration: by the
    stretched elbow the damped steps fell to the mirror solution across the edge (pose 74 of
    this 3 m arm: cfx 3 -> 1, 4.3 deg from the measured joints) and compensate only warned. Now
    every pose whose guess shares the measured joints' arm configuration keeps it."""
    from robocal.server.formats.cell_doc import CellDoc
    from robocal.solver.configuration import confdata

    ring = {"A": [150.0, 0.0, 80.0], "B": [-75.0, 130.0, 80.0], "C": [-75.0, -130.0, 80.0]}
    cell = tmp_path / "cell.json"
    _cell(cell, LARGE, ring)
    rows = _fitted(tmp_path, 260, 11, 60)
    qs = [f"q{i}" for i in range(1, 7)]
    off = [-2, -2, 2, -2, -2, 2]  # deg: pose 74's guess across the edge from its solution
    measured, guess = {}, {}
    with open(tmp_path / "targets.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["pose", "target", "x", "y", "z", *qs])
        for row in rows[3 * 60 :]:
            p = row["pose"]
            measured[p] = [float(row[q]) for q in qs]
            guess[p] = [v + d for v, d in zip(measured[p], off)]
            w.writerow([p, row["target"], row["x"], row["y"], row["z"], *guess[p]])
    r = robocal("compensate", "model.json", "targets.csv", "--out", "joints.csv", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    robot = CellDoc.model_validate(json.loads(cell.read_text())).robot_model

    def cfx(q):
        return int(np.asarray(confdata(robot, np.radians([q]))).reshape(-1)[3])

    for row in csv.DictReader(open(tmp_path / "joints.csv")):
        p = row["pose"]
        if cfx(guess[p]) == cfx(measured[p]):
            assert cfx([float(row[q]) for q in qs]) == cfx(measured[p]), p
    got = {row["pose"]: row for row in csv.DictReader(open(tmp_path / "joints.csv"))}
    q74 = [float(got["74"][q]) for q in qs]
    assert np.max(np.abs(np.subtract(q74, measured["74"]))) < 0.5, q74


@pytest.mark.parametrize("value", ["-1", "0", "nan"])
def test_a_tolerance_not_above_zero_says_above_zero(tmp_path, value):
    """--tolerance-mm=-1 said 'is not a finite number >= 0', though 0 is refused too."""
    r = robocal("calibrate", "m.csv", f"--tolerance-mm={value}", cwd=tmp_path)
    line = r.stderr.strip()
    assert r.returncode != 0 and len(line.splitlines()) == 1, r.stderr
    assert f"'{value}' is not a finite number > 0" in line, line


def test_a_condition_number_the_smr_layout_sets_warns_instead_of_refusing(tmp_path):
    """One SMR 1 mm off the flange axis of the 3 m arm: 60 poses ended 'NOT DEPLOYABLE: condition
    number 1.54e+03 exceeds 1000 ... measure more poses' with the held-out error at the noise
    floor, though the arm and layout allow no better (the same parameters' condition number on
    random poses within the limits: 1.31e+03). A warning says so; the verdict is the held-out
    error's."""
    _cell(tmp_path / "cell.json", LARGE, {"A": [1.0, 0.0, 25.0]})
    _simulate(tmp_path, 60, 72, "m.csv")
    r = robocal("calibrate", "m.csv", "--cell", "cell.json", "--out", "model.json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    v = json.loads((tmp_path / "model.json").read_text())["validation"]
    assert v["deployable"] and v["condition_number"] > 1000, v
    assert any("robot and SMR layout's own" in w for w in v["warnings"]), v["warnings"]


def _blanked(src, dst, lines, column="temp_c"):
    """src's campaign with `column` blank on the given data lines (1-based), written to dst."""
    rows = list(csv.DictReader(open(src)))
    for i in lines:
        rows[i - 1][column] = ""
    with open(dst, "w", newline="") as f:
        w = csv.DictWriter(f, list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def test_a_blank_temperature_is_not_recorded_not_a_crash(tmp_path):
    """A blank temp_c is 'not recorded' (the reader says so), yet one blank reading (or 'nan')
    ended diagnose in 'robocal: error: non-finite values in the information matrix', and a pose
    without its temperature ended predict in 'predictions must be finite' (evaluate and check
    alike named no file or pose). A reading takes its pose's temperature; a pose with none is
    said by name where a thermal model needs it, and the diagnosis then grows with time."""
    r = robocal(
        "simulate", "--poses", 60, "--seed", 4, "--effect", "thermal_drift", "--out", "m.csv",
        cwd=tmp_path,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    _blanked(tmp_path / "m.csv", tmp_path / "one.csv", [5])
    r = robocal("diagnose", "one.csv", "--out", "r.json", "--model-out", "x.json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    effects = json.loads((tmp_path / "r.json").read_text())["effects"]
    assert [e["name"] for e in effects] == ["thermal_drift"], effects
    assert effects[0]["parameters"]["variable"] == "temp_c", effects
    _blanked(tmp_path / "m.csv", tmp_path / "pose.csv", [7, 8, 9])  # pose 3's three readings
    for args in (
        ("predict", "x.json", "pose.csv", "--out", "pred.csv"),
        ("evaluate", "x.json", "pose.csv"),
        ("check", "x.json", "pose.csv", "--db", "h.db"),
    ):
        r = robocal(*args, cwd=tmp_path)
        line = r.stderr.strip()
        assert r.returncode == 1 and len(line.splitlines()) == 1, (args[0], r.stderr)
        assert "pose.csv" in line and "pose '3'" in line and "temp_c" in line, line
    assert not (tmp_path / "pred.csv").exists()
    r = robocal("diagnose", "pose.csv", "--out", "r2.json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    effects = json.loads((tmp_path / "r2.json").read_text())["effects"]
    assert [e["parameters"]["variable"] for e in effects] == ["time_s"], effects


@pytest.mark.parametrize("column", ["q5", "cfx", "prev_q3"])
def test_rows_of_a_pose_that_disagree_name_the_field_that_differs(tmp_path, column):
    """The second row of a pose with another cfx was refused as 'column cf1: the configuration
    differs ...' (and another prev_q3 as 'column prev_q1', another q5 in targets.csv as 'column
    q1'): the line named the group's first column, which agreed. It names the one that differs."""
    _cell(tmp_path / "cell.json", UR10E, RING)
    rows = _fitted(tmp_path, 40, 3, 40)[:6]
    kind = "q" if column == "q5" else column[:-1] if column != "prev_q3" else "prev_q"
    cfs = ["cf1", "cf4", "cf6", "cfx"]
    qs = [f"q{i}" for i in range(1, 7)]
    cols = {"q": qs, "cf": cfs, "prev_q": [f"prev_{q}" for q in qs]}[kind]
    header = ["pose", "target", "x", "y", "z", *(qs if kind != "cf" else []), *cols]
    header = list(dict.fromkeys(header))
    out = []
    for k, row in enumerate(rows):
        row = dict(row)
        row.update({c: "0" for c in cfs})
        row.update({f"prev_{q}": row[q] for q in qs})
        if k == 1:  # pose 1's second row
            row[column] = str(float(row[column]) + 1) if column != "cfx" else "1"
        out.append(row)
    name = "meas.csv" if kind == "prev_q" else "targets.csv"
    with open(tmp_path / name, "w", newline="") as f:
        w = csv.DictWriter(f, header if kind != "prev_q" else list(out[0]), extrasaction="ignore")
        w.writeheader()
        w.writerows(out)
    if kind == "prev_q":
        r = robocal("calibrate", name, "--cell", "cell.json", "--out", "m.json", cwd=tmp_path)
    else:
        r = robocal("compensate", "model.json", name, "--out", "joints.csv", cwd=tmp_path)
    line = r.stderr.strip()
    assert r.returncode == 1 and len(line.splitlines()) == 1, r.stderr
    assert line.startswith(f"robocal: error: {name}:3:") and f"column '{column}'" in line, line


def _write_rows(path, rows):
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, list(rows[0]), extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)


def _rms_on(tmp_path, model: str, meas: str) -> float:
    """3-D RMS (mm) of `model`'s predictions against the readings of `meas` (one SMR, A)."""
    r = robocal("predict", model, meas, "--out", "pred.csv", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    got = {p["pose"]: p for p in csv.DictReader(open(tmp_path / "pred.csv"))}
    d = [
        [float(got[m["pose"]][c]) - float(m[c]) for c in "xyz"]
        for m in csv.DictReader(open(tmp_path / meas))
    ]
    return float(np.sqrt(np.mean(np.sum(np.square(d), axis=1))))


def test_a_deployable_diagnosis_holds_beyond_its_joint_1_range(tmp_path):
    """The real UR5 (ur5_jacobi) fitted on 150 grid poses with q1 below 10 deg, tested on the
    grid's other poses with q1 above 30 deg: the diagnosis named joint-1 periodic errors of 58.8
    deg (k = 1) and 15.1 deg (k = 2) amplitude, traded against the geometry within the measured
    q1 -23.7 to 10.0 deg (5-fold 0.125 -> 0.090 mm), and off it the model missed by 40.9 mm RMS
    (max 91 mm) where the geometry misses by 0.207 mm; with --tolerance-mm 0.5 the model was
    deployable. A deployable model must hold there (or the terms be refused)."""
    from tests.real import REAL

    src = REAL / "ur5_jacobi"
    grid = list(csv.DictReader(open(src / "train.csv")))
    train = [r for r in grid if float(r["q1"]) < 10]
    other = [r for r in csv.DictReader(open(src / "test_gridrest.csv")) if float(r["q1"]) > 30]
    rng = np.random.default_rng(0)
    rng.choice(sum(float(r["q3"]) < 95 for r in grid), 150, replace=False)  # the audit's first draw
    _write_rows(
        tmp_path / "fit.csv", [train[i] for i in sorted(rng.choice(len(train), 150, False))]
    )
    _write_rows(tmp_path / "other.csv", other)
    cell = str(src / "cell.json")
    tol = ("--tolerance-mm", "0.5")
    r = robocal("calibrate", "fit.csv", "--cell", cell, "--out", "geo.json", *tol, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    r = robocal(
        "diagnose", "fit.csv", "--cell", cell, "--out", "r.json", "--model-out", "x.json", *tol,
        cwd=tmp_path,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    v = json.loads((tmp_path / "x.json").read_text())["validation"]
    geo, ext = _rms_on(tmp_path, "geo.json", "other.csv"), _rms_on(tmp_path, "x.json", "other.csv")
    print(f"q1 > 30 deg: geometry {geo:.4f} mm, diagnosed {ext:.4f} mm; verdict {v}")
    assert not v["deployable"] or ext <= 2 * geo, (geo, ext, v)
    if not v["deployable"] and ext > 2 * geo:
        assert any("joint 1" in why and "peak to peak" in why for why in v["reasons"]), v


def test_a_base_that_moved_during_the_campaign_stays_moved_after_it(tmp_path):
    """simulate --effect base_shift=0.3 (seed 5): the diagnosis finds the shift at t = 566 s. The
    cell then stands as the campaign left it, but a quick check measured next (its time_s from
    its own start, 5 s) was predicted before the shift: 'recalibrate ... every point moved as
    one rigid body (0.244 mm)', exit 3, on an unchanged cell; and predict, check and compensate
    without a time_s refused ('needs a time_s column'), though no time on the campaign's clock
    means anything to a later program. Data after the campaign is predicted after the shift."""
    r = robocal(
        "simulate", "--poses", 80, "--seed", 5, "--effect", "base_shift=0.3", "--out", "m.csv",
        cwd=tmp_path,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    r = robocal("diagnose", "m.csv", "--out", "r.json", "--model-out", "x.json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    ext = json.loads((tmp_path / "x.json").read_text())["extensions"]
    assert [e["name"] for e in ext] == ["base_shift"], ext
    rows = list(csv.DictReader(open(tmp_path / "m.csv")))
    late = [r for r in rows if float(r["time_s"]) > ext[0]["at_s"] + 60]
    late = [r for r in late if r["pose"] in {x["pose"] for x in late[:3]} | {late[-1]["pose"]}]
    t0 = float(late[0]["time_s"])
    for r in late:
        r["time_s"] = f"{float(r['time_s']) - t0 + 5:.3f}"  # the check's own clock
    _write_rows(tmp_path / "check.csv", late)
    r = robocal("check", "x.json", "check.csv", "--db", "h.db", "--out", "c.json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    doc = json.loads((tmp_path / "c.json").read_text())
    assert doc["verdict"] == "ok" and doc["rms_mm"] < 0.05, doc
    qs = [f"q{i}" for i in range(1, 7)]
    targets = [{k: r[k] for k in ("pose", "target", "x", "y", "z", *qs)} for r in late]
    _write_rows(tmp_path / "targets.csv", targets)
    r = robocal("compensate", "x.json", "targets.csv", "--out", "joints.csv", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    measured = {r["pose"]: [float(r[q]) for q in qs] for r in late}
    for row in csv.DictReader(open(tmp_path / "joints.csv")):
        moved = np.subtract([float(row[q]) for q in qs], measured[row["pose"]])
        assert np.max(np.abs(moved)) < 0.05, (row["pose"], moved)
        assert float(row["predicted_error_mm"]) < 0.05, row


def test_poses_past_the_measured_range_of_an_extended_joint_are_said(tmp_path):
    """The diagnosis prints 'trusted within the joint ranges measured', but the model did not
    keep them: predict and compensate extrapolated an extension silently (the real UR5's full
    diagnosis: its joint-1 periodic pair moves joint 1 by 0.024 deg over the measured q1 -24..57
    deg and by 0.98 deg peak to peak over its +-360 deg). Simulated: compliance of joint 2 found
    on poses with q2 in -60..20 deg; predicted and compensated at q2 above 40 deg, a warning
    names the joint, the range and the first pose."""
    r = robocal(
        "simulate", "--poses", 300, "--seed", 8, "--effect", "joint_compliance:2",
        "--out", "all.csv", cwd=tmp_path,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    rows = list(csv.DictReader(open(tmp_path / "all.csv")))
    _write_rows(tmp_path / "fit.csv", [r for r in rows if -60 < float(r["q2"]) < 20])
    far = [r for r in rows if float(r["q2"]) > 40]
    _write_rows(tmp_path / "far.csv", far)
    qs = [f"q{i}" for i in range(1, 7)]
    _write_rows(
        tmp_path / "targets.csv",
        [{k: r[k] for k in ("pose", "target", "x", "y", "z", *qs)} for r in far],
    )
    r = robocal("diagnose", "fit.csv", "--out", "r.json", "--model-out", "x.json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    model = json.loads((tmp_path / "x.json").read_text())
    assert any(e.get("joint") == 2 for e in model["extensions"]), model["extensions"]
    lo, hi = model["diagnosis"]["joint_range_deg"][1]
    assert -60 <= lo < hi <= 20, (lo, hi)
    for args in (
        ("predict", "x.json", "far.csv", "--out", "pred.csv"),
        ("compensate", "x.json", "targets.csv", "--out", "joints.csv"),
    ):
        r = robocal(*args, cwd=tmp_path)
        assert r.returncode == 0, r.stderr
        said = [w for w in r.stderr.splitlines() if "outside the q2 range" in w]
        assert len(said) == 1 and f"{len(far) // 3} poses" in said[0], r.stderr
    r = robocal("predict", "x.json", "fit.csv", "--out", "pred.csv", cwd=tmp_path)
    assert r.returncode == 0 and "outside" not in r.stderr, r.stderr


def test_a_check_plan_of_readings_in_the_robots_frame_says_why_not(tmp_path):
    """The real UR5's readings are in its base frame (the authors' registration): `check --plan
    6` said 'constraints too tight: only 0 of 1000 poses valid ... range: move the tracker at
    least 1 m from every SMR: check the base guess', though the cell gives no base guess: the
    planner put the tracker at the frame's origin, 0.4 mm from the robot's base."""
    from tests.real import REAL

    src = REAL / "ur5_jacobi"
    r = robocal(
        "calibrate", str(src / "small" / "train.csv"), "--cell", str(src / "cell.json"),
        "--out", "model.json", cwd=tmp_path,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    r = robocal("check", "--plan", "6", "model.json", "--out", "plan.csv", cwd=tmp_path)
    line = r.stderr.strip()
    assert r.returncode == 1 and len(line.splitlines()) == 1, r.stderr
    assert "registered to the robot" in line and "base guess" not in line, line
    assert not (tmp_path / "plan.csv").exists()
